"""The saddle-point system of a Newton/Oseen linearisation and what every solver needs of it.

A :class:`SaddlePointSystem` holds the blocks of

    [ A   B ] [du]   [f]
    [ B^T 0 ] [dp] = [g]      (+ the border  w . dp = 0  when the pressure is fixed by its mean)

and a linear solver is any object with ``solve(system, f, g) -> (du, dp, LinearReport)`` (and
``factor(system)``, returning such a solve for one system); one that keeps state between
factorisations offers ``forget()`` to drop it. Solvers are registered by name in
:data:`fbmflow.solvers.LINEAR_SOLVERS`: the direct one (:mod:`fbmflow.solvers.direct`) and
multigrid (:mod:`fbmflow.solvers.multigrid`). This module also finds the pressure modes that no
velocity sees (orphans) and makes continuity data solvable in closed domains.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import scipy.sparse as sp
import scipy.sparse.csgraph as csgraph

from ..fem.continuity_block import ContinuityBlock, splice_rows, zero_columns
from ..fem.sorted_sets import union_sorted
from ..fem.velocity_block import VelocityBlock
from ..kept import KeptByIdentity
from . import _kernels
from .sparse import cell_transposed_matvec, matvec

log = logging.getLogger(__name__)

MAX_CLUSTER_MODES = 1000  # pressure modes up to which a cluster of cut cells gets a dense SVD


@dataclass
class SaddlePointSystem:
    """Blocks of one linearised system.

    Attributes
    ----------
    A : (n_u, n_u) CSR or :class:`~fbmflow.fem.velocity_block.VelocityBlock`, constrained rows already
        unit rows (or the row constraints' rows)
    BT : (n_p, n_u) CSR or :class:`~fbmflow.fem.continuity_block.ContinuityBlock` (the level's
        divergence and the rows that differ), constrained columns zeroed; ``B = BT.T``
    mean_weights : (n_p,) float64 or None, border row fixing ``int p = 0``
    fixed : (n_c,) int64 or None, the constrained velocity DOFs (unit rows of ``A``); solvers
        may eliminate them (their solution is the right-hand side there)
    fixed_always : (n_a,) int64 or None, the constrained DOFs that stay constrained in every
        system of the problem (the domain's walls; the particles' DOFs come and go). A
        factorisation that reuses its analysis (:class:`~fbmflow.solvers.direct.PardisoAnalysis`) eliminates
        only the
        ones of them in ``fixed`` and keeps the other constrained DOFs as unit rows, so that the
        matrix keeps its sparsity pattern while particles move.
    space : FlowSpace or None, the discretisation (cell structure for cell-wise smoothers)
    coarser : SaddlePointSystem or None, the same operator re-discretised on the next coarser mesh
    prolongation : (P_v, P_p) or None, scalar Q2 (n_v x n_v_coarse) and P1disc (n_p x n_p_coarse)
        prolongations from ``coarser`` to this level
    orphans : (n_p, n_p) CSR or None, the pressure-pressure block ``C``: the orthogonal projector
        onto the pressure modes that no free velocity DOF sees any more (cells inside or almost
        inside a fictitious boundary, alone or in clusters). Those modes would make the system
        singular; ``C`` sets them to ``g`` (zero for Newton updates) and leaves every other
        unknown unchanged. Computed from ``B^T`` (the columns of ``rows`` zeroed) when ``space``
        is given and ``orphans`` is None (:func:`orphan_pressure_modes`); a caller that has
        computed them passes them, an empty matrix where there are none.
    rows : (n_r,) int64 or None, velocity DOFs whose rows of ``A`` are linear constraints
        (:class:`~fbmflow.fem.constraints.RowConstraints`, the sharp fictitious boundary): they
        are unknowns of the continuity equations (their columns of ``B^T`` stay), but their rows
        carry no pressure gradient, and no pressure mode counts as seen through them.
    gradient_BT : (n_p, n_u) CSR or None, the divergence whose transpose is ``B`` (the level's
        own matrix, shared: a rediscretised level's systems, whose ``B`` would otherwise be a
        copy, and the sharp boundary's, whose ``BT`` holds other continuity rows), in the
        divergence's cell-local pattern, its constrained columns *not* zeroed: ``B``'s rows of
        ``fixed`` and ``rows`` are zero. None: ``B`` is ``BT`` transposed.
    extension : the sharp boundary's :class:`~fbmflow.fem.constraints.PressureExtension` or None
    preconditioner : SaddlePointSystem or None, an approximation of this system with its own
        ``coarser`` chain (the Picard linearisation of a Newton system) that an iterative solver
        builds its preconditioner from, applying this system's matrix in the Krylov iteration;
        None: the system itself.
    transient : bool, a time step's system (the mass term is part of ``A``)
    partition : :class:`~fbmflow.parallel.blocks.BlockPartition` or None, the slab of the mesh
        this process holds where the system is one process's part of the whole mesh's (its rows
        of the owned unknowns are the whole system's; the solver is then
        :class:`~fbmflow.solvers.distributed.DistributedMultigrid`); None: the whole mesh's
    """

    A: sp.csr_matrix
    BT: sp.csr_matrix
    mean_weights: np.ndarray | None = None
    fixed: np.ndarray | None = None
    space: object = None
    fixed_always: np.ndarray | None = None
    coarser: "SaddlePointSystem | None" = None
    prolongation: tuple | None = None
    orphans: sp.csr_matrix | None = None
    rows: np.ndarray | None = None
    gradient_BT: sp.csr_matrix | None = None
    extension: object = None
    preconditioner: "SaddlePointSystem | None" = None
    transient: bool = False
    partition: object = None
    _gradient: sp.csr_matrix | None = field(default=None, init=False, repr=False)

    def __post_init__(self):
        if self.orphans is None and self.space is not None:
            seen = as_csr(self.BT if self.gradient_BT is None else self.gradient_BT)
            self.orphans = orphan_pressure_modes(seen, self.space.dim + 1, zero=self.gradient_zero,
                                                 closed=self.mean_weights is not None)
            if self.extension is not None:  # continued cells' pressures are constrained instead
                self.orphans = self.extension.exclude(self.orphans)
        elif self.orphans is not None and self.orphans.nnz == 0:  # the caller found none
            self.orphans = None
        if self.rows is not None and self.orphans is not None:
            # the orphaned modes' continuity equations drop out (as in the residual): they see the
            # row-constrained columns only, and would otherwise tie those to the modes' g
            self.BT = without_orphaned_modes(self.BT, self.orphans)

    @property
    def gradient(self) -> sp.csr_matrix:
        """The pressure-gradient block ``B`` (n_u, n_p) CSR: ``B^T`` (or ``gradient_BT``)
        transposed, the rows of ``rows`` (and of ``fixed``, from ``gradient_BT``) zeroed. Kept
        once built, except where ``gradient_BT`` is given: products then use it transposed
        (:meth:`apply_gradient`) and ``B`` is built anew on each access, for the set-up of
        smoothers and coarse rows (at ten Cate level 1 it would hold 37 MB, 132 bytes per
        unknown)."""
        if self._gradient is not None:
            return self._gradient
        source = self.BT if self.gradient_BT is None else self.gradient_BT
        B = zero_columns(as_csr(source), self.gradient_zero).T.tocsr()
        if self.gradient_BT is None:
            self._gradient = B
        return B

    def gradient_rows(self, rows: np.ndarray) -> sp.csr_matrix:
        """``B[rows]`` (k, n_p) CSR, columns ascending, for the velocity DOFs ``rows`` (k,) int
        (distinct): read from ``gradient_BT`` cell by cell where it is in the divergence's
        cell-local pattern (:func:`cell_local`), without ``B`` built (at ten Cate level 2 a
        transpose of 23 M entries, some 0.07 s, at every smoother's set-up), the pattern as
        :attr:`gradient`'s (zeroed rows keep their entries, zero); else :attr:`gradient`'s rows."""
        rows = np.asarray(rows, dtype=np.int64)
        if self.gradient_BT is None or self.space is None or not cell_local(self.space, self.gradient_BT):
            return self.gradient[rows]
        space = self.space
        ptr, cells, ranks = space.node_cell_ranks
        nodes = rows % space.n_v
        indptr = np.zeros(rows.size + 1, dtype=np.int64)
        np.cumsum((ptr[nodes + 1] - ptr[nodes]) * (space.dim + 1), out=indptr[1:])
        zero = np.zeros(self.n_u, dtype=bool)
        if self.gradient_zero is not None:
            zero[self.gradient_zero] = True
        indices, data = np.empty(indptr[-1], dtype=np.int32), np.empty(indptr[-1])
        _kernels.gradient_rows(rows, indptr, space.n_v, ptr, cells, ranks,
                               cell_values(space, self.gradient_BT), zero, indices, data)
        return sp.csr_matrix((data, indices, indptr), shape=(rows.size, self.n_p))

    @cached_property
    def gradient_zero(self) -> np.ndarray | None:
        """The velocity DOFs whose rows of ``B`` are zero, (k,) int64, or None: those of
        ``rows``, and those of ``fixed`` where ``gradient_BT`` (whose columns are not zeroed)
        stands for ``B``."""
        if self.gradient_BT is None or self.fixed is None:
            return self.rows
        return self.fixed if self.rows is None else union_sorted(self.fixed, self.rows)

    def apply_gradient(self, p: np.ndarray) -> np.ndarray:
        """``B p`` for a pressure (n_p,) -> (n_u,): from ``gradient_BT`` cell by cell where it is
        given (:func:`~fbmflow.solvers.sparse.cell_transposed_matvec`), else the product with
        :attr:`gradient`."""
        if self.gradient_BT is None or self.space is None:
            return matvec(self.gradient, p)
        out = cell_transposed_matvec(self.gradient_BT, p, self.space.colour_groups, self.space.dim + 1)
        if self.gradient_zero is not None:
            out[self.gradient_zero] = 0.0
        return out

    @property
    def n_u(self) -> int:
        return self.A.shape[0]

    @property
    def n_p(self) -> int:
        return self.BT.shape[0]

    @cached_property
    def pressure_block(self) -> sp.csr_matrix | None:
        """The pressure-pressure block: ``orphans`` plus the extension's constraint rows."""
        if self.extension is None:
            return self.orphans
        D = self.extension.block(self.n_p)
        return D if self.orphans is None else (self.orphans + D).tocsr()

    def apply(self, x: np.ndarray) -> np.ndarray:
        """``K x`` for ``x = [u, p]`` (n_u + n_p,), without the border row."""
        u, p = x[:self.n_u], x[self.n_u:]
        q = self.BT @ u if isinstance(self.BT, ContinuityBlock) else matvec(self.BT, u)
        if self.pressure_block is not None:
            q += self.pressure_block @ p
        return np.concatenate([matvec(self.A, u) + self.apply_gradient(p), q])

    def balance(self, g: np.ndarray) -> np.ndarray:
        """Continuity right-hand side(s) made solvable (:func:`balance_volume`); ``g`` itself when
        the pressure is determined."""
        if self.mean_weights is None:
            return g
        return balance_volume(g, self.mean_weights, self.orphans, self.space.dim + 1, self.extension)

    def remove_pressure_mean(self, x: np.ndarray) -> None:
        """Shift the pressure part of ``x`` in place so that ``mean_weights · p = 0`` (no-op when
        the pressure is determined)."""
        if self.mean_weights is None:
            return
        p = x[self.n_u:]
        const = np.zeros(self.n_p)
        const[::self.space.dim + 1] = 1.0  # the constant pressure: mean DOFs of P1disc
        p -= np.multiply.outer(const, self.mean_weights @ p) / (self.mean_weights @ const)

    def matrix(self, bordered: bool = True) -> sp.spmatrix:
        """The assembled system matrix, bordered by ``mean_weights`` (CSC) unless ``bordered`` is
        False (CSR, explicit zeros of the blocks kept, sorted indices). The unbordered one is
        stacked row-wise from CSR blocks without a COO round trip (scipy's ``bmat`` took 3.6 s
        per factorisation at ten-cate level 1)."""
        C = self.pressure_block
        A = self.A.tocsr() if isinstance(self.A, VelocityBlock) else self.A
        if bordered and self.mean_weights is not None:
            w = sp.csr_matrix(self.mean_weights[None, :])
            blocks = [[A, self.gradient, None], [as_csr(self.BT), C, w.T], [None, w, None]]
            return sp.bmat(blocks, format="csc")
        C = sp.csr_matrix((self.n_p, self.n_p)) if C is None else sp.csr_matrix(C)
        top = sp.hstack([sp.csr_matrix(A), self.gradient], format="csr")
        K = sp.vstack([top, sp.hstack([as_csr(self.BT), C], format="csr")], format="csr")
        K.sort_indices()
        return K


def as_csr(M) -> sp.csr_matrix:
    """A continuity block assembled (:meth:`~fbmflow.fem.continuity_block.ContinuityBlock.tocsr`),
    any other sparse matrix as CSR."""
    return M.tocsr() if isinstance(M, ContinuityBlock) else sp.csr_matrix(M)


def without_orphaned_modes(BT, orphans: sp.csr_matrix):
    """``B^T - C B^T`` (``C`` the orphans' projector, (n_p, n_p); ``BT`` CSR or a
    :class:`~fbmflow.fem.continuity_block.ContinuityBlock`, the result the same) with only the
    modes' rows changed (:func:`~fbmflow.fem.continuity_block.splice_rows`): every other row
    keeps its entries, explicit zeros included (a wall's zeroed columns), so that a cell's rows
    stay in the divergence's cell-local pattern, where the factored Vanka smoother reads its
    ``D`` (``fbmflow.solvers._kernels.continuity_in_patch_order``)."""
    rows = np.flatnonzero(np.diff(orphans.indptr))
    R = BT[rows] - orphans[rows] @ BT
    return BT.splice(rows, R) if isinstance(BT, ContinuityBlock) else splice_rows(BT, rows, R)


def orphan_pressure_modes(BT: sp.csr_matrix, npl: int, tol: float = 1e-10,
                          closed: bool = False, zero: np.ndarray | None = None) -> sp.csr_matrix | None:
    """Projector onto the pressure modes that ``B^T`` (constrained columns zeroed, or the
    columns ``zero`` (k,) int taken as zero, as :func:`~fbmflow.fem.continuity_block.zero_columns`
    would make them: no copy of ``B^T``) no longer
    couples to any velocity: (n_p, n_p) CSR, or None when there are none. ``closed``: the
    pressure is fixed by its mean (velocities prescribed on the whole boundary), so the constant
    pressure is not one of them even when it lies in their span (``_without_constant``).

    A mode ``q`` is orphaned when ``B q = 0``. It lives on cells that lost velocity columns
    (candidates; a cell with all its velocities free keeps its pressure in every mode). The
    candidates are pruned: a velocity row of a candidate cell that no other candidate shares
    constrains that cell's pressure alone, and a cell whose such rows have full rank carries no
    orphaned mode. The remaining cells, grouped into clusters that share velocity rows, get the
    null space of their part of ``B`` from a dense SVD (singular values below ``tol max|B|``):
    batched for single cells (a cell inside a particle), one SVD per larger cluster (several
    cut cells whose few free velocities only balance each other, e.g. inside a particle next to
    a wall). The rows of ``B^T`` are cell-local with ``dim nl`` entries each, so the local blocks
    are a reshape.
    """
    n_p, n_u = BT.shape
    n_cells = n_p // npl
    width = BT.indptr[1] - BT.indptr[0]
    Bc = BT.data.reshape(n_cells, npl, width)
    cols = BT.indices.reshape(n_cells, npl, width)[:, 0, :]
    unseen, scale = _unseen_columns(BT, Bc)
    zeroed = None
    active = unseen
    if zero is not None:
        zeroed = np.zeros(n_u, dtype=bool)
        zeroed[zero] = True
        active = np.union1d(unseen, np.flatnonzero(zeroed[cols].any(axis=1)))
    live = np.zeros((n_cells, width), dtype=bool)  # columns that see the cell: of the active cells only
    live[active] = ~(Bc[active] == 0.0).all(axis=1)
    if zeroed is not None:
        live[active] &= ~zeroed[cols[active]]
    while active.size:
        count = np.bincount(cols[active][live[active]], minlength=n_u)
        private = live[active] & (count[cols[active]] == 1)
        keep = _rank_deficient(Bc[active] * private[:, None, :], tol * scale)
        if keep.all():
            break
        active = active[keep]
    if active.size == 0:
        return None
    incidence = sp.csr_matrix((np.ones(int(live[active].sum())), (np.nonzero(live[active])[0],
                                                                   cols[active][live[active]])),
                              shape=(active.size, n_u))
    n_comp, label = csgraph.connected_components(incidence @ incidence.T, directed=False)
    rows, colidx, vals = [], [], []
    size = np.bincount(label, minlength=n_comp)
    single = active[size[label] == 1]
    for comp in np.flatnonzero(size > 1):  # clusters: few per mesh
        cells = active[label == comp]
        if cells.size * npl > MAX_CLUSTER_MODES:  # a thin mesh where every cell touches a wall
            log.warning("%d cells share their free velocities; looking for orphaned pressure modes "
                        "cell by cell only", cells.size)
            single = np.union1d(single, cells)
            continue
        dofs = (cells[:, None] * npl + np.arange(npl)).ravel()
        M = BT[dofs].T.tocsr()
        seen = abs(M).max(axis=1).toarray().ravel() != 0.0
        if zeroed is not None:
            seen &= ~zeroed
        M = M[np.flatnonzero(seen)].toarray()  # (velocity rows, modes)
        if M.shape[0] < M.shape[1]:
            M = np.vstack([M, np.zeros((M.shape[1] - M.shape[0], M.shape[1]))])
        _, sv, Vt = np.linalg.svd(M, full_matrices=False)
        null = Vt[sv <= tol * scale]
        if len(null):
            block = null.T @ null
            rows.append(np.repeat(dofs, dofs.size))
            colidx.append(np.tile(dofs, dofs.size))
            vals.append(block.ravel())
    if single.size:  # cells alone: batched SVD of their blocks, null left vectors
        U, sv, _ = np.linalg.svd(Bc[single] * live[single][:, None, :], full_matrices=False)
        blocks = np.einsum("cmk,ck,cnk->cmn", U, (sv <= tol * scale).astype(float), U)
        dofs = single[:, None] * npl + np.arange(npl)
        rows.append(np.repeat(dofs, npl, axis=1).ravel())
        colidx.append(np.tile(dofs, (1, npl)).ravel())
        vals.append(blocks.ravel())
    if not rows:
        return None
    P = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(colidx))),
                      shape=(n_p, n_p))
    P.data[np.abs(P.data) < 1e-14] = 0.0
    P.eliminate_zeros()
    if closed and P.nnz:
        P = _without_constant(P, npl)
    return P if P is not None and P.nnz else None


