"""The Navier–Stokes operators on one mesh level, and the hierarchy of coarser levels that the
multigrid solver works on (re-discretisation on nested meshes)."""
from __future__ import annotations

import copy
import logging

import numpy as np
import scipy.sparse as sp

from ..fem import (
    FlowSpace,
    apply_convection,
    apply_reaction,
    assemble_convection,
    assemble_divergence,
    assemble_laplace,
    assemble_mass,
    assemble_mass_laplace,
    pressure_mean_weights,
    reaction_coefficients,
    velocity_coefficients,
)
from ..fem.constraints import DirichletConstraints
from ..fem.continuity_block import ContinuityBlock
from ..fem.velocity_block import VelocityBlock
from ..mesh import StructuredMesh
from ..solvers import SaddlePointSystem
from ..solvers.sparse import matvec
from ..solvers.system import orphan_pressure_modes
from ..solvers.transfer import injection_q2, prolongation_p1disc, prolongation_q2
from .boundary import build_constraints

log = logging.getLogger(__name__)


#: the drift ``u - u0`` of a :class:`NewtonBlock`, relative to its largest value, below which a
#: cell's convection of it is left out (the Jacobian is then approximate there: the Newton
#: steps' residuals, evaluated exactly, keep the solution the same)
DRIFT_CUTOFF = 1e-3


