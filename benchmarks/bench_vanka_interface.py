"""The factored Vanka smoother's interface sweeps in slab phases against one patch after the
other, on the system of a many-disk scene (one process, the same system, in turn).

Run:  python benchmarks/bench_vanka_interface.py [--count 500] [--level 2] [--sweeps 2]

Builds ``sedimentation-2d`` with ``--count`` disks (multigrid, the stabilised coupling), takes
one step, and times ``FactoredVankaSmoother.smooth`` on the finest level of that step's
hierarchy from a random right-hand side: the interface patches in slab phases (as the smoother
does), one after the other (as it did before), and without interface sweeps; best of three,
two rounds in turn. Prints the times and the residuals after the sweeps.
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from fbmflow.config import from_dict
from fbmflow.scenes import get_scene
from fbmflow.solvers.vanka import FactoredVankaSmoother


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--count", type=int, default=500)
    ap.add_argument("--level", type=int, default=2)
    ap.add_argument("--sweeps", type=int, default=2)
    args = ap.parse_args(argv)
    scene = get_scene("sedimentation-2d")
    params = from_dict(scene.Params, {"particles": {"count": args.count}, "solver": {"linear": "multigrid"},
                                      "coupling": {"scheme": "stabilised"}})
    sim = scene.build(params, args.level).sim
    sim.step()
    system = sim.flow._linearisation[4]
    system = system.preconditioner or system
    smoother = FactoredVankaSmoother(system)
    print(f"{system.n_u + system.n_p} unknowns, {smoother.ptr.size - 1} patches, "
          f"{smoother.interface.size} at the interface", flush=True)
    b = np.random.default_rng(0).standard_normal(system.n_u + system.n_p)
    phases, merged = smoother.interface_phases, smoother.interface_merged

    def timed(order: str) -> tuple[float, float]:
        smoother.interface_sweeps = 0 if order == "none" else 2
        smoother.interface_phases = phases if order == "slab phases" else []
        smoother.interface_merged = merged if order == "slab phases" else smoother.interface
        best = np.inf
        for _ in range(3):
            x = np.zeros_like(b)
            t0 = time.perf_counter()
            smoother.smooth(b, x, args.sweeps)
            best = min(best, time.perf_counter() - t0)
        return best, float(np.linalg.norm(b - system.apply(x)))

    for order in ("slab phases", "one after the other"):  # compile and warm up
        timed(order)
    for _ in range(2):
        for order in ("one after the other", "slab phases", "none"):
            t, r = timed(order)
            print(f"interface sweeps {order}: {args.sweeps} sweeps {t:.3f} s, residual after {r:.4e}",
                  flush=True)


if __name__ == "__main__":
    main()
