"""The factored Vanka smoother's set-up on every level of a scene's first multigrid hierarchy.

Question: how long does the factored Vanka smoother take to set up (patches, the operator's parts,
reach, colours; no local factors: the GPU path's set-up, on the CPU at every linearisation) on each
level of a scene's first linear system?
Answer: ten Cate E4 level 2 (2 012 403 unknowns on the finest of 4 levels, 2 cores), repeats 2-8:
the three smoothers 0.240-0.286 s per set-up (median 0.275 s; the finest 0.207-0.249 s) with the
cell patches' unknowns kept per space, the patches' reach and interface found by a parallel kernel
and the rows merged in parallel (tag kept-patches, 2a6c098), against 0.459-0.488 s (median 0.471 s;
the finest 0.405-0.432 s) at 522b7e5 the same hour (session-head): 0.58 of the median. Earlier,
another hour: 0.408 s (gradient-rows, 21475c4, the gradient's rows read from the divergence cell
by cell) against 0.790 s at dd47fbe, which built the whole gradient at each set-up;
results/smoother_setup.md.
Measured: 2026-12-02, commit 2a6c098 and 522b7e5 before it (in a git worktree,
``FBMFLOW_BENCH_COMMIT=522b7e5``), one after the other; 21475c4 and dd47fbe likewise, earlier;
quoted in docs/validation/gpu.md
Run: python -m fbmbench smoother_setup --tag now

The scene is built at its defaults with ``solver.linear=multigrid``; its first time step runs up to
the first multigrid factorisation, whose system is kept (the step goes no further). Then
``repeats`` times, one after the other in this process, a
:class:`~fbmflow.solvers.vanka.FactoredVankaSmoother` (colour order, ``factor=False``) is built on
every level but the coarsest, each timed. The first repeat includes what is made once per level and
kept (the reach of the space and of the divergence, the check of its cell pattern) and Numba's
compilation or cache load. Time nothing beside another job.
"""
from __future__ import annotations

import time

from fbmbench.common import commit, merge_row

from studies.thread_scaling import RESULTS, machine


class _Caught(Exception):
    """Stops the step once the multigrid factorisation has its system."""


def _first_system(scene_name: str, level: int):
    """The first system the scene's multigrid solver is asked to factor."""
    from fbmflow.scenes.registry import load_scene
    from fbmflow.solvers import multigrid

    caught = {}

    def factor(self, system):
        caught["system"] = system
        raise _Caught

    original = multigrid.MultigridSolver.factor
    multigrid.MultigridSolver.factor = factor
    try:
        scene, params, level = load_scene(scene_name, level, ["solver.linear=multigrid"])
        setup = scene.build(params, level)
        try:
            setup.sim.step(setup.dt)
        except _Caught:
            pass
    finally:
        multigrid.MultigridSolver.factor = original
    if "system" not in caught:
        raise SystemExit(f"smoother_setup: {scene_name} level {level} asked for no multigrid factorisation")
    system = caught["system"]
    return system.preconditioner or system


def table(rows: list[dict]) -> str:
    lines = ["# The factored Vanka smoother's set-up per level (python -m fbmbench smoother_setup)", "",
             "Each row one process: the scene's first multigrid system, the smoother (colour order, no "
             "local factors) built on every level but the coarsest, `repeats` times one after the other. "
             "Seconds per level, finest first; the first repeat includes what is kept per level and "
             "Numba's cache load.", "",
             "| scene | level | unknowns per level | repeat | s per level | s in all | machine | measured "
             "| tag |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        for k, seconds in enumerate(r["seconds"]):
            lines.append(f"| {r['scene']} | {r['level']} | {' / '.join(map(str, r['unknowns']))} | {k + 1} | "
                         f"{' / '.join(f'{s:.3f}' for s in seconds)} | {sum(seconds):.3f} | {r['machine']} | "
                         f"{r['measured']} | {r['tag']} |")
    return "\n".join(lines) + "\n"


def run(*, scene: str = "ten-cate", level: int = 2, repeats: int = 4, tag: str = "") -> None:
    """Time the smoothers' set-up on the levels of ``scene``'s first multigrid system.

    Parameters
    ----------
    scene : the scene
    level : its level
    repeats : set-ups of every level, one after the other
    tag : names this run's row in the results
    """
    from fbmflow.solvers.vanka import FactoredVankaSmoother

    fine = _first_system(scene, level)
    levels = []
    while fine is not None:
        levels.append(fine)
        fine = fine.coarser
    seconds = []
    for k in range(repeats):
        seconds.append([])
        for system in levels[:-1]:
            t0 = time.perf_counter()
            FactoredVankaSmoother(system, order="colours", factor=False)
            seconds[-1].append(time.perf_counter() - t0)
        print(f"repeat {k + 1}: " + " / ".join(f"{s:.3f}" for s in seconds[-1]) + " s", flush=True)
    row = dict(scene=scene, level=level, unknowns=[s.n_u + s.n_p for s in levels[:-1]], seconds=seconds,
               machine=machine(), measured=f"{time.strftime('%Y-%m-%d')} {commit()}", tag=tag)
    rows = merge_row("smoother_setup", row, lambda old, new: (old["scene"], old["level"], old["tag"]) ==
                     (new["scene"], new["level"], new["tag"]))
    (RESULTS / "smoother_setup.md").write_text(table(rows))