class NewtonBlock:
    """The velocity block of a Newton system at ``u``, applied from an assembled block ``A`` of
    an earlier point ``u0`` plus, without a matrix (:func:`~fbmflow.fem.assembly.apply_convection`,
    :func:`~fbmflow.fem.assembly.apply_reaction`) and left out on the ``constrained`` rows, what the
    Newton linearisation adds or changes at ``u``, ``s = a rho``:

    * ``A`` the Picard block ``m rho M + a (mu L + rho N(u0))`` (``newton_base`` False):
      ``A + s (N(u - u0) + R(u))``; it stores ``dim`` times fewer entries than the assembled
      Newton block;
    * ``A`` the Newton block ``m rho M + a (mu L + rho (N(u0) + R(u0)))`` (``newton_base``
      True): ``A + s (N(u - u0) + R(u - u0))``, nothing at ``u0`` itself.

    With constraint rows as assembled in ``A``. An iterative solver needs only its products;
    :meth:`relinearise` moves it to another ``u`` without an assembly (``A``, and the hierarchy
    built from it, stay at ``u0``).

    Parameters
    ----------
    base : (n_u, n_u) CSR, ``A``
    space : FlowSpace
    u0 : (n_u,) float64, the velocity ``base`` is linearised at (the block starts there)
    scale : float, ``s``
    constrained : (k,) int64, rows without the Newton term
    newton_base : bool, whether ``base`` holds the Newton term ``R(u0)``
    """

    def __init__(self, base: sp.csr_matrix, space: FlowSpace, u0: np.ndarray, scale: float,
                 constrained: np.ndarray, newton_base: bool = False):
        self.base, self.space, self.scale = base, space, scale
        self.u0 = u0.copy()
        self.constrained = constrained
        self.newton_base = newton_base
        self.shape = base.shape
        self.dtype = base.dtype
        #: how many times the block has moved (a copy elsewhere follows it)
        self.moves = -1
        self.relinearise(u0)

    def relinearise(self, u: np.ndarray, max_abs=None) -> None:
        """The Newton block at ``u`` (n_u,) from now on. The drift ``u - u0``'s convection is
        applied on the cells where the drift reaches :data:`DRIFT_CUTOFF` of its largest value
        (none where ``u`` is ``u0``): a moving particle changes the flow about itself, and the
        cells far from it, where the drift is round-off next to the near field, are left out of
        every product. ``max_abs``: the largest ``|v_i|`` of a vector over the whole mesh where
        this block is one process's slab (:meth:`~fbmflow.flow.navier_stokes.NavierStokesProblem.max_abs`;
        a slab's own largest drift, far from a particle, let its every cell in: measured, the
        drift's convection took 2.0 s of a ten Cate level-1 run on the slab without the sphere
        against 1.1 s on the whole mesh).

        The terms' coefficients (:attr:`react`, :attr:`drift`) are computed at the first product
        with a vector on the CPU after the move, not here: a solver that applies the block
        elsewhere (the GPU's, from ``reacting`` and ``drifting``) leaves the CPU's unmade; a
        product with a sparse matrix makes them on the cells its columns touch only."""
        s = self.space
        drift = u - self.u0
        size = np.abs(drift).reshape(s.dim, s.n_v).max(axis=0)
        largest = float(size.max()) if size.size else 0.0
        if max_abs is not None:
            largest = max_abs(drift)
        # the previous coefficients go before the new ones are made (not both held at once)
        self._react = self._drift = self._drift_groups = self.drift_cells = None
        #: the velocity whose Newton term ``R`` the block adds (``u``, or the drift where
        #: ``newton_base``), (n_u,), or None where it adds none
        self.reacting = (drift if largest > 0.0 else None) if self.newton_base else u.copy()
        #: the drift whose convection the block adds on ``drift_cells``, or None
        self.drifting = drift if largest > 0.0 else None
        if largest > 0.0:
            self.drift_cells = (size > DRIFT_CUTOFF * largest)[s.V.cell_dofs].any(axis=1)
        self.moves += 1

    @property
    def react(self) -> np.ndarray | None:
        """:func:`~fbmflow.fem.assembly.reaction_coefficients` of ``reacting``, made at the
        first call after a move."""
        if self._react is None and self.reacting is not None:
            self._react = reaction_coefficients(self.space, self.reacting)
        return self._react

    @property
    def drift(self) -> np.ndarray | None:
        """:func:`~fbmflow.fem.assembly.velocity_coefficients` of ``drifting``, made at the
        first call after a move."""
        if self._drift is None and self.drifting is not None:
            self._drift = velocity_coefficients(self.space, self.drifting)
        return self._drift

    @property
    def drift_groups(self) -> list[np.ndarray] | None:
        """``drift_cells`` in the space's parallel groups, made at the first call after a move."""
        if self._drift_groups is None and self.drift_cells is not None:
            self._drift_groups = self.space.cell_groups(self.drift_cells)
        return self._drift_groups

    def _newton_terms(self, v: np.ndarray, cells: np.ndarray | None = None,
                      coefficients: tuple | None = None) -> np.ndarray:
        """What the Newton block adds to ``A v``, with the constrained rows zero, (n_u,):
        on ``cells`` only where given, from ``coefficients`` (``(react, drift)``, which hold
        those cells' at least) where given, else from :attr:`react` and :attr:`drift`."""
        react, drift = coefficients or (self.react, self.drift)
        out = np.zeros(v.size)
        if react is not None:
            apply_reaction(self.space, react, v, self.scale, out, cells=cells)
        if drift is not None:
            apply_convection(self.space, v, self.scale, out, conv=drift, groups=self.drift_groups,
                             cells=None if cells is None else cells[self.drift_cells[cells]])
        out[self.constrained] = 0.0
        return out

    def __matmul__(self, v):
        """Product with a vector (n_u,), or with a dense or sparse matrix (n_u, k) (dense result;
        sparse columns only visit the cells that touch their non-zeros)."""
        if sp.issparse(v):
            return self._sparse(sp.csc_matrix(v))
        v = np.asarray(v)
        if v.ndim == 2:
            return np.column_stack([self @ v[:, k] for k in range(v.shape[1])])
        return matvec(self.base, v) + self._newton_terms(v)

    def _sparse(self, W: sp.csc_matrix) -> np.ndarray:
        """``self @ W`` column by column on the cells each column touches. The coefficients
        where the CPU has made them, else on those cells only (the rigid responses' right-hand
        sides, where the solves apply the block on a GPU: ten Cate level 2, 0.5 s of whole-mesh
        coefficients per step on 2 cores otherwise)."""
        out = (self.base @ W).toarray()
        s = self.space

        def touched(rows):  # the cells that hold the nodes of the unknowns ``rows``
            return np.unique(s.node_cells[np.unique(rows % s.n_v)].indices)

        near = touched(W.indices)
        react = self._react
        if react is None and self.reacting is not None:
            react = reaction_coefficients(s, self.reacting, cells=near)
        drift = self._drift
        if drift is None and self.drifting is not None:
            drift = velocity_coefficients(s, self.drifting, cells=near[self.drift_cells[near]])
        for k in range(W.shape[1]):
            rows = W.indices[W.indptr[k]:W.indptr[k + 1]]
            if rows.size == 0:
                continue
            out[:, k] += self._newton_terms(W[:, k].toarray().ravel(), touched(rows), (react, drift))
        return out


