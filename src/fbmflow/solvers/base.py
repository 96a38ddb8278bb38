"""The linear-solver contract: what the flow problem asks of a linear solver, and nothing more.

A :class:`LinearSolver` turns one linearised saddle-point system
(:class:`~fbmflow.solvers.system.SaddlePointSystem`) into a :class:`Factorization` (its sparse LU,
or its multigrid hierarchy: PyAMG's ``MultilevelSolver``), whose :meth:`~Factorization.solve`
answers one or several right-hand sides to a relative residual ``rtol``. A solver that needs
coarse re-discretisations says what it needs through :meth:`LinearSolver.hierarchy`; the flow
problem builds them (it owns the meshes), the solver never reads the flow problem's state and the
flow problem never probes the solver's attributes. The memory and cost models of
:mod:`fbmflow.solvers.choice` know a solver by its :meth:`~LinearSolver.engine`.
"""
from __future__ import annotations

import functools
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Callable

import numpy as np
import scipy.sparse as sp

from ..fem import FlowSpace, apply_mass_laplace
from .reports import LinearReport
from .sparse import DivergenceProducts
from .system import SaddlePointSystem


@dataclass(frozen=True)
class Hierarchy:
    """The coarse systems a solver asks the flow problem to build with each linearisation.

    picard : bool
        Build the hierarchy from the Picard linearisation; the solver's Krylov iteration applies
        the system's own (Newton) operator, which the flow problem then hands over without a
        matrix (:class:`~fbmflow.flow.levels.NewtonBlock`).
    follows_iterates : bool
        The solver's Krylov iteration applies the fine operator itself, so the flow problem may
        move that operator to later Newton iterates and keep the hierarchy
        (:meth:`~fbmflow.flow.levels.NewtonBlock.relinearise`).
    galerkin : bool
        Coarse levels take Galerkin rows of the truncated prolongation next to the constraints
        beyond the walls (:mod:`fbmflow.solvers.galerkin`) instead of constraining their own nodes.
    """

    picard: bool = False
    follows_iterates: bool = False
    galerkin: bool = False


class Factorization(ABC):
    """A linear solver set up for one saddle-point system.

    ``setup_time_s`` is the set-up's wall time [s]; it is charged to the first solve's report
    (``_charge_setup``), so that a run's summed solve times include every set-up once.
    """

    #: whether :meth:`solve` takes ``k`` right-hand sides at once, ``f (n_u, k)``, ``g (n_p, k)``
    multiple_rhs: bool = False

    def __init__(self, setup_time_s: float = 0.0):
        self.setup_time_s = float(setup_time_s)
        self._setup_billed = False

    @abstractmethod
    def solve(self, f: np.ndarray, g: np.ndarray, rtol: float | None = None
              ) -> tuple[np.ndarray, np.ndarray, LinearReport]:
        """``(u (n_u,), p (n_p,), report)`` solving ``[[A, B], [B^T, 0]] [u, p] = [f, g]`` to the
        relative residual ``rtol`` (None: the solver's own target; a direct solver without
        refinement is exact to round-off whatever ``rtol``). With :attr:`multiple_rhs`, ``f``
        and ``g`` may carry ``k`` columns, and so do ``u`` and ``p``."""

    def forget(self) -> None:
        """Free what the set-up holds (factors, smoother blocks); the default holds nothing
        beyond what garbage collection frees."""

    def _charge_setup(self) -> float:
        """The set-up time the first call gets, 0 for the others."""
        if self._setup_billed:
            return 0.0
        self._setup_billed = True
        return self.setup_time_s


class LinearSolver(ABC):
    """A linear solver for the flow problem's saddle-point systems (see the module docstring).

    ``name``: the registry's name (:data:`fbmflow.solvers.LINEAR_SOLVERS`), in reports.
    """

    name: str = ""

    @abstractmethod
    def factor(self, system: SaddlePointSystem) -> Factorization:
        """Set up ``system`` (factorise it, or build its hierarchy from its ``coarser`` chain)."""

    def hierarchy(self, time_step: bool) -> Hierarchy | None:
        """The coarse systems this solver needs with a system of a time step (``time_step``) or
        of a steady solve; None: none (the default)."""
        return None

    @abstractmethod
    def engine(self, dim: int, n_unknowns: int) -> str:
        """The engine that solves a ``dim``-dimensional system of ``n_unknowns``: ``"superlu"``,
        ``"pardiso"`` or ``"multigrid"`` (the keys of the cost and memory models,
        :mod:`fbmflow.solvers.choice`)."""

    def describe(self, dim: int, n_unknowns: int) -> str:
        """The solver in words for reports, e.g. ``"direct (SuperLU)"`` or ``"multigrid"``."""
        return self.name

    def velocity_operator(self, space: FlowSpace) -> Callable[..., np.ndarray]:
        """``apply(alpha, beta, u, convection=0.0)``: ``(alpha M + beta L + convection N(u)) u``
        on ``space`` for a velocity ``u (dim * n_v,)`` -> ``(dim * n_v,)`` float64, host arrays
        in and out, which the flow problem's residuals and time-step right-hand sides apply. The
        default is the CPU's (:func:`~fbmflow.fem.assembly.apply_mass_laplace`); a solver on a device
        applies it there (:mod:`fbmflow.gpu`)."""
        return functools.partial(apply_mass_laplace, space)

    def divergence_products(self, space: FlowSpace, BT: sp.csr_matrix) -> DivergenceProducts:
        """``gradient(p)``: ``B p`` (n_u,), and ``continuity(u)``: ``B^T u`` (n_p,), of the
        level's divergence ``BT (n_p, n_u)`` on ``space``, host arrays in and out, which the flow
        problem's residuals apply. The default is the CPU's
        (:class:`~fbmflow.solvers.sparse.DivergenceProducts`); a solver on a device applies them
        there, from its copy of ``BT`` (:mod:`fbmflow.gpu`)."""
        return DivergenceProducts(space, BT)

    def forget(self) -> None:
        """Drop what the solver keeps between factorisations (the default keeps nothing): the
        next set-up starts afresh, as after a restart."""

    def solve(self, system: SaddlePointSystem, f: np.ndarray, g: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray, LinearReport]:
        """Set up ``system`` and solve one right-hand side (a convenience for single solves)."""
        return self.factor(system).solve(f, g)