def cell_values(space, BT: sp.csr_matrix) -> np.ndarray:
    """The values of a divergence ``BT`` (n_p, n_u) in its cell-local pattern (:func:`cell_local`)
    as (n_cells, d + 1, d nl) float64, a view: entry ``[c, m, i nl + r]`` is that of row ``c (d +
    1) + m`` and of component ``i`` of the cell's node at position ``r`` in ascending order
    (:attr:`~fbmflow.fem.space.FlowSpace.local_rank`)."""
    n_cells, nl = space.V.cell_dofs.shape
    return BT.data.reshape(n_cells, space.dim + 1, space.dim * nl)


def cell_local(space, BT) -> bool:
    """Whether the divergence ``BT`` (n_p, n_u) is in its cell-local pattern on ``space``: CSR,
    every row ``c (d + 1) + m`` of cell ``c`` with the ``d nl`` columns ``i n_v + a`` of the
    cell's nodes ``a``, ascending (as :func:`~fbmflow.fem.assembly.assemble_divergence` makes it,
    explicit zeros kept), so that its values read as :func:`cell_values`. Kept per ``BT`` while
    it lives (one pass over its columns)."""
    def check(_):
        n_cells, nl = space.V.cell_dofs.shape
        npl, width = space.dim + 1, space.dim * nl
        if (not sp.issparse(BT) or BT.format != "csr" or BT.shape != (n_cells * npl, space.n_u)
                or BT.nnz != BT.shape[0] * width
                or not np.array_equal(BT.indptr, np.arange(BT.shape[0] + 1) * width)):
            return False
        nodes = np.sort(space.V.cell_dofs, axis=1)[:, None, None, :]
        expected = nodes + space.n_v * np.arange(space.dim)[None, None, :, None]
        return bool((BT.indices.reshape(n_cells, npl, space.dim, nl) == expected).all())

    return _CELL_LOCAL.get(BT, "cell-local", check)


