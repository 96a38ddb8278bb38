"""Vanka-type smoothers for the Q2/P1disc saddle-point system.

Each cell's DOFs (its ``dim * nl`` velocity and ``dim + 1`` pressure unknowns) get a correction
from the local saddle-point problem driven by the current residual, and the next cell's residual
sees it: a sweep is a sequential block Gauss–Seidel sweep in slab order
(:mod:`fbmflow.solvers.ordering`: lexicographic within slabs that threads sweep at the same
time), the same whatever the number of threads.

Variants (a registry):

* ``vanka-full``: the full local block ``[[A_cc, B_c], [B_c^T, 0]]`` solved by LU (21 x 21 in 2D,
  85 x 85 in 3D); robust for convection-dominated Oseen/Newton systems.
* ``vanka-diagonal``: ``A_cc`` replaced by its diagonal and solved through the
  ``(dim+1) x (dim+1)`` Schur complement, precomputed per cell; cheap, for Stokes-like systems.
"""
from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp
import scipy.sparse.csgraph as csgraph

from .._jit import numba_threads
from ..fem.continuity_block import ContinuityBlock
from ..fem.velocity_block import VelocityBlock
from ..kept import KeptByIdentity
from . import _kernels, ordering
from .system import SaddlePointSystem, as_csr, cell_blocks, cell_local, cell_values


class VankaSmoother:
    """Cell-wise Vanka smoother on one level.

    Parameters
    ----------
    system : SaddlePointSystem with ``space`` set
    variant : "vanka-full" or "vanka-diagonal"
    omega : float, damping of the corrections
    symmetric : bool, every second sweep backwards (symmetric Gauss–Seidel) instead of forwards
    """

    factor_time_s = 0.0  # it stores no local factors

    def __init__(self, system: SaddlePointSystem, variant: str = "vanka-full", omega: float = 1.0,
                 symmetric: bool = False):
        if variant not in VANKA_VARIANTS:
            raise ValueError(f"unknown smoother {variant!r}; choose one of {sorted(VANKA_VARIANTS)}")
        self.variant = variant
        self.omega = omega
        self.system = system
        space = system.space
        self.space = space
        BT = as_csr(system.BT)
        B = BT.T.tocsr()
        self._b = (B.indptr.astype(np.int64), B.indices.astype(np.int64), B.data)
        A = system.A.tocsr() if isinstance(system.A, VelocityBlock) else system.A  # on the space's pattern
        nb = A.data.size // (space.dim * space.nnz)  # blocks per row: dim or 1
        npl = space.dim + 1
        pblock = cell_blocks(system.orphans, space.mesh.n_cells, npl)  # cluster modes: cell parts only
        self._common = (space.dim, nb, space.n_v, space.indptr, space.indices, A.data,
                        *self._b, BT.data, space.local_rank, space.V.cell_dofs, pblock)
        if variant == "vanka-diagonal":
            diag = A.diagonal()
            diag_inv = np.where(diag != 0.0, 1.0 / np.where(diag != 0.0, diag, 1.0), 0.0)
            S = _kernels.schur_diagonal(BT.data, space.local_rank, space.V.cell_dofs,
                                        diag_inv, space.dim, space.n_v)
            self._extra = (diag_inv, np.linalg.pinv(S + pblock, rcond=1e-12, hermitian=True))
        else:
            self._extra = (space.offsets,)
        mesh = space.mesh
        reach = int(ordering.unknown_reach(system).max())
        phases = ordering.slab_phases(mesh.shape, mesh.periodic, mesh.cell_indices(), np.arange(mesh.n_cells),
                                      reach)
        self.sweeps = [phases, ordering.reversed_phases(phases)] if symmetric else [phases]
        self._kernel = _kernels.vanka_full if variant == "vanka-full" else _kernels.vanka_diagonal

    def update(self, cells: np.ndarray, b: np.ndarray, x: np.ndarray, omega: float | None = None) -> None:
        """Add ``omega`` times the local correction of each of ``cells`` to ``x``, one after the
        other."""
        self._kernel(np.array([0, cells.size]), cells, b, x, self.omega if omega is None else omega,
                     *self._common, *self._extra)

    def smooth(self, b: np.ndarray, x: np.ndarray, sweeps: int) -> None:
        """``sweeps`` smoothing sweeps on ``K x = b`` in slab order (:mod:`fbmflow.solvers.ordering`),
        updating ``x`` in place."""
        for k in range(sweeps):
            for gptr, order in self.sweeps[k % len(self.sweeps)]:
                self._kernel(gptr, order, b, x, self.omega, *self._common, *self._extra)


