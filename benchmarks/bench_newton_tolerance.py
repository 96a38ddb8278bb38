"""Newton's tolerance on a many-particle scene: 1e-10 / 1e-8 (Newton / linear) against 1e-6 /
1e-3, the same steps from rest, one process.

Run:  python benchmarks/bench_newton_tolerance.py [--scene sedimentation-2d] [--level 1]
      [--scheme implicit] [--linear auto] [--steps 40]

Prints the wall time and Newton iterations per step (the first step, with the set-up, left
out of the mean), and the largest difference of the particles' mean vertical velocity between
the two over all steps, relative to its largest value.
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from fbmflow.params import from_dict
from fbmflow.scenes import get_scene

TOLERANCES = ((1e-10, 1e-8), (1e-6, 1e-3))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="sedimentation-2d")
    ap.add_argument("--level", type=int, default=1)
    ap.add_argument("--scheme", default="implicit")
    ap.add_argument("--linear", default="auto")
    ap.add_argument("--steps", type=int, default=40)
    args = ap.parse_args(argv)
    scene = get_scene(args.scene)
    velocity = {}
    for newton_rtol, linear_rtol in TOLERANCES:
        params = from_dict(scene.Params, {"coupling": {"scheme": args.scheme}, "solver": {
            "linear": args.linear, "newton_rtol": newton_rtol, "linear_rtol": linear_rtol}})
        sim = scene.build(params, args.level).sim
        v, wall, newton = [], [], []
        for _ in range(args.steps):
            t0 = time.perf_counter()
            r = sim.step()
            wall.append(time.perf_counter() - t0)
            v.append(float(r.velocity[:, -1].mean()))
            newton.append(r.newton_iterations)
        velocity[newton_rtol] = np.array(v)
        print(f"newton_rtol {newton_rtol:g}, linear_rtol {linear_rtol:g}: {np.mean(wall[1:]):.2f} s per "
              f"step, {np.mean(newton):.2f} Newton iterations per step, last mean velocity {v[-1]:.6f}",
              flush=True)
    tight, loose = (velocity[t] for t, _ in TOLERANCES)
    print(f"largest difference of the mean velocity: {np.abs(tight - loose).max() / np.abs(tight).max():.2e} "
          f"of its largest value; at the last step {abs(tight[-1] - loose[-1]) / abs(tight[-1]):.2e}")


if __name__ == "__main__":
    main()