#: per divergence matrix (by identity, while it lives) :func:`cell_local`'s answer
_CELL_LOCAL = KeptByIdentity()

#: per divergence matrix (by identity, while it lives) :func:`_unseen_columns`'s answer
_UNSEEN = KeptByIdentity()


def _unseen_columns(BT: sp.csr_matrix, Bc: np.ndarray) -> tuple[np.ndarray, float]:
    """The cells of ``BT`` (its data ``Bc`` as (n_cells, npl, width)) with a column none of
    their rows sees, (k,) int64, and ``max |B|``: computed at the first call for ``BT`` and kept
    while it lives (a level's divergence, never written, that every linearisation's
    constraints ask about: ten Cate level 2, two passes over 530 MB each time)."""
    def look(_):
        unseen = np.flatnonzero((Bc == 0.0).all(axis=1).any(axis=1))
        return unseen, max(Bc.max(initial=0.0), -Bc.min(initial=0.0))

    return _UNSEEN.get(BT, "unseen columns", look)


def _rank_deficient(blocks: np.ndarray, threshold: float) -> np.ndarray:
    """Which blocks (n, m, k) have a singular value at most ``threshold``, (n,) bool.

    A block with fewer than ``m`` non-zero columns has rank below ``m`` (a cut cell whose free
    velocities other cells share, or none). The eigenvalues of the other blocks' Gram matrices
    ``b b^T`` (m x m, a few times cheaper than the blocks' SVD) clear most of them: one whose
    smallest eigenvalue exceeds ``threshold^2 + 1e-12 lambda_max`` has every singular value above
    ``threshold`` (the eigenvalues' rounding error is a few ``eps lambda_max``). The rest, the
    candidates, get the SVD's answer.
    """
    out = (blocks != 0.0).any(axis=1).sum(axis=1) < blocks.shape[1]
    rest = np.flatnonzero(~out)
    if rest.size:
        b = blocks[rest]
        lam = np.linalg.eigvalsh(b @ b.transpose(0, 2, 1))
        check = rest[lam[:, 0] <= threshold**2 + 1e-12 * lam[:, -1]]
        if check.size:
            sv = np.linalg.svd(blocks[check], compute_uv=False)
            out[check] = (sv <= threshold).any(axis=1)
    return out


