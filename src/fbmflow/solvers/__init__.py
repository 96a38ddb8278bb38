"""Linear solvers (direct; multigrid plugs into the same interface) and Newton's method."""
from .linear import LINEAR_SOLVERS, DirectSolver, LinearReport, SaddlePointSystem, make_linear_solver
from .newton import ConvergenceError, NewtonReport, NewtonSettings, solve_newton

__all__ = ["SaddlePointSystem", "LinearReport", "DirectSolver", "LINEAR_SOLVERS",
           "make_linear_solver", "NewtonSettings", "NewtonReport", "solve_newton",
           "ConvergenceError"]