class FlowLevel:
    """Mesh-dependent operators of one level: space, ``B^T``, the diagonals of the mass and
    Laplace matrices.

    Parameters
    ----------
    mesh : StructuredMesh
    boundary : dict of boundary conditions (only which DOFs are constrained matters here)
    pressure_fixed : bool, whether ``int p = 0`` closes the system
    """

    def __init__(self, mesh: StructuredMesh, boundary: dict, pressure_fixed: bool,
                 extra_constraints=None):
        self.mesh = mesh
        self.space = space = FlowSpace(mesh)
        # the mass and Laplace matrices are assembled into each linearisation's block and applied
        # cell by cell elsewhere; of the stored pair only their diagonals stay (row_scale)
        diag = np.flatnonzero(space.indices == np.repeat(np.arange(space.n_v), np.diff(space.indptr)))
        self._diagonals = (assemble_mass(space)[diag], assemble_laplace(space)[diag])
        self.BT = assemble_divergence(space)
        self.mean_weights = pressure_mean_weights(space) if pressure_fixed else None
        self.boundary_constraints = build_constraints(space.V, boundary, 0.0)
        self.extra_constraints = extra_constraints
        self._jacobian_data: np.ndarray | None = None
        self._orphans = None  # (constraints, their orphaned pressure modes) last found
        self.prolongation: tuple | None = None  # from the next coarser level
        self.injection: np.ndarray | None = None  # fine DOF of every DOF of this level

    def homogeneous_constraints(self, t: float = 0.0, extra=None) -> DirichletConstraints:
        """Which DOFs are constrained on this level (values zero): the box faces plus the extra
        constraints (e.g. fictitious boundaries) at time ``t`` (``extra``: a solve's own instead
        of the level's)."""
        con = self.boundary_constraints
        extra = extra or self.extra_constraints
        if extra is not None:
            con = con.merged(extra(self.space.V, t))
        return con.homogeneous()

    def orphans(self, con: DirichletConstraints) -> sp.csr_matrix | None:
        """Pressure modes that no free velocity sees under the constraints ``con``: the projector
        (n_p, n_p) CSR of :func:`~fbmflow.solvers.system.orphan_pressure_modes` on this level's
        divergence with ``con``'s DOFs zero, the continued cells' modes left out; or None.

        They depend on which DOFs are constrained and which cells' pressures are continued, not
        on the values: those of the last ``con`` are kept for the next on the same DOFs (a
        coupling iteration's other particle velocities, a Newton solve's residuals and linear
        systems, every level's next linearisation while the particles stay on the same nodes).
        """
        if self._orphans is not None:
            last, P = self._orphans
            if last is con or (np.array_equal(last.dofs, con.dofs)
                               and _same_dofs(last.extension, con.extension)):
                self._orphans = (con, P)
                return P
        P = orphan_pressure_modes(self.BT, self.space.dim + 1, closed=self.mean_weights is not None,
                                  zero=con.dofs)
        if con.extension is not None:
            P = con.extension.exclude(P)
        self._orphans = (con, P)
        return P

    def close_pockets(self, con: DirichletConstraints, partition=None) -> DirichletConstraints:
        """Hold still the fluid nodes cut off from the main fluid by constrained nodes
        (``partition``: the :class:`~fbmflow.parallel.blocks.BlockPartition` whose slab this level's
        mesh is; the components are then the whole mesh's, the largest the same on every process).

        A particle within a node layer of a wall or of another particle can enclose a few free
        nodes; the prescribed velocities around them generally carry a net flux into the pocket,
        and no divergence-free field exists (Newton stagnates). The pocket's nodes (every
        connected component of nodes with a free component, except the largest) get zero
        velocity; the pressure modes of the cells they leave orphaned drop out."""
        s = self.space
        free = np.bincount(con.dofs % s.n_v, minlength=s.n_v) < s.dim
        labels = s.free_node_components(free)
        if partition is None:
            roots, counts = np.unique(labels[free], return_counts=True)
        else:
            labels, roots, counts = partition.join_components(labels)
        if roots.size <= 1:
            return con
        pocket = np.flatnonzero(free & (labels != roots[np.argmax(counts)]))
        log.debug("closing %d fluid nodes cut off from the main fluid", pocket.size)
        dofs = np.concatenate([k * s.n_v + pocket for k in range(s.dim)])
        return con.merged(DirichletConstraints(np.sort(dofs), np.zeros(dofs.size)))

    def system(self, u: np.ndarray, m: float, a: float, rho: float, mu: float, convection: bool,
               con: DirichletConstraints | None = None, newton: bool = True,
               own_buffer: bool = False, orphans: sp.csr_matrix | None = None) -> SaddlePointSystem:
        """Newton linearisation ``m rho M + a (mu L + rho (N(u) + R(u)))`` at velocity ``u``.

        Without the Newton term (``newton`` False, no convection, or ``a`` zero) the velocity
        block is a :class:`~fbmflow.fem.velocity_block.VelocityBlock`: the scalar operator stored
        once, the constrained rows beside it. The Newton block is assembled, its data in a buffer
        of this level that the next call overwrites: use the returned system before linearising
        again (or pass ``own_buffer`` to get a fresh array that nothing else writes to).
        ``orphans``: the orphaned pressure modes under ``con`` where the caller has them (an empty
        matrix: none), else this level's (:meth:`orphans`, kept for constraints on the same DOFs).
        """
        s = self.space
        con = con or self.homogeneous_constraints()
        if orphans is None:
            orphans = self.orphans(con)
            if orphans is None:  # none: the system looks for none either
                orphans = sp.csr_matrix((s.n_p, s.n_p))
        newton = convection and a != 0.0 and newton
        rows = con.rows.dofs if con.rows is not None else None
        if not newton:  # block diagonal: the same scalar operator for every component, stored once
            if convection and a != 0.0:
                S = np.zeros(s.nnz)
                assemble_convection(s, u, a * rho, scalar_out=S, mass_laplace=(m * rho, a * mu))
            else:
                S = assemble_mass_laplace(s, m * rho, a * mu)
            R = None if rows is None else sp.diags(self.row_scale(rows, m, a, rho, mu)) @ con.rows.matrix
            A = VelocityBlock(s, S, con.fixed, rows, R)
        else:
            size = s.dim * s.nnz * s.dim
            if own_buffer:
                J = np.empty(size)
            else:
                if self._jacobian_data is None or self._jacobian_data.size != size:
                    self._jacobian_data = np.empty(size)
                J = self._jacobian_data
            J.fill(0.0)
            assemble_convection(s, u, a * rho, newton_out=J, mass_laplace=(m * rho, a * mu))
            A = s.coupled_matrix(J)
            con.zero_rows(A)
            if rows is not None:
                A = con.rows.write_rows(A, self.row_scale(rows, m, a, rho, mu))
                if not own_buffer and not np.shares_memory(A.data, J):
                    # a new matrix: the buffer would only hold memory (ten Cate level 1: 116 MB, the
                    # step's peak 1 326 -> 1 210 MB)
                    self._jacobian_data = None
        # the level's divergence and the rows that differ, and B from the level's divergence: no
        # copy of either (B's rows of the constrained DOFs are zero)
        D = ContinuityBlock(self.BT)
        if not con.sharp:
            return SaddlePointSystem(A, con.constrain_divergence(D), self.mean_weights, con.dofs, s,
                                     fixed_always=self.boundary_constraints.dofs, gradient_BT=self.BT,
                                     transient=m != 0.0, orphans=orphans)
        return SaddlePointSystem(A, con.constrain_divergence(con.continuity_matrix(D), fixed_only=True),
                                 self.mean_weights, con.fixed, s, fixed_always=self.boundary_constraints.dofs,
                                 rows=rows, gradient_BT=self.BT,
                                 extension=con.extension, transient=m != 0.0, orphans=orphans)

    def newton_system(self, assembled: SaddlePointSystem, u: np.ndarray, a: float, rho: float,
                      newton_base: bool = False) -> SaddlePointSystem:
        """The Newton system of ``assembled`` (this level's, linearised at ``u`` with weight
        ``a``; its velocity block the Picard one, or the Newton one where ``newton_base``): the
        same blocks and constraints, the velocity block a :class:`NewtonBlock` that
        :meth:`NewtonBlock.relinearise` moves to other velocities (no hierarchy of its own;
        ``assembled`` is its preconditioner)."""
        constrained = np.concatenate([d for d in (assembled.fixed, assembled.rows) if d is not None] or
                                     [np.zeros(0, dtype=np.int64)])
        system = copy.copy(assembled)  # shares the blocks and the derived ones already computed
        system.A = NewtonBlock(assembled.A, self.space, u, a * rho, constrained, newton_base)
        system.preconditioner, system.coarser, system.prolongation = assembled, None, None
        return system

    def row_scale(self, dofs: np.ndarray, m: float, a: float, rho: float, mu: float) -> np.ndarray:
        """Scale of the momentum equations of the velocity ``dofs`` (component-blocked): the
        diagonal of ``m rho M + a mu L`` there, (n,) float64. Row constraints replacing those
        equations are multiplied by it, so that their residuals weigh like the others."""
        node = dofs % self.space.n_v
        return m * rho * self._diagonals[0][node] + a * mu * self._diagonals[1][node]


