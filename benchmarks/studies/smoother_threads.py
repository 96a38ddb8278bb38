"""One smoothing sweep of the factored Vanka smoother against Numba's thread count, in the
sweep order of today and in slabs only.

Question: how fast is one smoothing sweep on 1, 2, ... threads in the blocked order with the
far-reaching patches set aside, against the slab order it replaced, and what do the parts that
run on one thread cost?
Answer: ten Cate level 1 (278 739 unknowns, 12 x 12 x 64 cells), on this 2-core machine: the
blocked order gives 16 groups per phase (slabs only: 4, the sphere's rows reaching 6
half-cells). Its phases took 148.4 / 68.4 ms on 1 / 2 threads against 154.0 / 90.6 ms in slabs
in one run, and 138.4 / 99.4 against 173.4 / 96.9 ms in another: on 2 cores the difference is
within the machine's noise. On the 16-core machine the slab order's sweep stopped at 63 ms from
4 threads on (1 thread: 135 ms; memory bandwidth 13 / 91 GB/s on 1 / 16 threads); the blocked
order there is not measured yet. The 86 agglomerated patches take 35 colours: 8.1 / 4.5 ms on
1 / 2 threads, against 7.1 / 6.7 ms one by one. One V-cycle of the hierarchy (8e498bb, two runs
minutes apart, tags cycle-8e498bb and cycle-8e498bb-b): 988 / 789 ms and 1 446 / 761 ms on
1 / 2 threads, 1.25x and 1.90x: the 2-thread time holds, the 1-thread time scatters by half.
Measured: 2026-11-28, commit 3fd90f7 (and d59c63a); the cycle 2026-11-29, 8e498bb; quoted in
docs/validation/multigrid-with-fictitious-boundaries.md, "Threads"
Run: python -m fbmbench smoother_threads --threads 1 2 --repeats 5

The scene is built at ``level``, one time step taken, and the last linear system it solved (its
Picard preconditioner where it has one) given two factored Vanka smoothers: one in today's order
(:mod:`fbmflow.solvers.ordering`) and one in slabs along one axis with the gap of the
furthest-reaching row (the order before blocks). For each thread count (one process,
``numba.set_num_threads``) each part of a sweep is timed, best of ``repeats``: the parallel phases,
the far patches' sequential updates, the interface patches' extra sweep, the agglomerated
patches' updates one by one (as before) and in colours (as now), and one product with the system
(:meth:`SaddlePointSystem.apply`); in today's order, one V-cycle of the system's multigrid hierarchy
as well (the sweeps, residuals, transfers and the coarsest solve).

writes benchmarks/results/smoother_threads.{json,md}: the rows of this run with the machine;
``--tag`` names the run (rows with other tags are kept).
"""
from __future__ import annotations

import json
import time
from pathlib import Path

from studies.thread_scaling import machine

BENCHMARKS = Path(__file__).resolve().parents[1]
RESULTS = BENCHMARKS / "results"


