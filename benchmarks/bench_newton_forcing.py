"""Newton's last-step forcing against a fixed linear tolerance, on the same steps of a run, in
one process.

Run:  python benchmarks/bench_newton_forcing.py RUN_DIR [--steps 2] [--rounds 2]

``RUN_DIR`` holds ``run.json`` and ``checkpoint.h5`` (``fbmflow run ... --checkpoint-every N``,
e.g. ``fbmflow run ten-cate --level 2 --set solver.linear=multigrid --set time.dt=0.01 --set
time.t_end=0.3 --checkpoint-every 5`` stopped after step 25). The scene is built once; each
round restores the checkpoint and runs ``--steps`` steps with the fixed rule (every linear
step asked for ``solver.linear_rtol``: :data:`fbmflow.solvers.newton.LAST_STEP_FORCING` set
to it) and then with the package's rule. Prints every step's wall time, linear solves, multigrid
cycles and the first particle's velocity, and the means per rule.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from fbmflow.io import load_checkpoint
from fbmflow.params import from_dict
from fbmflow.scenes import get_scene
from fbmflow.solvers import newton


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run_dir", type=Path)
    ap.add_argument("--steps", type=int, default=2)
    ap.add_argument("--rounds", type=int, default=2)
    args = ap.parse_args(argv)
    run = json.loads((args.run_dir / "run.json").read_text())
    scene = get_scene(run["scene"])
    sim = scene.build(from_dict(scene.Params, run["params"]), run["level"]).sim
    state = load_checkpoint(args.run_dir / "checkpoint.h5")[0]
    rules = {"fixed": sim.flow.newton.linear_rtol, "last-step forcing": newton.LAST_STEP_FORCING}
    rows = {name: [] for name in rules}
    for _ in range(args.rounds):
        for name, cap in rules.items():
            newton.LAST_STEP_FORCING = cap
            sim.set_state(state)
            for _ in range(args.steps):
                t0 = time.perf_counter()
                r = sim.step()
                wall = time.perf_counter() - t0
                rows[name].append((wall, r.linear.time_s, r.linear.solves, r.linear.iterations))
                print(f"{name}: step {r.step} {wall:.2f} s (solves {r.linear.time_s:.2f} s), "
                      f"{r.linear.solves} solves, {r.linear.iterations} cycles, "
                      f"velocity {r.velocity[0].tolist()}", flush=True)
    for name, values in rows.items():
        v = np.array(values)
        print(f"{name}: {v[:, 0].mean():.2f} s per step ({v[:, 1].mean():.2f} s in {v[:, 2].mean():.2f} "
              f"solves, {v[:, 3].mean():.2f} cycles)")


if __name__ == "__main__":
    main()
