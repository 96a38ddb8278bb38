"""Newton's tolerance on a many-particle scene: pairs of Newton / linear residual reductions
(default 1e-10 / 1e-8 and 1e-6 / 1e-3), the same steps from rest, one after the other in one
process.

Run:  python benchmarks/bench_newton_tolerance.py [--scene sedimentation-2d] [--level 1]
      [--scheme implicit] [--linear auto] [--steps 40] [--count N]
      [--tolerances 1e-6/1e-3 1e-3/1e-3 ...]

Prints, per pair, the wall time and Newton iterations per step (the first step, with the
set-up, left out of the mean) and the largest overlap of two particles; then, for each pair
after the first, the largest difference of the particles' mean vertical velocity from the
first pair's over all steps, relative to its largest value.
"""
from __future__ import annotations

import argparse
import gc
import time

import numpy as np

from fbmflow.config import from_dict
from fbmflow.scenes import get_scene
from fbmflow.scenes.sedimentation import max_overlap

TOLERANCES = ("1e-10/1e-8", "1e-6/1e-3")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="sedimentation-2d")
    ap.add_argument("--level", type=int, default=1)
    ap.add_argument("--scheme", default="implicit")
    ap.add_argument("--linear", default="auto")
    ap.add_argument("--steps", type=int, default=40)
    ap.add_argument("--count", type=int, help="particles.count (default: the scene's)")
    ap.add_argument("--tolerances", nargs="+", default=TOLERANCES, metavar="NEWTON/LINEAR",
                    help="Newton / linear residual reductions; the first pair is the reference")
    args = ap.parse_args(argv)
    scene = get_scene(args.scene)
    velocity = {}
    for pair in args.tolerances:
        newton_rtol, linear_rtol = (float(v) for v in pair.split("/"))
        settings = {"coupling": {"scheme": args.scheme}, "solver": {
            "linear": args.linear, "newton_rtol": newton_rtol, "linear_rtol": linear_rtol}}
        if args.count is not None:
            settings["particles"] = {"count": args.count}
        sim = scene.build(from_dict(scene.Params, settings), args.level).sim
        v, wall, newton, overlap = [], [], [], []
        for _ in range(args.steps):
            t0 = time.perf_counter()
            r = sim.step()
            wall.append(time.perf_counter() - t0)
            v.append(float(r.velocity[:, -1].mean()))
            newton.append(r.newton_iterations)
            overlap.append(max_overlap(sim.particles, sim.flow.mesh.lower, sim.flow.mesh.upper))
        velocity[pair] = np.array(v)
        del sim
        gc.collect()  # one simulation's memory at a time (its reference cycles hold gigabytes)
        print(f"newton_rtol {newton_rtol:g}, linear_rtol {linear_rtol:g}: {np.mean(wall[1:]):.2f} s per "
              f"step ({' '.join(f'{w:.1f}' for w in wall)}), {np.mean(newton):.2f} Newton iterations per "
              f"step, largest overlap {max(overlap):.2g} r, last mean velocity {v[-1]:.6f}", flush=True)
    reference = velocity[args.tolerances[0]]
    for pair in args.tolerances[1:]:
        diff = np.abs(velocity[pair] - reference)
        print(f"{pair} against {args.tolerances[0]}: largest difference of the mean velocity "
              f"{diff.max() / np.abs(reference).max():.2e} of its largest value; at the last step "
              f"{diff[-1] / abs(reference[-1]):.2e}")


if __name__ == "__main__":
    main()
