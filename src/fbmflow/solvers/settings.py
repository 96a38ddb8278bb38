"""The solver settings a scene or a :class:`~fbmflow.simulation.Simulation` takes: Newton and the
linear solver (:class:`~fbmflow.solvers.settings.SolverParams`, with its multigrid table
``[solver.multigrid]``)."""
from __future__ import annotations

import dataclasses

import numpy as np

from ..config import ParamError, Section, param, section
from .base import LinearSolver
from .choice import choose_linear_solver
from .multigrid import MultigridSettings
from .newton import NewtonSettings

#: where the linear solves run (:attr:`SolverParams.device`)
DEVICES = ("cpu", "gpu")


@dataclasses.dataclass(frozen=True)
class SolverParams(Section):
    """Nonlinear and linear solver settings."""

    renamed = {f"mg_{key}": f"multigrid.{key}" for key in ("cycle", "smoother", "coarse_obstacle", "krylov",
                                                           "linearisation", "sweeps")}
    renamed["mg_smoothing_steps"] = "multigrid.pre_smooth and multigrid.post_smooth"

    linear: str = param("auto", "linear solver for the Newton systems ('auto': the cheaper of the two by "
                        "measured cost for the size, the accuracy asked and the coupling's responses, "
                        "among those whose memory fits; fbmflow.solvers.choice)",
                        choices=("auto", "direct", "multigrid"))
    linear_rtol: float = param(1e-8, "relative residual per linear solve (multigrid: its stopping "
                               "rule; direct with PARDISO: its refinement target in Newton steps)",
                               positive=True, maximum=0.1)
    multigrid: MultigridSettings = section(MultigridSettings)
    newton_rtol: float = param(1e-10, "Newton stop: residual reduction", positive=True, maximum=1.0)
    newton_atol: float = param(1e-12, "Newton stop: absolute residual", positive=True)
    newton_max_iterations: int = param(30, "Newton iteration limit per solve", minimum=1)
    newton_reuse_jacobian: bool = param(True, "keep a factorised Jacobian while it contracts the "
                                        "residual 10x per iteration (same solution, less work)")
    device: str = param("cpu", "where the linear solves run: cpu, or gpu (multigrid's cycles and FGMRES on "
                        "an NVIDIA GPU, the set-up and the coarsest level on the CPU; the gpu extra; "
                        "fbmflow.gpu)", choices=DEVICES)
    process_grid: str = param("auto", "on several processes, how many divide every axis of the mesh, "
                              "as '2x2x4' (the product the number of processes), or 'auto': the grid that "
                              "divides the most multigrid levels, then the one with the fewest cell faces "
                              "between the blocks (fbmflow.flow.blocks)")

    def validate(self):
        if self.device == "gpu" and self.linear == "direct":
            raise ParamError("solver.device = 'gpu' runs multigrid, not the direct solver: set "
                             "solver.linear = 'multigrid' (or 'auto'), or solver.device = 'cpu'")
        if self.device == "gpu" and self.multigrid.smoother not in ("auto", "vanka-factored"):
            raise ParamError("solver.device = 'gpu' smoothes with vanka-factored, not "
                             f"{self.multigrid.smoother!r}: set solver.multigrid.smoother = 'auto'")

    def grid(self, size: int, dim: int) -> tuple[int, ...] | None:
        """The process grid of :attr:`process_grid` for ``size`` processes on a ``dim``-dimensional
        mesh (None: 'auto', or one process); ParamError where it is not ``dim`` whole numbers
        whose product is ``size``."""
        if self.process_grid == "auto" or size == 1:
            return None
        try:
            grid = tuple(int(g) for g in self.process_grid.lower().split("x"))
        except ValueError:
            grid = ()
        if len(grid) != dim or min(grid) < 1 or int(np.prod(grid)) != size:
            raise ParamError(f"solver.process_grid = {self.process_grid!r} is not a grid of {size} processes "
                             f"over the mesh's {dim} axes: give {dim} whole numbers joined by 'x' whose "
                             f"product is {size} (as {'x'.join(['1'] * (dim - 1) + [str(size)])}), or 'auto'")
        return grid

    def on_processes(self, size: int) -> "SolverParams":
        """These settings for a run on ``size`` processes: multigrid on several (the one solver
        that divides among them), ParamError where the direct solver or the GPU is asked for
        there."""
        if size == 1:
            return self
        if self.device == "gpu":
            raise ParamError("solver.device = 'gpu' runs on one process: start one, or set solver.device = "
                             "'cpu' to run on several")
        if self.linear == "direct":
            raise ParamError("the direct solver runs on one process: set solver.linear = 'multigrid' (or "
                             "'auto') to run on several")
        return dataclasses.replace(self, linear="multigrid")

    def linear_solver(self, dim: int, n_unknowns: int, responses: int = 0) -> LinearSolver:
        """The linear solver for a ``dim``-dimensional flow of ``n_unknowns``, ``"auto"`` resolved
        with ``responses`` right-hand sides per step besides the Newton steps
        (:func:`~fbmflow.solvers.choice.choose_linear_solver`)."""
        linear = "multigrid" if self.device == "gpu" else self.linear
        return choose_linear_solver(dim, n_unknowns, self.linear_rtol, linear, self.multigrid, responses)

    def newton_settings(self) -> NewtonSettings:
        """The Newton stopping rule and Jacobian reuse of these settings."""
        return NewtonSettings(rtol=self.newton_rtol, atol=self.newton_atol,
                              max_iterations=self.newton_max_iterations,
                              reuse_jacobian=self.newton_reuse_jacobian, linear_rtol=self.linear_rtol)


@dataclasses.dataclass(frozen=True)
class SteadySolverParams(SolverParams):
    """Solver settings of a steady Newton solve: inexact Newton steps (the stopping rule is on the
    nonlinear residual, so the accuracy is Newton's; measured cost: docs/validation/)."""

    linear_rtol: float = param(1e-2, "relative residual per linear solve (inexact Newton steps; the "
                               "Newton stop on the nonlinear residual decides the accuracy; multigrid: "
                               "at most this, tighter near the solution by Eisenstat-Walker)",
                               positive=True, maximum=0.1)
    continuation_rtol: float = param(1e-3, "Newton stop of the intermediate steady solves of a continuation "
                                     "(they only start the next one; the last solves to newton_rtol)",
                                     positive=True, maximum=1.0)
