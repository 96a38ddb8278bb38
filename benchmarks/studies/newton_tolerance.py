"""Newton's tolerance on a many-particle scene: pairs of Newton / linear residual reductions
(default 1e-10 / 1e-8 and 1e-6 / 1e-3), the same steps from rest, one after the other in one
process.

Question: what do the many-particle scenes gain by stopping Newton at a 1e-6 residual reduction
with linear steps to 1e-3 instead of 1e-10 / 1e-8, and what does it change?
Answer: ``sedimentation-2d`` (100 disks): level 1, implicit, direct: 2.78 -> 2.55 s per step
(10.3 -> 5.0 Newton iterations), the mean settling velocity the same to 3e-8 of its largest
value; level 2, stabilised, multigrid: 6.22 -> 1.88 s (3.3x faster), the same to 6e-7. At 2 000
disks (level 2, stabilised, multigrid) 1e-4 / 1e-3 is 1.5x faster than 1e-6 / 1e-3 at a 6.5e-5
change (no results file; the figures are those docs/validation/ quotes).
Measured: 2026-11-28, commit 017045c; quoted in docs/validation/many-particles.md, "Newton's tolerance in the
many-particle scenes"
Run: python -m fbmbench newton_tolerance --level 1 --scheme implicit --linear auto --steps 40

At 2 000 disks (docs/validation/many-particles.md, "2 000 disks and 1 000 spheres"): ``python -m fbmbench
newton_tolerance --scene sedimentation-2d --level 2 --scheme stabilised --linear multigrid
--count 2000 --steps 8 --tolerances 1e-6/1e-3 1e-4/1e-3 1e-3/1e-3 1e-2/1e-2``.

Prints, per pair, the wall time and Newton iterations per step (the first step, with the
set-up, left out of the mean) and the largest overlap of two particles; then, for each pair
after the first, the largest difference of the particles' mean vertical velocity from the
first pair's over all steps, relative to its largest value.
"""
from __future__ import annotations

import gc
import time

import numpy as np

from fbmflow.config import from_dict
from fbmflow.scenes import get_scene
from fbmflow.scenes.sedimentation import max_overlap

TOLERANCES = ("1e-10/1e-8", "1e-6/1e-3")


def run(*, scene: str = "sedimentation-2d", level: int = 1, scheme: str = "implicit", linear: str = "auto",
        steps: int = 40, count: int | None = None, tolerances: list[str] = TOLERANCES) -> None:
    """Run the same steps from rest with each tolerance pair in turn and print the comparison.

    Parameters
    ----------
    scene : the scene
    level : the mesh level
    scheme : coupling.scheme
    linear : solver.linear
    steps : steps from rest per pair
    count : particles.count (default: the scene's)
    tolerances : Newton / linear residual reductions, NEWTON/LINEAR each; the first pair is the
        reference
    """
    scene_name = scene
    scene = get_scene(scene_name)
    velocity = {}
    for pair in tolerances:
        newton_rtol, linear_rtol = (float(v) for v in pair.split("/"))
        settings = {"coupling": {"scheme": scheme}, "solver": {
            "linear": linear, "newton_rtol": newton_rtol, "linear_rtol": linear_rtol}}
        if count is not None:
            settings["particles"] = {"count": count}
        sim = scene.build(from_dict(scene.Params, settings), level).sim
        v, wall, newton, overlap = [], [], [], []
        for _ in range(steps):
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
    reference = velocity[tolerances[0]]
    for pair in tolerances[1:]:
        diff = np.abs(velocity[pair] - reference)
        print(f"{pair} against {tolerances[0]}: largest difference of the mean velocity "
              f"{diff.max() / np.abs(reference).max():.2e} of its largest value; at the last step "
              f"{diff[-1] / abs(reference[-1]):.2e}")

