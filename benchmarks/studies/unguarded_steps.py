"""Memory and time of a scene's first steps where the memory guard would refuse it.

Question: what does a ten Cate level-3 step (15.8 M unknowns) really need, on a machine where
the guard's estimate (30.2 GB at the time, 25.0 GB since) refuses it?
Answer: on the 24 GB machine, 2 threads: the build 132 s with a peak of 17.6 GB (the scalar
pattern's sort, since replaced by Numba kernels), the steps 435 s and 423 s (9 and 10 cycles),
the process's peak 21.7 GB, 1 373 bytes per unknown (in the study's units then, KiB / 1e6;
22.2 GB); 5.2 times a level-2 step. After the continuity block and the copies around it
(114f0e2, ``--steps 1``): the build 62.2 s with a peak of 8.49 GB, the step 619 s on a slower
day (9 cycles), the process's peak 19.60 GB, 1 241 bytes per unknown; the guard's refitted
estimate, 22.8 GB, lets level 3 run on this machine.
Measured: 2026-11-29, commit 114f0e2 (the first answer at 71c70e3); quoted in
docs/validation/multigrid-with-fictitious-boundaries.md, "Memory"
Run: python -m fbmbench unguarded_steps --scene ten-cate --level 3 --steps 2

The guard (:func:`fbmflow.solvers.choice.check_memory`) is replaced for this process by a line
that prints its estimate, so that a run it refuses can be measured; the run may then be killed
by the kernel's out-of-memory killer, which is the risk the guard exists for. Nothing else runs
beside it. Prints the build's time and largest resident memory (sampled every 0.5 s), then per
step the wall time, the linear solves' time, cycles and solves, and the process's peak; writes
nothing.
"""
from __future__ import annotations

import json
import resource
import threading
import time


def _peak_gb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 / 1e9


def run(*, scene: str = "ten-cate", level: int = 3, steps: int = 2, set: list[str] = ()) -> None:
    """Build ``scene`` at ``level`` without the memory guard and time ``steps`` steps.

    Parameters
    ----------
    scene : a scene name (``fbmflow scenes``)
    level : the mesh level
    steps : time steps to take and time (>= 1)
    set : scene parameters (KEY=VALUE), as ``fbmflow run --set``
    """
    if steps < 1:
        raise SystemExit(f"--steps must be at least 1, got {steps}")
    import fbmflow.scenes.builder as builder
    import fbmflow.simulation as simulation
    from fbmflow.scenes.registry import load_scene
    from fbmflow.solvers import choice

    def logged(n, dim, solver, *args, transient=False, **kwargs):
        need, words = choice.estimate_memory(n, dim, solver, transient)
        print(f"guard (not enforced): {words} about {need / 1e9:.1f} GB for {n} unknowns", flush=True)
        return need

    simulation.check_memory = builder.check_memory = logged
    largest = [0]

    def sample():
        while True:
            with open("/proc/self/statm") as f:
                largest[0] = max(largest[0], int(f.read().split()[1]) * resource.getpagesize())
            time.sleep(0.5)

    threading.Thread(target=sample, daemon=True).start()
    found, params, lvl = load_scene(scene, level, list(set))
    t0 = time.perf_counter()
    setup = found.build(params, lvl)
    print(f"built in {time.perf_counter() - t0:.1f} s: {setup.sim.flow.n_dofs} unknowns, "
          f"dt {setup.dt:.6g} s, largest resident memory {largest[0] / 1e9:.2f} GB", flush=True)
    for k in range(steps):
        t1 = time.perf_counter()
        report = setup.sim.step(setup.dt)
        print(json.dumps(dict(step=k, wall_s=round(time.perf_counter() - t1, 2),
                              linear_s=round(report.linear.time_s, 2), cycles=report.linear.iterations,
                              solves=report.linear.solves, peak_gb=round(_peak_gb(), 2))), flush=True)
    n = setup.sim.flow.n_dofs
    print(f"peak {_peak_gb():.2f} GB, {_peak_gb() * 1e9 / n:.0f} bytes per unknown")
