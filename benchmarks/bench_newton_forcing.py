"""Newton's linear steps in time steps, on the same steps of a run, in one process: the last-step
forcing against a fixed linear tolerance, and the Newton block moved to each iterate against the
chord method.

Run:  python benchmarks/bench_newton_forcing.py RUN_DIR [--steps 2] [--rounds 2]
      [--variants fixed chord relinearised]

``RUN_DIR`` holds ``run.json`` and ``checkpoint.h5`` (``fbmflow run ... --checkpoint-every N``,
e.g. ``fbmflow run ten-cate --level 2 --set solver.linear=multigrid --set time.dt=0.01 --set
time.t_end=0.3 --checkpoint-every 5`` stopped after step 25). The scene is built once; each
round restores the checkpoint and runs ``--steps`` steps with each variant in turn:

- ``fixed``: every linear step asked for ``solver.linear_rtol``
  (:data:`fbmflow.solvers.newton.LAST_STEP_FORCING` set to it), the chord method (a reused
  linearisation stays at the point where it was built);
- ``chord``: the last-step forcing, the chord method;
- ``relinearised``: the package's rule, the last-step forcing with a reused linearisation moved
  to each iterate (:meth:`fbmflow.flow.levels.NewtonBlock.relinearise`).

Prints every step's wall time, linear solves, multigrid cycles, Newton iterations and the first
particle's velocity, and the means per variant.
"""
from __future__ import annotations

import argparse
import json
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from fbmflow.config import from_dict
from fbmflow.flow.levels import NewtonBlock
from fbmflow.io import load_checkpoint
from fbmflow.scenes import get_scene
from fbmflow.solvers import newton

VARIANTS = ("fixed", "chord", "relinearised")


@contextmanager
def variant(name: str, linear_rtol: float):
    """The package with ``name``'s rule in place (restored afterwards)."""
    forcing, relinearise = newton.LAST_STEP_FORCING, NewtonBlock.relinearise
    if name == "fixed":
        newton.LAST_STEP_FORCING = linear_rtol
    if name in ("fixed", "chord"):  # set once, where the block is built
        NewtonBlock.relinearise = lambda block, u: None if hasattr(block, "react") else relinearise(block, u)
    try:
        yield
    finally:
        newton.LAST_STEP_FORCING, NewtonBlock.relinearise = forcing, relinearise


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run_dir", type=Path)
    ap.add_argument("--steps", type=int, default=2)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=VARIANTS)
    args = ap.parse_args(argv)
    run = json.loads((args.run_dir / "run.json").read_text())
    scene = get_scene(run["scene"])
    sim = scene.build(from_dict(scene.Params, run["params"]), run["level"]).sim
    state = load_checkpoint(args.run_dir / "checkpoint.h5")[0]
    rows = {name: [] for name in args.variants}
    for _ in range(args.rounds):
        for name in args.variants:
            with variant(name, sim.flow.newton.linear_rtol):
                sim.set_state(state)
                for _ in range(args.steps):
                    t0 = time.perf_counter()
                    r = sim.step()
                    wall = time.perf_counter() - t0
                    rows[name].append((wall, r.linear.time_s, r.linear.solves, r.linear.iterations,
                                       r.newton_iterations))
                    print(f"{name}: step {r.step} {wall:.2f} s (solves {r.linear.time_s:.2f} s), "
                          f"{r.linear.solves} solves, {r.linear.iterations} cycles, "
                          f"{r.newton_iterations} Newton"
                          + (f", velocity {r.velocity[0].tolist()}" if len(r.velocity) else ""), flush=True)
    for name, values in rows.items():
        v = np.array(values)
        print(f"{name}: {v[:, 0].mean():.2f} s per step ({v[:, 1].mean():.2f} s in {v[:, 2].mean():.2f} "
              f"solves, {v[:, 3].mean():.2f} cycles, {v[:, 4].mean():.2f} Newton)")


if __name__ == "__main__":
    main()
