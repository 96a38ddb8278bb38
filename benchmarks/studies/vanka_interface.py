"""The factored Vanka smoother's interface sweeps in slab phases against one patch after the
other, on the system of a many-disk scene (one process, the same system, in turn).

Question: what do the factored Vanka smoother's interface sweeps cost when the interface patches
are swept in parallel slab phases instead of one after the other?
Answer: two sweeps on the first step's system of 500 disks at level 2 (882 402 unknowns, 80 000
patches, 10 839 at the interface): 0.232-0.235 s one after the other against 0.191-0.202 s in
slab phases and 0.137 s without interface sweeps, so the interface sweeps cost 0.06 s instead of
0.10 s, with the residual after them the same to 3e-4; printed, no results file.
Measured: 2026-11-28, commit 017045c; quoted in docs/validation/many-particles.md, "2 000 disks and 1 000
spheres"
Run: python -m fbmbench vanka_interface --count 500 --level 2 --sweeps 2

Builds ``sedimentation-2d`` with ``--count`` disks (multigrid, the stabilised coupling), takes
one step, and times ``FactoredVankaSmoother.smooth`` on the finest level of that step's
hierarchy from a random right-hand side: the interface patches in slab phases (as the smoother
does), one after the other (as it did before), and without interface sweeps; best of three,
two rounds in turn. Prints the times and the residuals after the sweeps.
"""
from __future__ import annotations

import time

import numpy as np

from fbmflow.config import from_dict
from fbmflow.scenes import get_scene
from fbmflow.solvers.vanka import FactoredVankaSmoother


def run(*, count: int = 500, level: int = 2, sweeps: int = 2) -> None:
    """Time the smoother's sweeps with the interface patches in slab phases, one after the other,
    and without them.

    Parameters
    ----------
    count : number of disks
    level : mesh level of the scene
    sweeps : smoothing sweeps per timing
    """
    scene = get_scene("sedimentation-2d")
    params = from_dict(scene.Params, {"particles": {"count": count}, "solver": {"linear": "multigrid"},
                                      "coupling": {"scheme": "stabilised"}})
    sim = scene.build(params, level).sim
    solved = [None]

    def keep(report, system):
        solved[0] = system  # the last one: the system of that step's last solve

    sim.flow.on_linear_solve = keep
    sim.step()
    sim.flow.on_linear_solve = None
    system = solved[0]
    system = system.preconditioner or system
    smoother = FactoredVankaSmoother(system)
    print(f"{system.n_u + system.n_p} unknowns, {smoother.ptr.size - 1} patches, "
          f"{smoother.interface.size} at the interface", flush=True)
    b = np.random.default_rng(0).standard_normal(system.n_u + system.n_p)
    phases, merged = smoother.interface_phases, smoother.interface_merged_phases
    one_group = [(np.array([0, smoother.interface.size]), smoother.interface)]  # one after the other

    def timed(order: str) -> tuple[float, float]:
        smoother.interface_sweeps = 0 if order == "none" else 2
        smoother.interface_phases = phases if order == "slab phases" else []
        smoother.interface_merged_phases = merged if order == "slab phases" else one_group
        best = np.inf
        for _ in range(3):
            x = np.zeros_like(b)
            t0 = time.perf_counter()
            smoother.smooth(b, x, sweeps)
            best = min(best, time.perf_counter() - t0)
        return best, float(np.linalg.norm(b - system.apply(x)))

    for order in ("slab phases", "one after the other"):  # compile and warm up
        timed(order)
    for _ in range(2):
        for order in ("one after the other", "slab phases", "none"):
            t, r = timed(order)
            print(f"interface sweeps {order}: {sweeps} sweeps {t:.3f} s, residual after {r:.4e}",
                  flush=True)