def balance_volume(g: np.ndarray, mean_weights: np.ndarray, orphans: sp.csr_matrix | None,
                   npl: int, extension=None, dot=None) -> np.ndarray:
    """Continuity right-hand side(s) ``g`` ((n_p,) or (n_p, k)) made solvable in a closed domain:
    ``g - lambda w`` with ``lambda = (q · g) / (q · w)``, a copy.

    In a box with velocities prescribed on every face the continuity equations can only be
    satisfied together if the prescribed fluxes into the fluid add up to zero: ``q · g = 0`` for
    the saddle-point matrix's left null vector ``q``, the constant pressure ``1`` less its orphaned
    part (``q = 1 - C 1``). A rigid motion is divergence-free, but once a particle is within a
    node layer of a wall (or of another particle) the cells in between have only prescribed
    velocities, their continuity drops out (orphaned modes), and the particle's motion into them
    is a net flux that no free velocity can carry: Newton then stalls with the whole defect in the
    one cell whose pressure is pinned (measured: glowinski level 2, t = 0.728 s, gap 0.4 cells,
    ``|F_p| = 0.087`` for ever). ``lambda w``, with ``w = (1 - C) int psi`` the mean weights less
    their orphaned part, spreads the defect as a uniform expansion rate ``lambda`` [1/s] over the
    fluid: the Lagrange multiplier that the mean-pressure border row ``w · p = 0`` would carry.
    For compatible data ``lambda`` is round-off and nothing changes. ``dot``: the inner product of
    pressure vectors (default ``q @ g``; one process's part: the sum over the cells it owns).
    ``q`` and ``w`` are kept for the last two ``(mean_weights, orphans, extension)``
    (``_null_and_expansion``).
    """
    q, w, qw = _null_and_expansion(mean_weights, orphans, npl, extension)
    if dot is None:
        lam = (q @ g) / qw
    else:
        lam = (dot(q, g) if g.ndim == 1 else np.array([dot(q, c) for c in g.T])) / dot(q, w)
    out = np.multiply.outer(w, -lam)  # one array of g's size, no temporary beside it
    out += g
    return out


