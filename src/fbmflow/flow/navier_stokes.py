"""The incompressible Navier–Stokes problem on a Q2/P1disc space (knows no particles).

    rho (du/dt + (u . grad) u) - mu Laplace u + grad p = f,     div u = 0.

Every solve (steady, or one implicit substep of a time scheme) is the nonlinear system

    F_u(u, p) = m rho M u + a (mu L u + rho N(u) u) + B p - rhs = 0,      F_p = B^T u = 0,

with ``m = 0, a = 1, rhs = f`` for the steady problem; :mod:`fbmflow.flow.time_schemes` supplies
``m, a, rhs`` for the time steps. Newton's Jacobian of ``F_u`` is
``m rho M + a (mu L + rho N(u) + rho R(u))``. The unknown vector is ``x = [u (dim * n_v), p (n_p)]``,
velocity component-blocked.
"""
from __future__ import annotations

import dataclasses
import logging
from typing import Callable

import numpy as np
import scipy.sparse as sp

from ..fem import FlowSpace, assemble_load
from ..fem.constraints import DirichletConstraints
from ..fem.continuity_block import ContinuityBlock
from ..mesh import StructuredMesh
from ..solvers import ConvergenceError, NewtonSettings, SaddlePointSystem, solve_newton
from ..solvers.base import Factorization, LinearSolver
from ..solvers.choice import choose_linear_solver
from ..solvers.galerkin import dilate_cells, galerkin_coarse_system
from ..solvers.reports import LinearWork
from ..solvers.system import balance_volume
from .boundary import Dirichlet, build_constraints, check_boundary, pressure_is_determined
from .levels import FlowLevel, NewtonBlock, coarse_levels, inject_velocity

log = logging.getLogger(__name__)

#: Newton's residual reduction for the Stokes flow that starts a steady solve from rest
STOKES_START_RTOL = 1e-3
#: unknowns above which a coarsest multigrid level is kept coarsened further, whatever the cell
#: Reynolds number of the coarser levels (``_resolving_levels``)
COARSEST_UNKNOWNS = {2: 50_000, 3: 20_000}


