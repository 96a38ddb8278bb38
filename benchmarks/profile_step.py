"""Profile one time step of a run from its checkpoint: where the time goes outside the linear
solves.

Run:  python benchmarks/profile_step.py RUN_DIR [--top 40] [--warm N]

``RUN_DIR``: the output folder of a run with ``--checkpoint-every`` (``run.json`` and
``checkpoint.h5``, e.g. from ``python benchmarks/bench_tencate.py --cases E4 --levels 2 --dt 0.01
--set solver.linear=multigrid --checkpoint-every 5``). The scene is built from ``run.json``, the
state restored from the checkpoint, ``--warm`` steps run unprofiled (0: the profiled step is the
first after the build and includes the multigrid hierarchy's construction), and the next step
runs under cProfile. Prints the wall time,
the time in the linear solves (``StepReport.linear.time_s``), and the functions by cumulative
and by own time.
"""
from __future__ import annotations

import argparse
import cProfile
import io
import json
import pstats
import time
from pathlib import Path

from fbmflow.config import from_dict
from fbmflow.io import load_checkpoint
from fbmflow.scenes import get_scene


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run_dir", type=Path)
    ap.add_argument("--top", type=int, default=40, help="functions listed per ordering")
    ap.add_argument("--warm", type=int, default=0, help="steps run before the profiled one")
    args = ap.parse_args(argv)
    run = json.loads((args.run_dir / "run.json").read_text())
    scene = get_scene(run["scene"])
    t0 = time.perf_counter()
    sim = scene.build(from_dict(scene.Params, run["params"]), run["level"]).sim
    sim.set_state(load_checkpoint(args.run_dir / "checkpoint.h5")[0])
    print(f"built and restored in {time.perf_counter() - t0:.1f} s, t = {sim.t:.4g} s", flush=True)
    for _ in range(args.warm):
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
        pstats.Stats(profile, stream=out).sort_stats(order).print_stats(args.top)
        print(out.getvalue())


if __name__ == "__main__":
    main()
