"""Profile one time step of a run from its checkpoint: where the time goes outside the linear
solves.

Question: where does the time of one time step go, in and outside the linear solves, at a given
state of a run (a utility: cProfile of the step after a checkpoint)?
Answer: sedimentation-2d with 2 000 disks from the checkpoint at t = 0.9 s (``--warm 1``): 11.2 s,
8.7 s of it in the one linear solve (4.6 s in the two cycles, 2.7 s setting up the hierarchy) and
2.5 s outside it (the orphaned pressure modes 1.2 s, the levels' systems 1.2 s); ten-cate E4
level 2 after the step-110 checkpoint: 123.9 s, 96.4 s in the solves; printed, no results file.
Measured: 2026-11-28, commit 017045c; quoted in docs/validation/many-particles.md, "2 000 disks and 1 000
spheres"
Run: python -m fbmbench profile_step out/sed2000 --warm 1

``RUN_DIR``: the output folder of a run with ``--checkpoint-every`` (``run.json`` and
``checkpoint.h5``, e.g. from ``python -m fbmbench tencate --cases E4 --levels 2 --dt 0.01 --set
solver.linear=multigrid --checkpoint-every 5``). The scene is built from ``run.json``, the state
restored from the checkpoint, ``--warm`` steps run unprofiled (0: the profiled step is the first
after the build and includes the multigrid hierarchy's construction), and the next step runs under
cProfile. Prints the wall time, the time in the linear solves (``StepReport.linear.time_s``), and
the functions by cumulative and by own time. docs/validation/multigrid-with-fictitious-boundaries.md also
quotes ``python -m fbmbench profile_step RUN_DIR``.
"""
from __future__ import annotations

import cProfile
import io
import json
import pstats
import time
from pathlib import Path

from fbmflow.config import from_dict
from fbmflow.io import load_checkpoint
from fbmflow.scenes import get_scene


def run(run_dir: Path, *, top: int = 40, warm: int = 0) -> None:
    """Profile the step after ``warm`` steps from the checkpoint in ``run_dir``.

    Parameters
    ----------
    run_dir : output folder of a run with run.json and checkpoint.h5
    top : functions listed per ordering
    warm : steps run before the profiled one
    """
    info = json.loads((run_dir / "run.json").read_text())
    scene = get_scene(info["scene"])
    t0 = time.perf_counter()
    sim = scene.build(from_dict(scene.Params, info["params"]), info["level"]).sim
    sim.set_state(load_checkpoint(run_dir / "checkpoint.h5")[0])
    print(f"built and restored in {time.perf_counter() - t0:.1f} s, t = {sim.t:.4g} s", flush=True)
    for _ in range(warm):
        t0 = time.perf_counter()
        report = sim.step()
        print(f"warm step: {time.perf_counter() - t0:.1f} s, linear solves {report.linear.time_s:.1f} s",
              flush=True)
    profile = cProfile.Profile()
    t0 = time.perf_counter()
    profile.enable()
    report = sim.step()
    profile.disable()
    wall = time.perf_counter() - t0
    print(f"step: {wall:.1f} s, linear solves {report.linear.time_s:.1f} s ({report.linear.solves} solves, "
          f"{report.newton_iterations} Newton iterations), outside them {wall - report.linear.time_s:.1f} s")
    for order in ("cumulative", "tottime"):
        out = io.StringIO()
        pstats.Stats(profile, stream=out).sort_stats(order).print_stats(top)
        print(out.getvalue())
