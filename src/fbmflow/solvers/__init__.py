"""Linear solvers (sparse direct, geometric multigrid with Vanka smoothing, FGMRES) and Newton."""
from .direct import DirectSolver, factorize
from .krylov import fgmres
from .multigrid import MultigridSettings, MultigridSolver
from .newton import ConvergenceError, NewtonReport, NewtonSettings, solve_newton
from .reports import LinearReport
from .system import SaddlePointSystem
from .vanka import VANKA_VARIANTS, VankaSmoother

#: the linear solvers by name (the parameter ``solver.linear``, besides ``auto``)
LINEAR_SOLVERS = {"direct": DirectSolver, "multigrid": MultigridSolver}


def make_linear_solver(name: str, **settings):
    """Instantiate a registered linear solver by name (settings go to its constructor)."""
    try:
        cls = LINEAR_SOLVERS[name]
    except KeyError:
        raise ValueError(f"unknown linear solver {name!r}; choose one of {sorted(LINEAR_SOLVERS)}") from None
    return cls(**settings)


__all__ = ["SaddlePointSystem", "LinearReport", "DirectSolver", "factorize", "MultigridSolver",
           "MultigridSettings", "VankaSmoother", "VANKA_VARIANTS", "fgmres", "LINEAR_SOLVERS",
           "make_linear_solver", "NewtonSettings", "NewtonReport", "solve_newton", "ConvergenceError"]
