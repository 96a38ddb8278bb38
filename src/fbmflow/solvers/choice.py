"""``solver.linear = "auto"``: the linear solver that costs least, by measured cost.

The time of one linear solve (its share of the factorisation or the multigrid set-up included)
is modelled per solver as ``t = c n (n / n_ref)^p`` seconds for ``n`` unknowns, with constants
fitted to runs on this project's 2-core machine (benchmarks/results/solver_table.md and the
rows cited below). A multigrid solve costs cycles, whose number grows with the accuracy asked of
it: the model has one constant for loose solves (relative residual 1e-3 or more, two to four
cycles: inexact Newton steps, time steps) and one for tight ones (about ten cycles). Candidates
are the direct solver (PARDISO where installed, else SuperLU) and multigrid; a candidate whose
memory estimate exceeds what the machine has is left out.
"""
from __future__ import annotations

from collections.abc import Callable

#: (dim, solver) -> (c [s per unknown at n_ref], n_ref, p). Direct solvers fill more than
#: linearly; multigrid is linear. Measured per solve: cavity-2d level 3 (45 570 unknowns, steady
#: Newton): SuperLU 0.48 / 0.39 s, PARDISO 0.18 / 0.13 s, multigrid 0.31 / 0.32 s (2.4 cycles) at
#: Re 400 / 1000; glowinski-free-fall level 2 (17 106 unknowns, time steps to 1e-8): SuperLU
#: 0.19 s, multigrid 1.4 s (12 cycles); ten-cate (time steps to 1e-3): PARDISO about 1.0 / 11 s
#: at 64 547 / 278 739 unknowns, multigrid 0.5 / 1.7 s; channel-3d level 4 (486 979 unknowns,
#: steady Newton): multigrid 8.6 s (3.3 cycles). SuperLU in 3D (nested-dissection order), one
#: factorisation and solve of a channel-3d Stokes system: 0.13 / 16.0 s at 9 043 / 64 547
#: unknowns (idle machine; 0.35 / 42.7 s in COLAMD's order beside another job).
SOLVE_COST = {
    (2, "superlu"): (9.5e-6, 45_570, 0.5),
    (2, "pardiso"): (3.5e-6, 45_570, 0.2),
    (2, "multigrid"): (7.0e-6, 45_570, 0.0),
    (2, "multigrid-tight"): (8.0e-5, 17_106, 0.0),
    (3, "superlu"): (2.5e-4, 64_547, 1.45),
    (3, "pardiso"): (1.6e-5, 64_547, 0.5),
    (3, "multigrid"): (1.2e-5, 278_739, 0.0),
    (3, "multigrid-tight"): (4.0e-5, 278_739, 0.0),
}
#: multigrid solves asked for a relative residual below this count as tight
TIGHT_RTOL = 1e-3


def solve_time(solver: str, dim: int, n_unknowns: int, rtol: float | None = None) -> float:
    """Modelled seconds per linear solve (:data:`SOLVE_COST`): ``solver`` ``"superlu"``,
    ``"pardiso"`` or ``"multigrid"`` (``rtol``: the relative residual asked of it; None: tight)."""
    key = solver
    if solver == "multigrid" and (rtol is None or rtol < TIGHT_RTOL):
        key = "multigrid-tight"
    c, n_ref, p = SOLVE_COST[(dim, key)]
    return c * n_unknowns * (n_unknowns / n_ref) ** p


def cheapest_solver(dim: int, n_unknowns: int, rtol: float | None, pardiso: bool,
                    fits: Callable[[str], bool] = lambda solver: True) -> str:
    """``"direct"`` or ``"multigrid"``, whichever :func:`solve_time` says is cheaper (the direct
    solver being PARDISO when ``pardiso``, else SuperLU), among those for which ``fits(name)``
    (``"direct"`` / ``"multigrid"``: its memory fits the machine); multigrid when neither fits
    (it needs the least)."""
    direct = solve_time("pardiso" if pardiso else "superlu", dim, n_unknowns)
    multigrid = solve_time("multigrid", dim, n_unknowns, rtol)
    if direct <= multigrid and fits("direct"):
        return "direct"
    return "multigrid"