class NavierStokesProblem:
    """Incompressible (Navier–)Stokes flow on a structured mesh.

    Parameters
    ----------
    mesh : StructuredMesh
    viscosity : float
        Dynamic viscosity ``mu`` [Pa s] (> 0).
    boundary : dict tag -> condition
        One of :mod:`fbmflow.flow.boundary`'s conditions for every non-periodic face.
    density : float, default 1
        ``rho`` [kg/m^3] (> 0).
    body_force : callable ``f(x (n, dim), t) -> (n, dim)``, optional
        Force per unit volume [N/m^3].
    convection : bool, default True
        False solves the (time-dependent) Stokes equations.
    linear_solver : LinearSolver, optional
        A :class:`~fbmflow.solvers.base.LinearSolver` (e.g. a configured
        :class:`~fbmflow.solvers.multigrid.MultigridSolver`); default: the cheaper by measured cost for
        this size and ``newton.linear_rtol`` (:func:`fbmflow.solvers.choice.choose_linear_solver`).
    newton : NewtonSettings
    coarse_cells : int, optional
        Multigrid only: the coarsest level keeps at least this many cells (default 16 in 2D,
        8 in 3D).
    extra_constraints : callable ``(DofMap, t) -> DirichletConstraints``, optional
        Further velocity constraints evaluated on every level (the fictitious boundaries of
        particles and obstacles); the box faces win where both constrain a DOF.
    max_cell_reynolds : float, default 64
        Multigrid only: no level coarser than cell Reynolds number ``rho U h / mu`` of this,
        with ``U = max |u|`` at the first linearisation.
    """

    def __init__(self, mesh: StructuredMesh, viscosity: float, boundary: dict,
                 density: float = 1.0, body_force: Callable | None = None,
                 convection: bool = True, linear_solver: LinearSolver | None = None,
                 newton: NewtonSettings = NewtonSettings(), coarse_cells: int | None = None,
                 max_cell_reynolds: float = 64.0, extra_constraints=None):
        if not viscosity > 0:
            raise ValueError(f"viscosity must be positive, got {viscosity}")
        if not density > 0:
            raise ValueError(f"density must be positive, got {density}")
        check_boundary(mesh.tags, boundary)
        coarse_cells = coarse_cells or (16 if mesh.dim == 2 else 8)
        self.mesh = mesh
        self.mu = float(viscosity)
        self.rho = float(density)
        self.boundary = dict(boundary)
        self.body_force = body_force
        self.convection = convection
        self.newton = newton
        if linear_solver is None:
            linear_solver = choose_linear_solver(mesh.dim, FlowSpace.estimate_dofs(mesh), newton.linear_rtol)
        if not isinstance(linear_solver, LinearSolver):
            raise TypeError("linear_solver must be a LinearSolver (DirectSolver() or MultigridSolver()), got "
                            f"{linear_solver!r}")
        self.linear_solver = linear_solver
        pressure_fixed = not pressure_is_determined(boundary)
        self.extra_constraints = extra_constraints
        self.fine = self._fine_level(mesh, boundary, pressure_fixed, extra_constraints)
        self.space = self.fine.space
        #: ``(alpha M + beta L + convection N(u)) u`` without a matrix, where the linear solver
        #: applies it (:meth:`~fbmflow.solvers.base.LinearSolver.velocity_operator`)
        self._mass_laplace = linear_solver.velocity_operator(self.space)
        self.BT = self.fine.BT
        #: the gradient ``B p`` and continuity rows ``B^T u`` of the residuals, where the linear
        #: solver applies them (:meth:`~fbmflow.solvers.base.LinearSolver.divergence_products`)
        self._divergence = linear_solver.divergence_products(self.space, self.BT)
        self.mean_weights = self.fine.mean_weights
        self._pressure_fixed = pressure_fixed
        self.coarse_cells = coarse_cells
        self.max_cell_reynolds = max_cell_reynolds
        self._levels: list[FlowLevel] | None = None  # every coarser level, built at the first linearisation
        self.coarse: list[FlowLevel] | None = None  # those of the last linearisation
        self._steady_bc = not any(isinstance(b, Dirichlet) and callable(b.value) for b in boundary.values())
        self._constraints: DirichletConstraints | None = None
        self._linearisation = None  # (m, a, constraints, solve, system) of the last Newton step
        self.linear_work = LinearWork()  # every linear solve of this problem, counted
        #: ``on_linear_solve(report, system)``, called after every linear solve with its
        #: :class:`~fbmflow.solvers.reports.LinearReport` and the
        #: :class:`~fbmflow.solvers.system.SaddlePointSystem`
        #: it solved (a hook for studies and profiles; None: none)
        self.on_linear_solve = None

    #: the inner product of pressure vectors in sums over the mesh (None: ``p @ q``; one
    #: process's part of the mesh: the sum over its owned cells)
    _pressure_dot = None

    def _fine_level(self, mesh: StructuredMesh, boundary: dict, pressure_fixed: bool,
                    extra_constraints) -> FlowLevel:
        """The fine level's operators (a subclass holding them already returns its own)."""
        return FlowLevel(mesh, boundary, pressure_fixed, extra_constraints)

    def dot(self, x: np.ndarray, y: np.ndarray) -> float:
        """The Euclidean inner product of two vectors of this problem's unknowns (or velocities)
        over the whole mesh, each unknown once."""
        return float(x @ y)

    def norm(self, x: np.ndarray) -> float:
        """The Euclidean norm of a vector of this problem's unknowns (or velocities) over the
        whole mesh."""
        return float(np.sqrt(self.dot(x, x)))

    # -- data ---------------------------------------------------------------------------------
    @property
    def n_dofs(self) -> int:
        return self.space.n_dofs

    @property
    def linear_solver_description(self) -> str:
        """The linear solver in words, for reports: ``"multigrid"``, ``"direct (SuperLU)"`` or
        ``"direct (PARDISO)"`` (the backend ``"auto"`` picks for this problem)."""
        return self.linear_solver.describe(self.mesh.dim, self.n_dofs)

    def split(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Velocity (dim, n_v) and pressure (n_p,) views of ``x``."""
        s = self.space
        return x[:s.n_u].reshape(s.dim, s.n_v), x[s.n_u:]

    def constraints(self, t: float = 0.0, extra=None) -> DirichletConstraints:
        """Dirichlet constraints at time ``t`` (cached when they do not depend on time); ``extra``:
        the further constraints ``(DofMap, t) -> DirichletConstraints`` of this solve instead of
        ``extra_constraints`` (the same DOFs, other values: a coupling iteration's particle
        velocities)."""
        extra = extra or self.extra_constraints
        if self._steady_bc and extra is None:
            if self._constraints is None:
                self._constraints = build_constraints(self.space.V, self.boundary, t)
            return self._constraints
        con = build_constraints(self.space.V, self.boundary, t)
        if extra is not None:
            con = self._close_pockets(con.merged(extra(self.space.V, t)))
        return con

    def _close_pockets(self, con: DirichletConstraints) -> DirichletConstraints:
        return self.fine.close_pockets(con)

    def _any(self, flag: bool) -> bool:
        """Whether ``flag`` holds on any process that holds part of the mesh (this one's alone
        here): decisions that every process must take alike."""
        return bool(flag)

    def max_abs(self, x: np.ndarray) -> float:
        """``max |x_i|`` over the whole mesh's unknowns of a vector (or its velocity)."""
        return float(np.abs(x).max(initial=0.0))

    @property
    def whole_space(self) -> FlowSpace:
        """The whole mesh's FlowSpace (this problem's own where it holds the whole mesh)."""
        return self.space

    def whole_flow(self, x: np.ndarray) -> tuple[FlowSpace, np.ndarray]:
        """The whole mesh's space and flow of this problem's vector ``x`` on every process (every
        process calls it; one process: as they are), for measuring a solution."""
        return self.space, x

    def whole_indices(self, unknowns: np.ndarray) -> np.ndarray:
        """The whole mesh's numbers of a set of this problem's ``unknowns`` (e.g. the fixed ones
        of :meth:`~fbmflow.flow.navier_stokes.NavierStokesProblem.constraints`), sorted, from
        every process (every process calls it; one process: as they are)."""
        return np.sort(unknowns)

    def make_consistent(self, x: np.ndarray) -> np.ndarray:
        """``x`` (unknowns or velocities, in place) after a change that this process made by its
        own constraints, with every copy holding its owner's value (one process: as it is);
        returns ``x``."""
        return x

    def _complete(self, U: np.ndarray, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Columns ``[U; P]`` (velocity rows, pressure rows) computed cell by cell, completed (one
        process's part of the mesh: their ghosts from the owners); as they are for the whole
        mesh."""
        return U, P

    def load(self, t: float = 0.0) -> np.ndarray:
        """``int f · v`` for every velocity DOF, (dim * n_v,) float64."""
        s = self.space
        if self.body_force is None:
            return np.zeros(s.n_u)
        x = s.xq.reshape(-1, s.dim)
        f = np.asarray(self.body_force(x, t), dtype=float).reshape(s.mesh.n_cells, -1, s.dim)
        return assemble_load(s, f)

    def zero_state(self, t: float = 0.0) -> np.ndarray:
        """Zero flow with the boundary values at time ``t``: x (n_dofs,) float64."""
        x = np.zeros(self.n_dofs)
        self.constraints(t).apply_to_vector(x)
        return self.make_consistent(x)

    # -- operators ----------------------------------------------------------------------------
    def _apply_operator(self, u: np.ndarray, m: float, a: float) -> np.ndarray:
        """``(m rho M + a (mu L + rho N(u))) u`` for a velocity (dim * n_v,) -> (dim * n_v,), cell by
        cell in one pass without a matrix (:func:`~fbmflow.fem.apply_mass_laplace`, or on the linear
        solver's device)."""
        return self._mass_laplace(m * self.rho, a * self.mu, u,
                                  convection=a * self.rho if self.convection else 0.0)

    def apply_mass(self, u: np.ndarray) -> np.ndarray:
        """``M u`` (no density) for a velocity (dim * n_v,) -> (dim * n_v,), without a matrix."""
        return self._mass_laplace(1.0, 0.0, u)

    def apply_spatial(self, u: np.ndarray) -> np.ndarray:
        """``mu L u + rho N(u) u`` for a velocity (dim * n_v,) -> (dim * n_v,)."""
        return self._apply_operator(u, 0.0, 1.0)

    def residual(self, x: np.ndarray, m: float, a: float, rhs: np.ndarray,
                 con: DirichletConstraints, orphans: sp.csr_matrix | None = None) -> np.ndarray:
        """``[F_u, F_p]`` (n_dofs,) with the fixed rows of ``F_u`` zero (and those of row
        constraints their scaled residual ``s (C u - g)``).

        ``orphans (n_p, n_p)``: projector onto the pressure modes that no free velocity sees
        (see :func:`~fbmflow.solvers.system.orphan_pressure_modes`); their continuity equations
        are removed from ``F_p``: a cell covered by a particle and a wall has prescribed
        velocities whose divergence no unknown can change.
        """
        n_u = self.space.n_u
        u, p = x[:n_u], x[n_u:]
        Fu = self._apply_operator(u, m, a) + self._divergence.gradient(p) - rhs
        Fu[con.dofs] = 0.0
        Fp = self._continuity(u[:, None], con, orphans, base=self._divergence.continuity(u)[:, None])[:, 0]
        if con.rows is not None:  # row constraints, scaled as in the linear system
            scale = self.fine.row_scale(con.rows.dofs, m, a, self.rho, self.mu)
            Fu[con.rows.dofs] = scale * con.rows.residual(u)
        if con.extension is not None:
            Fp[con.extension.dofs] = con.extension.residual(p)
        return np.concatenate([Fu, Fp])

    def _continuity(self, U: np.ndarray, con: DirichletConstraints,
                    orphans: sp.csr_matrix | None, base: np.ndarray | None = None) -> np.ndarray:
        """Continuity residuals ``B u`` of velocities ``U (n_u, k)`` (dense, or sparse: liftings
        are non-zero on a particle's nodes only) with the orphaned modes dropped and, in a closed
        box, the volume defect of the prescribed velocities taken out as the linear solvers do
        (:func:`~fbmflow.solvers.system.balance_volume`), (n_p, k) dense. ``base``: the level
        divergence's ``BT @ U`` (n_p, k) where the caller has it, which may be overwritten or
        returned."""
        if con.continuity is None:
            Fp = ContinuityBlock(self.BT) @ U if base is None else base
            Fp = Fp.toarray() if sp.issparse(Fp) else Fp
        else:  # without a copy of B^T, which would raise the Newton iteration's peak
            Fp = con.continuity.product(self.BT, U, base)
        if con.extension is not None:
            Fp = con.extension.transfer(Fp)
        if orphans is not None:
            Fp = Fp - orphans @ Fp
        if self.mean_weights is None:
            return Fp
        return balance_volume(Fp, self.mean_weights, orphans, self.space.dim + 1, con.extension,
                              dot=self._pressure_dot)

    def orphans(self, con: DirichletConstraints) -> sp.csr_matrix | None:
        """Pressure modes that no free velocity sees under the constraints ``con``
        (:meth:`FlowLevel.orphans <fbmflow.flow.levels.FlowLevel.orphans>` of the fine level,
        kept for the next constraints on the same DOFs); None without extra constraints (the
        systems find those of the walls themselves)."""
        if self.extra_constraints is None:
            return None
        return self.fine.orphans(con)

    def _known_orphans(self, con: DirichletConstraints) -> sp.csr_matrix | None:
        """The fine level system's orphaned modes where this problem computes them (an empty
        matrix: none), else None (the system finds those of the walls itself)."""
        if self.extra_constraints is None:
            return None
        P = self.orphans(con)
        n_p = self.BT.shape[0]
        return sp.csr_matrix((n_p, n_p)) if P is None else P

    def linear_system(self, x: np.ndarray, m: float, a: float,
                      con: DirichletConstraints, t: float = 0.0, extra=None) -> SaddlePointSystem:
        """Newton linearisation at ``x`` with constraints applied; with a multigrid solver the
        system carries its re-discretisations on the coarser levels (``coarser`` chain), or,
        where the solver builds its hierarchy from the Picard linearisation
        (:meth:`~fbmflow.solvers.multigrid.MultigridSettings.picard_hierarchy`), a ``preconditioner`` system
        that does.

        The velocity blocks live in buffers of the levels and are overwritten by the next call.
        ``extra``: the solve's further constraints (:meth:`constraints`), which the coarser levels
        take too.
        """
        u = x[:self.space.n_u]
        needs = self.linear_solver.hierarchy(m != 0.0)
        self.coarse = self._resolving_levels(u, needs is not None)
        args = (m, a, self.rho, self.mu, self.convection)
        newton = not (self.coarse and self.convection and a != 0.0 and needs.picard)
        if newton:
            system = finer_system = self.fine.system(u, *args, con=con, orphans=self._known_orphans(con))
            if self.coarse and self.convection and a != 0.0 and needs.follows_iterates:
                # FGMRES applies it: it can follow later Newton iterates (relinearise)
                system = self.fine.newton_system(finer_system, u, a, self.rho, newton_base=True)
        else:  # the hierarchy of the Picard linearisation preconditions the Newton system, whose
            # Newton term is applied without a matrix
            finer_system = self.fine.system(u, *args, con=con, newton=False,
                                            orphans=self._known_orphans(con))
            system = self.fine.newton_system(finer_system, u, a, self.rho)
        finer_level = self.fine
        galerkin = needs is not None and needs.galerkin and self.extra_constraints is not None
        irregular = self._irregular_cells(system) if galerkin and self.coarse else None
        for level in self.coarse:
            u = inject_velocity(u, level, finer_level.space.n_v)
            if galerkin:
                walls = level.boundary_constraints.homogeneous()
                coarse_system, irregular = galerkin_coarse_system(
                    finer_system, level.system(u, *args, con=walls, newton=newton), *finer_level.prolongation,
                    level.injection, irregular)
            else:
                coarse_system = level.system(u, *args, con=level.homogeneous_constraints(t, extra),
                                             newton=newton)
            finer_system.coarser = coarse_system
            finer_system.prolongation = finer_level.prolongation
            finer_level, finer_system = level, coarse_system
        return system

    def _irregular_cells(self, system: SaddlePointSystem) -> np.ndarray:
        """Fine cells whose rows are not the plain discretisation: cells with a DOF constrained
        by the extra constraints (not the walls) or a pressure in the pressure block, and the
        cells two layers around them (where continued pressures take their rows), (k,) int64."""
        s = self.space
        mark = np.zeros(s.n_u, dtype=bool)
        for dofs in (system.fixed, system.rows):
            if dofs is not None:
                mark[dofs] = True
        mark[self.fine.boundary_constraints.dofs] = False
        cells = mark.reshape(s.dim, s.n_v).any(axis=0)[s.V.cell_dofs].any(axis=1)
        C = system.pressure_block
        if C is not None:
            cells[np.flatnonzero(np.diff(sp.csr_matrix(C).indptr)) // (s.dim + 1)] = True
        return dilate_cells(s.V.cell_dofs, s.n_v, np.flatnonzero(cells), 2)

    def _coarse_spacing_limit(self, u: np.ndarray) -> float:
        """Largest cell size with cell Reynolds number ``rho max|u| h / mu <= max_cell_reynolds``.
        The unstabilised Galerkin operator on a mesh that does not resolve the convection is a
        poor coarse-grid correction (at Re = 1000 the 4 x 4 cavity level makes the cycle
        diverge), so the coarsest level should still see the flow."""
        scale = float(np.max(np.abs(u))) if u.size else 0.0
        if not self.convection or scale == 0.0:
            return np.inf
        return self.max_cell_reynolds * self.mu / (self.rho * scale)

    def _resolving_levels(self, u: np.ndarray, hierarchy: bool) -> list[FlowLevel]:
        """The multigrid levels below the fine one for the velocity ``u``: those whose cells stay
        within the cell Reynolds number limit (:meth:`_coarse_spacing_limit`; the flow got faster
        or the viscosity smaller: fewer levels), and coarser ones as long as the coarsest level
        would otherwise be larger than :data:`COARSEST_UNKNOWNS` (a weak coarse correction
        costs cycles; a direct solve of a large system, hours or more memory than there is).
        All levels are built at the first call (:func:`coarse_levels`)."""
        if not hierarchy:
            return []
        if self._levels is None:
            self._levels = coarse_levels(self.fine, self.boundary, self._pressure_fixed, self.coarse_cells,
                                         extra_constraints=self.extra_constraints)
        limit = self._coarse_spacing_limit(u)
        n = sum(float(np.max(lv.mesh.spacing)) <= limit for lv in self._levels)
        while n < len(self._levels) and ((self._levels[n - 1].space if n else self.space).n_dofs
                                         > COARSEST_UNKNOWNS[self.mesh.dim]):
            n += 1
        levels = self._levels[:n]
        if self.coarse is None or len(levels) != len(self.coarse):
            log.info("multigrid levels: %s", [self.mesh.shape] + [lv.mesh.shape for lv in levels])
        return levels

    # -- solves -------------------------------------------------------------------------------
    def solve(self, x0: np.ndarray, m: float, a: float, rhs: np.ndarray, t: float,
              guess: np.ndarray | None = None, rtol: float | None = None,
              newton: NewtonSettings | None = None, linear_rtol: float | None = None, extra=None):
        """Solve ``F(x) = 0`` by Newton from ``x0`` with the constraints at time ``t``.

        ``guess`` (n_dofs,): start Newton there instead (e.g. a prediction of the solution);
        the stopping rule stays relative to the residual at ``x0``, so the accuracy is the same.
        ``rtol``: Newton's residual reduction for this solve (default ``self.newton.rtol``);
        ``newton``: settings for this solve instead of ``self.newton``; ``linear_rtol``: the
        relative residual asked of its linear steps where that is looser than the settings' own
        (a loose solve's steps need no more than its own reduction); ``extra``: this solve's
        further constraints instead of ``extra_constraints`` (:meth:`constraints`).
        Returns x (n_dofs,) and the NewtonReport.
        """
        con = self.constraints(t, extra)
        x0 = x0.copy()
        con.apply_to_vector(x0)
        self.make_consistent(x0)
        reference = None

        def linear_step(x, F, fresh=True, rtol=None):
            solve = self._linearise(x, m, a, con, t, fresh, extra)
            du, dp, report = self._linear_solve(solve, -F[:self.space.n_u], -F[self.space.n_u:], rtol)
            return np.concatenate([du, dp]), report

        orphans = self.orphans(con)
        if guess is not None:
            reference = self.norm(self.residual(x0, m, a, rhs, con, orphans))
            x0 = guess.copy()
            con.apply_to_vector(x0)
            self.make_consistent(x0)
        settings = newton or self.newton
        settings = settings if rtol is None else dataclasses.replace(settings, rtol=rtol)
        if None not in (linear_rtol, settings.linear_rtol) and linear_rtol > settings.linear_rtol:
            settings = dataclasses.replace(settings, linear_rtol=linear_rtol)
        x, report = solve_newton(lambda x: self.residual(x, m, a, rhs, con, orphans), linear_step, x0,
                                 settings, reference, norm=self.norm)
        self._linearise(x, m, a, con, t, False, extra)  # keeps one for lifting_response
        return x, report

    def _linearise(self, x, m, a, con, t, fresh: bool, extra=None):
        """The factorised Newton linearisation at ``x`` (a new one when ``fresh`` or when the
        stored one belongs to other time-step weights or another constrained set).

        A stored one whose operator is applied without a matrix (:class:`~fbmflow.flow.levels.
        NewtonBlock`: multigrid inside FGMRES, on a Picard or Newton hierarchy) is moved to ``x`` at no
        assembly: the Newton step then solves with the Jacobian at ``x``, preconditioned by the
        hierarchy of the earlier point, and contracts like Newton rather than like the chord
        method."""
        last = self._linearisation
        if fresh or last is None or self._any(
                last[:2] != (m, a) or not np.array_equal(last[2].dofs, con.dofs)
                or (con.rows is not None and not con.rows.same_matrix(last[2].rows))):
            self._linearisation = last = None  # freed before the next is built (peak memory)
            system = self.linear_system(x, m, a, con, t, extra)
            self._linearisation = (m, a, con, self.linear_solver.factor(system), system)
        else:
            self._linearisation = (m, a, con) + last[3:]
            if isinstance(last[4].A, NewtonBlock):
                last[4].A.relinearise(x[:self.space.n_u], self.max_abs)
        return self._linearisation[3]

    def _linear_solve(self, solve: Factorization, f, g, rtol=None):
        """``solve.solve(f, g)`` to ``rtol`` (default ``self.newton.linear_rtol``) where the solver
        takes a target per solve (multigrid; the direct solver's PARDISO refinement), else to the
        solver's own; counted in :attr:`linear_work`. ConvergenceError when an iterative solver
        misses its target."""
        rtol = self.newton.linear_rtol if rtol is None else rtol
        du, dp, report = solve.solve(f, g, rtol)
        self.linear_work.add(report)
        if self.on_linear_solve is not None:
            self.on_linear_solve(report, self._linearisation[4])
        if not report.converged:
            reduction = report.residuals[-1] / report.residuals[0] if report.residuals else float("nan")
            raise ConvergenceError(
                f"the {report.solver} linear solver did not converge: residual reduced to {reduction:.2e} "
                f"in {report.iterations} iterations; use solver.linear = \"direct\", a smaller time step, "
                "or more smoothing (solver.multigrid.pre_smooth and post_smooth, solver.multigrid.cycle = "
                "\"W\")")
        return du, dp, report

    def forget_linearisation(self) -> None:
        """Drop the stored factorisation: the next solve starts with a fresh Jacobian, as after
        a restart (checkpoints call this so that a resumed run repeats the same iterations).
        A linear solver that keeps more between factorisations (PARDISO's analysis) forgets it
        too."""
        self._linearisation = None
        self.linear_solver.forget()

    def lifting_response(self, x: np.ndarray, liftings, row_liftings=None,
                         rtol: float | None = None) -> np.ndarray:
        """How the solution of the last :meth:`solve` responds to changed constraint values.

        ``liftings (dim * n_v, k)`` (dense or sparse) are velocity fields, one per column, that
        are non-zero only on constrained DOFs (e.g. a unit rigid-body motion on a particle's nodes,
        :func:`~fbmflow.coupling.indicator.rigid_liftings`). Each response ``dx = w + z`` solves
        the Newton linearisation ``J dx = 0`` with ``dx = w`` on the constrained DOFs: ``z``
        vanishes there and solves ``J z = -J w``. ``J w`` for all ``k`` liftings at once is the
        product with the Jacobian assembled at ``x`` (one assembly, constrained rows zeroed and
        orphaned continuity modes dropped as in :meth:`residual`); the factorisation of the last
        Newton step is reused (a Jacobian one iteration old, good enough for the coupling
        iteration it serves). ``row_liftings (dim * n_v, k)`` (dense or sparse): how the values
        ``g`` of the row constraints change with each lifting, on their DOFs; the response then
        keeps ``C dx = dg`` there. ``rtol``: the linear solves' residual reduction where the
        solver takes one (default the Newton steps', ``newton.linear_rtol``). Returns (k, n_dofs)
        float64.
        """
        m, a, con, solve, system = self._linearisation
        W = sp.csc_matrix(liftings)  # (n_u, k)
        Ju = system.A @ W  # the free rows of the Jacobian's product (the constrained ones follow)
        Ju = Ju.toarray() if sp.issparse(Ju) else np.asarray(Ju)
        Ju[con.dofs] = 0.0
        Wd = W.toarray()
        if con.rows is not None:
            dg = sp.csr_matrix(row_liftings)[con.rows.dofs].toarray() if row_liftings is not None else 0.0
            scale = self.fine.row_scale(con.rows.dofs, m, a, self.rho, self.mu)
            Ju[con.rows.dofs] = scale[:, None] * (con.rows.matrix @ Wd - dg)
        Jp = self._continuity(W, con, self.orphans(con))
        Ju, Jp = self._complete(Ju, Jp)
        if solve.multiple_rhs:
            du, dp, _ = self._linear_solve(solve, -Ju, -Jp, rtol)
        else:
            cols = [self._linear_solve(solve, -Ju[:, k], -Jp[:, k], rtol)[:2] for k in range(W.shape[1])]
            du, dp = np.column_stack([c[0] for c in cols]), np.column_stack([c[1] for c in cols])
        return np.vstack([Wd + du, dp]).T

    def solve_steady(self, x0: np.ndarray | None = None, t: float = 0.0):
        """Steady solution by Newton from ``x0``; by default from the Stokes solution (one more
        linear solve, to :data:`STOKES_START_RTOL`). Returns x, NewtonReport (of the
        Navier–Stokes iteration).

        From rest, a flow driven by inflow has a first Newton step (the Stokes flow) whose
        convection residual is thousands of times the starting residual, and the line search on
        ``|F|`` can fail (measured: dfg-3d-1z at level 1); from the Stokes flow it does not.

        With an iterative linear solver (multigrid) the Newton steps take Eisenstat–Walker
        forcing terms (:class:`~fbmflow.solvers.newton.NewtonSettings`). In 3D, inside FGMRES, a
        reused hierarchy (``newton.reuse_jacobian``, while Newton contracts the residual at
        least ``reuse_contraction`` times per step) preconditions the Jacobian at each iterate
        (:meth:`~fbmflow.flow.levels.NewtonBlock.relinearise`): Newton keeps converging like
        Newton, and the set-up (Vanka factors of 3D patches, the coarsest level's factorisation)
        is not repeated every step; measured on dfg-3d-1z level 3, the same cycles per solve
        as with fresh hierarchies. In 2D the set-up is cheap next to the extra cycles that an
        older hierarchy costs (cavity-2d at Re 1000: 57 against 48 cycles, 5.9 against 5.2 s),
        and stand-alone cycles would converge only linearly: every step takes a fresh Jacobian
        there. A direct solver keeps its factorisation (``newton.reuse_jacobian``), which costs
        more than its solves. The Stokes start, a linear problem, keeps its linearisation
        throughout.
        """
        newton = self.newton
        needs = self.linear_solver.hierarchy(False)
        if needs is not None:
            moving = self.mesh.dim == 3 and needs.follows_iterates
            newton = dataclasses.replace(newton, reuse_jacobian=newton.reuse_jacobian and moving,
                                         adaptive_linear_rtol=True)
        if x0 is None:
            x0 = self.zero_state(t)
            if self.convection:
                self.convection = False
                try:  # only a start: to a loose tolerance
                    x0, _ = self.solve(x0, 0.0, 1.0, self.load(t), t,
                                       newton=dataclasses.replace(newton, reuse_jacobian=True),
                                       rtol=max(STOKES_START_RTOL, newton.rtol))
                finally:
                    self.convection = True
                    self.forget_linearisation()
        x, report = self.solve(x0, 0.0, 1.0, self.load(t), t, newton=newton)
        log.info("steady solve: %d Newton iterations, |F| %.2e -> %.2e", report.iterations,
                 report.residuals[0], report.residuals[-1])
        return x, report