#: :func:`_null_and_expansion`'s last results, newest first, with their arguments
_NULL_AND_EXPANSION: list[tuple[tuple, tuple]] = []


def _null_and_expansion(mean_weights: np.ndarray, orphans: sp.csr_matrix | None, npl: int,
                        extension=None) -> tuple[np.ndarray, np.ndarray, float]:
    """The continuity rows' left null vector ``q = 1 - C 1`` (the continued cells' zero), the
    expansion column ``w`` (:func:`expansion`) and ``q · w``: (n_p,), (n_p,), float. Kept for the
    last two sets of arguments, found again by identity (none of them is ever written): a step's
    residuals and solves ask about the same constraints some ten times (a call at ten Cate level
    2's size, 276 480 pressures, measured alone: 9.2-9.8 ms made afresh, 0.11 ms kept)."""
    for (mw, C, ext, n), found in _NULL_AND_EXPANSION:
        if mw is mean_weights and C is orphans and ext is extension and n == npl:
            return found
    q = np.zeros(len(mean_weights))
    q[::npl] = 1.0
    if orphans is not None:
        q -= orphans @ q
    if extension is not None:  # continued cells: no continuity rows of their own
        q[extension.dofs] = 0.0
    w = expansion(mean_weights, orphans, extension)
    q.flags.writeable = False
    if w is not mean_weights:
        w.flags.writeable = False
    found = (q, w, float(q @ w))
    _NULL_AND_EXPANSION.insert(0, ((mean_weights, orphans, extension, npl), found))
    del _NULL_AND_EXPANSION[2:]
    return found