PRECISIONS = {"single": np.float32, "double": np.float64}
#: a level with fewer cells than this many per Numba thread is swept on one thread, phase after
#: phase without a parallel region: its phases have a few groups of short work for the threads,
#: and each region's barrier waits for the slowest one. 256: ten Cate level 1's coarse level (1 152
#: cells) is swept in parallel on 2 threads (its serial sweeps took 1.9 s of a 17.9 s step; the
#: step on 2 threads 12.98-13.00 s against 14.40-15.11 s with 4 096 cells for every thread count,
#: benchmarks/results/thread_scaling.md, tag coarse-parallel) and on one thread from 5 threads
#: (4 096 cells on 16, as before)
SERIAL_CELLS_PER_THREAD = 256
VANKA_VARIANTS = {"vanka-full": 0.7, "vanka-diagonal": 0.7, "vanka-factored": 0.7}  # name -> default damping
#: the orders of the factored smoother's cell patches (:class:`FactoredVankaSmoother`)
ORDERS = ("slabs", "colours")


def saddle_point_csr(system: SaddlePointSystem, dtype, keep_u: np.ndarray | None = None,
                     continuity: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(indptr, indices, data)`` of ``K = [[A, G], [D, C]]`` (the system's blocks, whatever
    their row patterns; ``C`` may be None): int64 row pointers, int32 column indices, ``dtype``
    values, (n_u + n_p + 1,), (nnz,), (nnz,). Velocity rows where ``keep_u`` (n_u,) bool is
    False are left empty (their rows of ``G`` not even made:
    :meth:`~fbmflow.solvers.system.SaddlePointSystem.gradient_rows`), and the continuity block
    ``D`` where ``continuity`` is False (the pressure rows then hold ``C`` only)."""
    n_u, n_p = system.n_u, system.n_p
    keep_u = np.ones(n_u, dtype=bool) if keep_u is None else keep_u
    blocks = []
    A = system.A.select(keep_u) if isinstance(system.A, VelocityBlock) else system.A
    kept = system.gradient_rows(np.flatnonzero(keep_u))
    lengths = np.zeros(n_u, dtype=np.int64)
    lengths[keep_u] = np.diff(kept.indptr)
    G = sp.csr_matrix((kept.data, kept.indices, np.concatenate([[0], np.cumsum(lengths)])), shape=(n_u, n_p))
    for M, shape in ((A, (n_u, n_u)), (G, (n_u, n_p)), (system.BT if continuity else None, (n_p, n_u)),
                     (system.pressure_block, (n_p, n_p))):
        M = sp.csr_matrix(shape) if M is None else as_csr(M)
        blocks += [M.indptr, M.indices, M.data]
    ptr = np.zeros(n_u + n_p + 1, dtype=np.int64)
    ptr[1:n_u + 1] = np.where(keep_u, np.diff(blocks[0]) + np.diff(blocks[3]), 0)
    ptr[n_u + 1:] = np.diff(blocks[6]) + np.diff(blocks[9])
    np.cumsum(ptr, out=ptr)
    idx, val = np.empty(ptr[-1], dtype=np.int32), np.empty(ptr[-1], dtype=dtype)
    _kernels.merge_blocks(*blocks, keep_u, ptr, idx, val)
    return ptr, idx, val


def _clusters(system: SaddlePointSystem, npl: int) -> list[np.ndarray]:
    """The clusters of cells that the pressure block couples (an orphaned pressure mode spread
    over several cells: cut cells along a cylinder that spans the domain, whose few free
    velocities only balance each other; cells next to each other inside particles at a wall on
    a coarse level), (k,) int64 cells each. Cell patches see only their own part of such a mode:
    block Gauss–Seidel over them leaves it nearly untouched, and alternating them with a patch
    of the whole cluster can diverge (measured: 1e3 times per sweep on a coarse level of 2 000
    disks), so each cluster is one patch instead of its cells' patches."""
    C = system.pressure_block
    if C is None:
        return []
    C = sp.coo_matrix(C)
    across = C.row // npl != C.col // npl
    if not across.any():
        return []
    n_cells = system.n_p // npl
    graph = sp.csr_matrix((np.ones(int(across.sum())), (C.row[across] // npl, C.col[across] // npl)),
                          shape=(n_cells, n_cells))
    n_parts, label = csgraph.connected_components(graph, directed=False)
    size = np.bincount(label, minlength=n_parts)
    return [np.flatnonzero(label == part) for part in np.flatnonzero(size > 1)]


def _cell_patches(space) -> np.ndarray:
    """Every cell's patch of ``space``: its nodes in ascending order (its divergence rows' order)
    on each velocity component, then its ``d + 1`` pressures; (n_cells, d nl + d + 1) int32 indices
    of the saddle-point unknowns, read-only. Kept while the space lives (``_KEPT``): about 12 bytes
    per unknown in 3D, made once instead of at every set-up."""
    d, n_v = space.dim, space.n_v
    nodes = np.sort(space.V.cell_dofs, axis=1).astype(np.int32)
    n_cells, npl = nodes.shape[0], d + 1
    pressures = (d * n_v + np.arange(n_cells, dtype=np.int32)[:, None] * npl + np.arange(npl, dtype=np.int32))
    table = np.concatenate([nodes + np.int32(i * n_v) for i in range(d)] + [pressures], axis=1)
    table.flags.writeable = False
    return table


#: what every set-up on a space reads of it, made once (:func:`_cell_patches`)
_KEPT = KeptByIdentity()


def _divergence(system: SaddlePointSystem) -> sp.csr_matrix:
    """The divergence whose transpose gives the system's ``B`` (``gradient_BT``, else the level's
    divergence under a :class:`~fbmflow.fem.continuity_block.ContinuityBlock`, else ``BT``)."""
    if system.gradient_BT is not None:
        return system.gradient_BT
    return system.BT.base if isinstance(system.BT, ContinuityBlock) else system.BT


def _continuity_rows(system: SaddlePointSystem) -> tuple:
    """The continuity rows as the factored kernels read them (the operator's layout in
    :mod:`fbmflow.solvers._kernels`): ``(d_pos (n_p,) int32, d_ptr int64, d_idx int32, d_val
    float64, b_idx int32)``, the rows that differ from :func:`_divergence` in the CSR and the
    others read from it (every row in the CSR where the system's ``B^T`` is no block over it)."""
    D = system.BT
    if isinstance(D, ContinuityBlock) and D.base is _divergence(system):
        R = D.rows
        return (D.position, R.indptr.astype(np.int64), R.indices.astype(np.int32, copy=False), R.data,
                D.base.indices.astype(np.int32, copy=False))
    D = as_csr(D)
    return (np.arange(D.shape[0], dtype=np.int32), D.indptr.astype(np.int64),
            D.indices.astype(np.int32, copy=False), D.data, np.zeros(0, dtype=np.int32))


def _cell_gradient(system: SaddlePointSystem) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The gradient rows of the free velocity DOFs as the kernels read them from the divergence
    in its cell-local pattern (``gradient_BT``, else ``BT``; see the operator's layout in
    :mod:`fbmflow.solvers._kernels`): ``(nc_ptr (n_v + 1,) int64, nc_cell int32, nc_rank uint8,
    gt (n_cells, d + 1, d nl) float64)`` (the space's
    :attr:`~fbmflow.fem.space.FlowSpace.node_cell_ranks` and :func:`~fbmflow.solvers.system.cell_values`,
    a view of the divergence's values). Raises ValueError where the divergence is not in that
    pattern."""
    source = _divergence(system)
    if not cell_local(system.space, source):
        raise ValueError("the factored Vanka smoother needs the divergence in its cell-local pattern")
    return (*system.space.node_cell_ranks, cell_values(system.space, source))


def partly_orphaned(system: SaddlePointSystem) -> bool:
    """Whether a cell of ``system`` has orphaned pressure modes (``orphans``, an orthogonal
    projector) and others beside them: the diagonal of the projector summed over some cell's
    pressures lies strictly between 0 and ``dim + 1`` (a cell wholly inside a particle has all
    its modes orphaned, a fluid cell none)."""
    if system.orphans is None or system.space is None:
        return False
    npl = system.space.dim + 1
    rank = system.orphans.diagonal().reshape(-1, npl).sum(axis=1)
    return bool(np.any((rank > 1e-6) & (rank < npl - 1e-6)))


class FactoredVankaSmoother:
    """Full Vanka on any row structure, local LU factors stored (``vanka-factored``).

    A patch is a cell's DOFs (its ``dim nl`` velocity and ``dim + 1`` pressure unknowns); where
    the system continues cut cells' pressures from other cells (the sharp boundary's
    :class:`~fbmflow.fem.constraints.PressureExtension`, whose continuity rows join the target's)
    the target's patch takes in the cells continued from it: the agglomerated element of the
    discretisation. The local blocks ``K[S, S]`` are read from the assembled blocks (CSR rows,
    whatever their pattern: ghost-node rows, transferred continuity rows, Galerkin coarse rows)
    and factorised once; a sweep then costs a residual and two triangular solves per patch.
    Cell patches go in slab order (:mod:`fbmflow.solvers.ordering`: a sequential block
    Gauss–Seidel sweep in lexicographic order within slabs or blocks that threads sweep at once),
    those whose rows reach further than most (:func:`~fbmflow.solvers.ordering.near_patches`)
    after them one after the other (before them in a backward sweep); then the patches at and
    inside the fictitious boundaries (those that hold a constrained velocity, fixed or
    row-constrained, not a wall's) get ``interface_sweeps`` more updates, the cell patches among
    them in slab phases as well and the agglomerated ones after them in colours (patches of one
    colour touch nothing of each other: one parallel phase per colour); then all agglomerated
    patches in colours. A cluster of cells whose pressures share an
    orphaned mode (the pressure block couples them; ``_clusters``) is agglomerated too, into one
    patch instead of its cells' patches.

    Parameters
    ----------
    system : SaddlePointSystem with ``space`` set
    omega : float, damping of the corrections
    precision : "auto", "single" or "double"
        Storage of the smoother's copy of the blocks and of the local factors (the factors are
        computed in double; residuals and corrections are always accumulated in double).
        Single halves the memory the sweeps stream through. "auto": single, or double where a
        cell keeps pressure modes beside orphaned ones (:func:`partly_orphaned`): the few free
        velocities of such a cell see them barely, its patch is too ill-conditioned for single
        precision, which drops them, and the cycle stalls (measured: a sphere of 3 cells per
        diameter on the nodal boundary, a cell with one free node of 27, local condition number
        7e9: FGMRES stalled at a residual reduction of 3e-3; converged in 2-4 cycles in double).
    interface_sweeps : int
        Extra sequential updates of the patches at the fictitious boundaries per sweep, where
        the error the constraints leave is local and rough (the cycle counts they buy:
        docs/validation/).
    symmetric : bool, every second sweep backwards (symmetric Gauss–Seidel) instead of forwards
    component_blocks : bool
        Cells whose velocity rows couple no two components but are no one scalar row (a
        symmetry plane's unit rows) solved through the Schur complement of their ``d``
        component blocks (True) or by an LU of the whole block (False: 2.5 times their factors'
        memory, the same corrections to rounding).
    cells : (n_cells,) bool or None, the cells whose patches the sweeps update (None: all): a
        process's owned cells on its slab of the mesh (:mod:`fbmflow.parallel.blocks`), whose halo
        cells are a neighbour's to update
    order : "slabs" or "colours"
        The order of the cell patches: slab phases (above), or colours
        (:func:`~fbmflow.solvers.ordering.colour_phases`: a colour's patches at once, the far
        ones in colours of their own after them), the order in which the GPU sweeps
        (:mod:`fbmflow.gpu`), so that the CPU can reproduce its sweeps.
    factor : bool
        Compute the local factors here (True), or leave ``store`` and ``piv`` None for the GPU to
        compute on the device (:class:`~fbmflow.gpu.vanka.DeviceVanka`; ``dtype`` and
        ``schur_tol`` say how); such a smoother cannot sweep on the CPU.
    """

    def __init__(self, system: SaddlePointSystem, omega: float = 0.7, precision: str = "auto",
                 interface_sweeps: int = 2, symmetric: bool = False, component_blocks: bool = True,
                 cells: np.ndarray | None = None, order: str = "slabs", factor: bool = True):
        if order not in ORDERS:
            raise ValueError(f"unknown patch order {order!r}; choose one of {ORDERS}")
        if precision == "auto":
            precision = "double" if partly_orphaned(system) else "single"
        if precision not in PRECISIONS:
            raise ValueError(f"unknown precision {precision!r}; choose one of {sorted(PRECISIONS)}")
        dtype = PRECISIONS[precision]
        space = system.space
        d, npl, n_u, n_v = space.dim, space.dim + 1, system.n_u, space.n_v
        cd = space.V.cell_dofs
        n_cells, nl = cd.shape
        cell_dofs = _KEPT.get(space, "cell patches", _cell_patches)
        plain = np.ones(n_cells, dtype=bool) if cells is None else np.array(cells, dtype=bool)
        merged = []
        if system.extension is not None:
            E = system.extension.matrix.tocsr()
            rows = system.extension.dofs[::npl]  # first pressure DOF of every continued cell
            source, target = rows // npl, E.indices[E.indptr[rows]] // npl
            plain[source] = plain[target] = False
            for t in np.unique(target):
                cells = np.concatenate([[t], source[target == t]])
                merged.append(np.unique(cell_dofs[cells].ravel()))
        free = np.ones(n_u, dtype=bool)
        if system.fixed is not None:
            free[system.fixed] = False
        for cluster in _clusters(system, npl):  # the cells' pressures and free velocities
            plain[cluster] = False
            velocity = np.unique(cell_dofs[cluster, :-npl].ravel())
            merged.append(np.concatenate([velocity[free[velocity]], cell_dofs[cluster, -npl:].ravel()]))
        cells = np.flatnonzero(plain)
        # the operator in four parts (the kernels' "op"), three of them the system's own arrays:
        # the scalar rows of the nodes ``held``, read where the block holds them (a
        # VelocityBlock's scalar operator, or an assembled block's component-0 rows), their
        # gradient rows from the divergence cell by cell, the continuity rows from ``B^T``, and
        # a copy of every other row (the other velocity rows, the pressure block).
        # ``regular``: the nodes whose d rows are one scalar row (a Schur patch shares one block
        # over them); ``held``: those whose row the block's scalar part holds and whose gradient
        # rows are the divergence's (the constrained nodes' rows are read as other rows)
        if isinstance(system.A, VelocityBlock):
            block = system.A
            regular = block.regular
            held = regular.copy()
            held[block.dofs % n_v] = False
            scalar_rows = (block.space.indptr, block.space.indices, block.data)
            R = block.rows
            crossing = np.zeros(n_v, dtype=bool)
            crossing[block.dofs[_kernels.crossing_rows(R.indptr, R.indices, R.data, block.dofs, n_v)]
                     % n_v] = True
        else:
            A = sp.csr_matrix(system.A)
            regular = _kernels.regular_nodes(A.indptr, A.indices, A.data, n_v, d)
            held = regular.copy()
            scalar_rows = (A.indptr.astype(np.int64, copy=False), A.indices.astype(np.int32, copy=False),
                           A.data)
            rows = np.arange(n_u, dtype=np.int64)
            crossing = np.zeros(n_v, dtype=bool)
            crossing[rows[_kernels.crossing_rows(A.indptr, A.indices, A.data, rows, n_v)] % n_v] = True
        for dofs in (system.fixed, system.rows):
            if dofs is not None:
                held[dofs % n_v] = False
        held_u = np.tile(held, d)
        self.op = (held, *scalar_rows, *_cell_gradient(system), *_continuity_rows(system),
                   *saddle_point_csr(system, dtype, ~held_u, continuity=False))
        sizes = np.concatenate([np.full(cells.size, cell_dofs.shape[1]),
                                [m.size for m in merged]]).astype(np.int64)
        #: per patch the component inverses its Schur factors store (:func:`vanka_factor
        #: <fbmflow.solvers._kernels.vanka_factor>`): 1 for a cell of regular nodes, ``d`` for a
        #: cell whose velocity rows couple no two components, 0 (an LU of the whole block) else
        separate = ~crossing[cd[cells]].any(axis=1) if component_blocks else np.zeros(cells.size, dtype=bool)
        self.blocks = np.concatenate([np.where(regular[cd[cells]].all(axis=1), 1, np.where(separate, d, 0)),
                                      np.zeros(len(merged), dtype=np.int64)]).astype(np.int64)
        self.ptr = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        #: the patches' unknowns, int32 (an unknown's index fits: 2^31 unknowns would need some
        #: 3 TB): 12 bytes per unknown fewer on a fine 3D level than int64
        self.dofs = np.concatenate([cell_dofs[cells].ravel()] + merged).astype(np.int32, copy=False)
        #: per patch whether its Schur factors leave ``D`` out, the solve reading it from the
        #: continuity rows (a cell whose rows are the divergence's in its own pattern; ten Cate
        #: level 2: 46 bytes per unknown)
        self.d_read = _kernels.continuity_in_patch_order(self.ptr, self.dofs, self.blocks, d * nl, npl, n_u,
                                                         *self.op[8:11], self.op[12])
        schur_size = self.blocks * nl * nl + d * nl * npl * (2 - self.d_read) + npl * npl
        self.lu_ptr = np.concatenate([[0], np.cumsum(np.where(self.blocks > 0, schur_size,
                                                              sizes**2))]).astype(np.int64)
        self.width = int(sizes.max())
        self.shape = (nl, d, self.width, n_v, n_u)
        self.omega = omega
        mesh = space.mesh
        self.n_cells = mesh.n_cells
        index = mesh.cell_indices()
        reach = _kernels.patch_max(self.ptr, self.dofs, ordering.unknown_reach(system))  # per patch
        near = ordering.near_patches(reach[:cells.size])
        phased = ordering.slab_phases if order == "slabs" else ordering.colour_phases
        phases = phased(mesh.shape, mesh.periodic, index, cells[near],
                        int(reach[:cells.size][near].max(initial=0)))
        phases = [(gptr, np.flatnonzero(near)[k]) for gptr, k in phases]  # as patch indices
        #: cell patches whose rows reach too far for the phases, updated after them one by one (in
        #: colours after them where the order is "colours")
        self.far = np.flatnonzero(~near).astype(np.int64)
        if order == "colours":
            phases += self._colour_phases(system, self.far)
            self.far = self.far[:0]
        self.order = order
        self.sweeps = [(phases, self.far), (ordering.reversed_phases(phases), self.far[::-1].copy())]
        self.sweeps = self.sweeps if symmetric else self.sweeps[:1]
        self.merged = np.arange(cells.size, cells.size + len(merged), dtype=np.int64)
        self.interface_sweeps = interface_sweeps
        self.interface = self._interface_patches(system)
        # the cell patches among them in slab phases too (patch k < cells.size is cell cells[k]);
        # the agglomerated ones, which may reach across slabs, in colours
        plain_interface = self.interface[self.interface < cells.size]
        #: the agglomerated patches in colours that touch nothing of each other (one parallel
        #: phase each), all of them and those at the fictitious boundaries
        self.merged_phases = self._colour_phases(system, self.merged)
        merged_interface = self.interface[self.interface >= cells.size]
        # the same colours where they are all of them (a list of its own: studies tell them apart)
        all_merged = np.array_equal(merged_interface, self.merged)
        self.interface_merged_phases = (list(self.merged_phases) if all_merged
                                        else self._colour_phases(system, merged_interface))
        interface_reach = int(reach[plain_interface].max(initial=0))
        self.interface_phases = [(gptr, plain_interface[k]) for gptr, k in phased(
            mesh.shape, mesh.periodic, index, cells[plain_interface], interface_reach)]
        #: the factors' storage dtype and the Schur complements' pivot tolerance
        self.dtype = np.dtype(dtype)
        self.schur_tol = 10 * float(np.finfo(dtype).eps) if precision == "single" else 1e-13
        self.store = self.piv = None
        #: seconds spent computing the local factors (0 where ``factor`` is False)
        self.factor_time_s = 0.0
        if not factor:
            return
        t0 = time.perf_counter()
        self.store = np.empty(self.lu_ptr[-1], dtype=dtype)
        self.piv = np.zeros(self.ptr[-1], dtype=np.int32)
        _kernels.vanka_factor(self.store, self.lu_ptr, self.piv, self.ptr, self.dofs, self.blocks,
                              self.d_read, nl, d, 4 * numba_threads(), self.width, self.schur_tol, n_v, n_u,
                              *self.op)
        self.factor_time_s = time.perf_counter() - t0

    def _colour_phases(self, system: SaddlePointSystem, patches: np.ndarray) -> list:
        """``patches`` (m,) int64 in colours: two patches of one colour never touch an unknown the
        other reads (its rows' columns) or writes (:func:`~fbmflow.solvers._kernels.greedy_colours`
        on that conflict graph, in patch order), so that one colour's patches may be updated at the
        same time, each its own group. Phases as :func:`~fbmflow.solvers.ordering.slab_phases`'s,
        colour by colour."""
        if patches.size == 0:
            return []
        n_u = system.n_u
        sizes = self.ptr[patches + 1] - self.ptr[patches]
        start = np.repeat(self.ptr[patches] - np.concatenate([[0], np.cumsum(sizes)[:-1]]), sizes)
        dofs = self.dofs[start + np.arange(sizes.sum())]
        P = sp.csr_matrix((np.ones(dofs.size), (np.repeat(np.arange(patches.size), sizes), dofs)),
                          shape=(patches.size, n_u + system.n_p))
        # the rows of the patches' unknowns only (a copy of the whole |A| would raise the peak by
        # the fine velocity block), in absolute value (no entries cancelling in the sums)
        u, p = np.unique(dofs[dofs < n_u]), np.unique(dofs[dofs >= n_u]) - n_u
        Pu, Pp = P[:, u], P[:, n_u + p]
        A = system.A if isinstance(system.A, VelocityBlock) else sp.csr_matrix(system.A)
        reads_u = Pu @ abs(A[u]) + Pp @ abs(system.BT[p])
        reads_p = Pu @ abs(system.gradient_rows(u))
        if system.pressure_block is not None:
            reads_p = reads_p + Pp @ abs(system.pressure_block[p])
        touch = sp.hstack([reads_u, reads_p]).tocsr() @ P.T  # patch i reads what patch j writes
        touch = (touch + touch.T).tocsr()
        touch.setdiag(0.0)
        touch.eliminate_zeros()
        colour = _kernels.greedy_colours(touch.indptr, touch.indices)
        phases = []
        for c in range(int(colour.max()) + 1):
            chosen = patches[colour == c]
            phases.append((np.arange(chosen.size + 1, dtype=np.int64), chosen.astype(np.int64)))
        return phases

    @property
    def _patches(self) -> tuple:
        """The kernels' patch arguments (:func:`~fbmflow.solvers._kernels.vanka_sweep_groups`)."""
        if self.store is None:
            raise ValueError("this smoother's local factors were left to the GPU (factor=False): it cannot "
                             "sweep on the CPU")
        nl, d, width, n_v, n_u = self.shape
        return (self.ptr, self.dofs, self.lu_ptr, self.store, self.piv, self.blocks, self.d_read, nl, d,
                width, n_v, n_u)

    def _interface_patches(self, system: SaddlePointSystem) -> np.ndarray:
        """Patches (cells and agglomerated ones) holding a constrained velocity (fixed or
        row-constrained, not a wall's), (k,) int64."""
        constrained = np.zeros(system.n_u + system.n_p, dtype=np.uint8)
        for dofs in (system.fixed, system.rows):
            if dofs is not None:
                constrained[dofs] = 1
        if system.fixed_always is not None:
            constrained[system.fixed_always] = 0
        if not constrained.any():
            return np.zeros(0, dtype=np.int64)
        return np.flatnonzero(_kernels.patch_max(self.ptr, self.dofs, constrained)).astype(np.int64)

    def update(self, patches: np.ndarray, b: np.ndarray, x: np.ndarray, omega: float | None = None) -> None:
        """Add ``omega`` times the correction of each of ``patches`` to ``x``, one after the
        other (patches may share DOFs; without a pressure extension, patch ``c`` is cell ``c``)."""
        if patches.size:
            _kernels.vanka_sweep_sequential(patches, b, x, self.omega if omega is None else omega,
                                            *self._patches, *self.op)

    def smooth(self, b: np.ndarray, x: np.ndarray, sweeps: int, first: int = 0) -> None:
        """``sweeps`` smoothing sweeps on ``K x = b``, updating ``x`` in place; ``first``: the
        number of the first (the direction it goes in symmetric sweeps)."""
        for k in range(first, first + sweeps):
            phases, far = self.sweeps[k % len(self.sweeps)]
            if k % len(self.sweeps) == 1:  # backwards: the far patches first
                self.update(far, b, x)
            self.sweep_phases(phases, b, x)
            if k % len(self.sweeps) == 0:
                self.update(far, b, x)
            for _ in range(self.interface_sweeps):
                self.sweep_phases(self.interface_phases, b, x)
                self.sweep_phases(self.interface_merged_phases, b, x)
            self.sweep_phases(self.merged_phases, b, x)

    def sweep_phases(self, phases: list, b: np.ndarray, x: np.ndarray) -> None:
        """The patches of ``phases`` (:func:`~fbmflow.solvers.ordering.slab_phases`), each phase's
        slabs in parallel, or, on a level of fewer than :data:`SERIAL_CELLS_PER_THREAD` cells per
        Numba thread, one after the other in the same order (the same result: a phase's slabs touch
        nothing of each other)."""
        serial = self.n_cells < SERIAL_CELLS_PER_THREAD * numba_threads()
        for gptr, order in phases:
            if serial:
                _kernels.vanka_sweep_sequential(order[gptr[0]:gptr[-1]], b, x, self.omega, *self._patches,
                                                *self.op)
            else:
                _kernels.vanka_sweep_groups(gptr, order, b, x, self.omega, *self._patches, *self.op)