def coarse_levels(fine: FlowLevel, boundary: dict, pressure_fixed: bool, min_cells: int,
                  extra_constraints=None) -> list[FlowLevel]:
    """Coarser levels below ``fine`` (finest first); sets the transfer operators.

    Coarsening goes on while every axis has an even cell count and the coarser mesh keeps at
    least ``min_cells`` cells. (Which of them a linearisation uses, the flow problem decides by
    their cell Reynolds number: ``_resolving_levels``.)
    """
    levels = [fine]
    mesh = fine.mesh
    while all(n % 2 == 0 for n in mesh.shape) and mesh.n_cells // 2**mesh.dim >= min_cells:
        try:
            mesh = mesh.coarsen()
        except ValueError:
            break
        coarse = FlowLevel(mesh, boundary, pressure_fixed, extra_constraints)
        finer = levels[-1]
        finer.prolongation = (prolongation_q2(coarse.space.V, finer.space.V),
                              prolongation_p1disc(coarse.space.Q, finer.space.Q))
        coarse.injection = injection_q2(coarse.space.V, finer.space.V)
        levels.append(coarse)
    return levels[1:]


def inject_velocity(u: np.ndarray, level: FlowLevel, n_v_fine: int) -> np.ndarray:
    """Velocity (dim * n_v_fine,) restricted by injection to ``level``'s nodes."""
    d = level.space.dim
    return u.reshape(d, n_v_fine)[:, level.injection].ravel()


def _same_dofs(a, b) -> bool:
    """Whether two pressure extensions (or None) continue the same pressure DOFs."""
    if a is None or b is None:
        return a is b
    return np.array_equal(a.dofs, b.dofs)