def expansion(mean_weights: np.ndarray, orphans: sp.csr_matrix | None, extension=None) -> np.ndarray:
    """The continuity rows' response to a uniform expansion rate of the fluid, (n_p,): the mean
    weights less their orphaned part, moved to the continuing cells by a pressure extension. The
    column of the mean-pressure border (:func:`balance_volume`)."""
    w = np.asarray(mean_weights, dtype=float)
    if orphans is not None:
        w = w - orphans @ w
    return w if extension is None else extension.transfer(w)


def _without_constant(P: sp.csr_matrix, npl: int) -> sp.csr_matrix | None:
    """``P`` less the constant pressure when that lies in its range: in a closed domain the mean
    fixes the constant (a small closed box where every cell touches a wall finds it orphaned)."""
    const = np.zeros(P.shape[0])
    const[::npl] = 1.0 / np.sqrt(P.shape[0] // npl)
    if np.linalg.norm(P @ const - const) > 1e-8:
        return P
    idx = np.flatnonzero(const)
    n = idx.size
    Q = (P - sp.csr_matrix((np.full(n * n, const[idx[0]] ** 2), (np.repeat(idx, n), np.tile(idx, n))),
                           shape=P.shape)).tocsr()
    Q.data[np.abs(Q.data) < 1e-14] = 0.0
    Q.eliminate_zeros()
    return Q if Q.nnz else None


def cell_blocks(P: sp.spmatrix | None, n_cells: int, npl: int) -> np.ndarray:
    """The diagonal ``npl x npl`` blocks of a pressure-pressure matrix, (n_cells, npl, npl)
    (zeros for ``P = None``): what cell-wise smoothers see of it."""
    blocks = np.zeros((n_cells, npl, npl))
    if P is not None:
        C = P.tocoo()
        own = C.row // npl == C.col // npl
        blocks[C.row[own] // npl, C.row[own] % npl, C.col[own] % npl] = C.data[own]
    return blocks