def _best(f, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        f()
        times.append(time.perf_counter() - t0)
    return min(times)


def last_system(scene: str, level: int):
    """The last linear system one time step of ``scene`` at ``level`` solved (its Picard
    preconditioner where it has one): the scene is built, every flow problem hands over the
    systems it solves, and one step is taken."""
    import fbmflow.flow.navier_stokes as ns
    from fbmflow.scenes.registry import load_scene

    captured = []
    init = ns.NavierStokesProblem.__init__

    def hooked(self, *args, **kwargs):
        init(self, *args, **kwargs)
        self.on_linear_solve = lambda report, system: captured.append(system)

    ns.NavierStokesProblem.__init__ = hooked
    try:
        sc, params, lvl = load_scene(scene, level, [])
        setup = sc.build(params, lvl)
        setup.sim.step(setup.dt)
    finally:
        ns.NavierStokesProblem.__init__ = init
    return captured[-1].preconditioner or captured[-1]


def table(rows: list[dict]) -> str:
    lines = ["# One smoothing sweep against threads (python -m fbmbench smoother_threads)", "",
             "Times in ms, best of the repeats, one process per tag; `groups`: groups per phase of the "
             "parallel sweep; `far`: patches updated one by one after the phases. Speed-up: over the "
             "same order's fewest threads in the same run.", "",
             "| tag | machine | scene | level | unknowns | order | groups | far | threads | phases | "
             "far updates | interface | agglomerated one by one | in colours (colours) | apply | "
             "speed-up of the phases | V-cycle | speed-up of the cycle |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    fewest = {}
    for r in rows:
        key = (r["tag"], r["order"])
        if key not in fewest or r["threads"] < fewest[key]["threads"]:
            fewest[key] = r
    for r in rows:
        speedup = fewest[(r["tag"], r["order"])]["phases_ms"] / r["phases_ms"]
        coloured = f"{r['merged_colours_ms']:.1f} ({r['colours']})" if "colours" in r else ""
        first = fewest[(r["tag"], r["order"])]
        cycle = (f"{r['cycle_ms']:.1f} | {first['cycle_ms'] / r['cycle_ms']:.2f}" if "cycle_ms" in r
                 and "cycle_ms" in first else " | ")
        lines.append(f"| {r['tag']} | {r['machine']} | {r['scene']} | {r['level']} | {r['unknowns']} | "
                     f"{r['order']} | {r['groups']} | {r['far']} | {r['threads']} | {r['phases_ms']:.1f} | "
                     f"{r['far_ms']:.1f} | {r['interface_ms']:.1f} | {r['merged_ms']:.1f} | {coloured} | "
                     f"{r['apply_ms']:.1f} | {speedup:.2f} | {cycle} |")
    return "\n".join(lines) + "\n"


def run(*, threads: list[int] = (1, 2), scene: str = "ten-cate", level: int = 1, repeats: int = 3,
        tag: str = "dev") -> None:
    """Time the parts of one sweep at every thread count, in both orders.

    Parameters
    ----------
    threads : Numba thread counts (at most the process's NUMBA_NUM_THREADS)
    scene : the scene
    level : its level
    repeats : timings per part; the best is kept
    tag : this run's name in the results (rows with other tags are kept)
    """
    import numba
    import numpy as np

    from fbmflow.solvers import MultigridSettings, MultigridSolver, ordering
    from fbmflow.solvers.vanka import FactoredVankaSmoother

    system = last_system(scene, level)
    hierarchy = MultigridSolver(MultigridSettings(threads="fixed")).factor(system)
    smoothers = {"blocks, far set aside": FactoredVankaSmoother(system)}
    block_cells, far_share = ordering.BLOCK_CELLS, ordering.FAR_SHARE
    ordering.BLOCK_CELLS, ordering.FAR_SHARE = 10**18, 0.0  # the slab order: one axis, the widest gap
    try:
        smoothers["slabs"] = FactoredVankaSmoother(system)
    finally:
        ordering.BLOCK_CELLS, ordering.FAR_SHARE = block_cells, far_share
    b = np.random.default_rng(0).standard_normal(system.n_u + system.n_p)
    RESULTS.mkdir(exist_ok=True)
    path = RESULTS / "smoother_threads.json"
    kept = [r for r in json.loads(path.read_text()) if r["tag"] != tag] if path.exists() else []
    rows, where = [], machine()
    for k in threads:
        numba.set_num_threads(k)
        for order, sm in smoothers.items():
            phases, far = sm.sweeps[0]
            x = np.zeros_like(b)
            sm.sweep_phases(phases, b, x)  # compiled, caches warm
            row = dict(tag=tag, machine=where, scene=scene, level=level, unknowns=system.n_u + system.n_p,
                       order=order, groups=[len(g) - 1 for g, _ in phases], far=int(far.size), threads=k,
                       phases_ms=1e3 * _best(lambda: sm.sweep_phases(phases, b, x), repeats),
                       far_ms=1e3 * _best(lambda: sm.update(far, b, x), repeats),
                       interface_ms=1e3 * _best(lambda: sm.sweep_phases(sm.interface_phases, b, x), repeats),
                       merged_ms=1e3 * _best(lambda: sm.update(sm.merged, b, x), repeats),
                       merged_colours_ms=1e3 * _best(lambda: sm.sweep_phases(sm.merged_phases, b, x),
                                                     repeats),
                       colours=len(sm.merged_phases),
                       apply_ms=1e3 * _best(lambda: system.apply(x), repeats))
            if order == "blocks, far set aside":  # today's order: the hierarchy's smoothers
                hierarchy.cycle(b, np.zeros_like(b))
                row["cycle_ms"] = 1e3 * _best(lambda: hierarchy.cycle(b, np.zeros_like(b)), repeats)
            rows.append(row)
            print(f"{order}, {k} threads: phases {row['phases_ms']:.1f} ms (groups {row['groups']}), far "
                  f"{row['far_ms']:.1f} ms ({row['far']}), agglomerated {row['merged_ms']:.1f} ms, apply "
                  f"{row['apply_ms']:.1f} ms", flush=True)
    path.write_text(json.dumps(kept + rows, indent=1))
    (RESULTS / "smoother_threads.md").write_text(table(kept + rows))
