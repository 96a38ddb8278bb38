"""The Q2/P1disc discretisation of one mesh: spaces, quadrature, geometry and sparsity.

Everything here depends only on the mesh and is computed once: the cell geometry at the
quadrature points, the CSR sparsity pattern of the scalar Q2 operator with the position of every
local entry in it (so re-assembly scatters straight into ``csr.data``), the pattern of the coupled
``dim x dim`` velocity block derived from it, and the colouring of the cells.
"""
from __future__ import annotations

import math
from functools import cached_property

import numpy as np
import scipy.sparse as sp

from .._jit import max_threads, numba_threads
from ..mesh import StructuredMesh
from . import _kernels
from .dofmap import DofMap, PressureDofMap
from .elements import ElementQ1
from .quadrature import gauss_tensor

#: cell groups per Numba thread in the parallel loops over one colour's cells: with ``G`` groups,
#: ``k`` threads take ``ceil(G / k)`` groups' time, so 15 threads of 16 with one group per thread
#: would run at the speed of 8; with four per thread, at that of 13
GROUPS_PER_THREAD = 4


class FlowSpace:
    """Q2 velocity / P1disc pressure spaces on a structured mesh.

    Parameters
    ----------
    mesh : StructuredMesh
    n_quad : int, default 3
        Gauss points per axis (3 integrates the Q2 mass and stiffness matrices exactly on
        affine cells).
    batch_size : int, optional
        Cells per assembly batch (bounds the temporary element-matrix memory).

    Notes
    -----
    Velocity vectors are component-blocked: ``u.reshape(dim, n_v)``; the coupled velocity
    unknown ``(i, r)`` is ``i * n_v + r``. Pressure DOF ``m`` of cell ``c`` is ``c (dim+1) + m``.
    """

    def __init__(self, mesh: StructuredMesh, n_quad: int = 3, batch_size: int | None = None):
        self.mesh = mesh
        self.dim = d = mesh.dim
        self.V = DofMap(mesh)
        self.Q = PressureDofMap(mesh)
        self.n_v = self.V.n_dofs
        self.n_u = d * self.n_v
        self.n_p = self.Q.n_dofs
        self.n_dofs = self.n_u + self.n_p
        self.points, self.weights = gauss_tensor(d, n_quad)
        self.phi, self.dphi = self.V.element.tabulate(self.points)
        _, dN = ElementQ1(d).tabulate(self.points)
        coords = mesh.cell_coordinates()
        self.detJw, Jinv = _kernels.cell_geometry(coords, dN, self.weights)
        #: (n_cells, nq, d, d) float64 ``d xi / d x`` at the quadrature points: a read-only view of
        #: one matrix per cell where every cell's map is affine (the structured boxes)
        self.Jinv = _uniform_along(Jinv, axis=1)
        #: (n_cells, nq, d + 1) float64 pressure basis at the quadrature points: a read-only
        #: view of one table where every cell's is the same (cells whose map is affine and
        #: diagonal: the P1disc frame is then the reference coordinates)
        self.psi = _uniform_along(self.Q.element.tabulate(self.xq, self.Q.centre[:, None, :],
                                                          self.Q.scale[:, None, :]), axis=0)
        self.batch_size = batch_size or (4096 if d == 2 else 512)
        self._build_pattern()

    @property
    def xq(self) -> np.ndarray:
        """The quadrature points in physical coordinates, (n_cells, nq, d) float64, computed on
        each access (a body force's load and the volume force's set-up read them; held, they
        were 650 bytes per cell)."""
        return self.mesh.map_to_physical(self.points)

    @staticmethod
    def estimate_dofs(mesh: StructuredMesh) -> int:
        """Number of unknowns (velocity + pressure) a FlowSpace on ``mesh`` would have."""
        return FlowSpace.count_dofs(mesh.shape, mesh.periodic)

    @staticmethod
    def count_dofs(shape, periodic=None) -> int:
        """Number of unknowns of a FlowSpace on a mesh of ``shape`` cells (``periodic`` axes), the
        mesh not made (Python integers: no overflow, however large)."""
        periodic = periodic or (False,) * len(shape)
        nodes = math.prod(2 * int(n) if p else 2 * int(n) + 1 for n, p in zip(shape, periodic))
        return len(shape) * nodes + (len(shape) + 1) * math.prod(int(n) for n in shape)

    # -- sparsity -----------------------------------------------------------------------------
    def _build_pattern(self):
        cd = self.V.cell_dofs
        self.indptr, self.indices = _kernels.scalar_pattern(cd, self.n_v, 4 * numba_threads())
        self.nnz = int(self.indptr[-1])
        if np.diff(self.indptr).max() > 256:
            raise ValueError("FlowSpace: a pattern row longer than 256 entries")
        #: (n_cells, nl, nl) uint8: where the pair (a, b) of cell c sits within the scalar
        #: pattern's row of its node a (entry ``indptr[cell_dofs[c, a]] + offsets[c, a, b]``)
        self.offsets = _kernels.pattern_offsets(cd, self.indptr, self.indices)

    @cached_property
    def coupled_pattern(self) -> tuple[np.ndarray, np.ndarray]:
        """CSR ``(indptr, indices)`` of the ``(d n_v) x (d n_v)`` coupled velocity block."""
        d, n = self.dim, self.n_v
        lengths = np.diff(self.indptr)
        indptr = np.zeros(d * n + 1, dtype=np.int64)
        indptr[1:] = np.cumsum(np.tile(d * lengths, d))
        row_of = np.repeat(np.arange(n), lengths)
        within = np.arange(self.nnz) - self.indptr[row_of]
        block = np.empty(d * self.nnz, dtype=np.int32)
        for k in range(d):
            block[d * self.indptr[row_of] + k * lengths[row_of] + within] = self.indices + k * n
        indices = np.tile(block, d)
        return indptr, indices

    @cached_property
    def local_rank(self) -> np.ndarray:
        """Position of each local node among its cell's DOFs in ascending order (the column
        order of a ``B^T`` row): (n_cells, nl) int64."""
        order = np.argsort(self.V.cell_dofs, axis=1)
        rank = np.empty_like(order)
        np.put_along_axis(rank, order, np.arange(order.shape[1])[None, :], axis=1)
        return rank

    @cached_property
    def node_cell_ranks(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The cells of every Q2 node and the node's place in each: ``(ptr (n_v + 1,) int64,
        cells int32, ranks uint8)``, node ``a`` in the cells ``cells[ptr[a]:ptr[a + 1]]``
        (ascending) at the positions ``ranks[ptr[a]:ptr[a + 1]]`` of :attr:`local_rank`. What
        reads the gradient ``B`` from the divergence cell by cell needs it (its row of node
        ``a``, component ``i``, has the columns ``c (d + 1) + m`` of those cells)."""
        flat = self.V.cell_dofs.ravel()
        order = np.argsort(flat, kind="stable")
        ptr = np.zeros(self.n_v + 1, dtype=np.int64)
        np.cumsum(np.bincount(flat, minlength=self.n_v), out=ptr[1:])
        cells = (order // self.V.cell_dofs.shape[1]).astype(np.int32)
        return ptr, cells, self.local_rank.ravel()[order].astype(np.uint8)

    @cached_property
    def node_cells(self) -> sp.csr_matrix:
        """Incidence of Q2 nodes and cells, (n_v, n_cells) CSR: row ``a`` lists the cells that
        hold node ``a``, ascending (the arrays of :attr:`node_cell_ranks`)."""
        ptr, cells, _ = self.node_cell_ranks
        return sp.csr_matrix((np.ones(cells.size, dtype=np.int8), cells, ptr),
                             shape=(self.n_v, self.mesh.n_cells))

    @cached_property
    def batches(self) -> list[np.ndarray]:
        """Cell batches for assembly, each (n_groups, length) int64, padded with -1.

        The slabs of one colour are split into ``n_groups`` contiguous groups with about equal
        numbers of cells, :data:`GROUPS_PER_THREAD` times the most Numba threads
        (``fbmflow._jit.max_threads``: the groups do not change with the threads in use, and
        fewer threads than the most still share them evenly); row ``g`` of a batch is the next
        piece of group ``g``'s cell sequence. Rows never share a DOF, so kernels run the rows in
        parallel and each row sequentially, in lexicographic order, which keeps the matrix rows
        being written in cache.
        """
        return self._colour_batches(max(1, self.batch_size // (GROUPS_PER_THREAD * max_threads())))

    @cached_property
    def colour_groups(self) -> list[np.ndarray]:
        """The cells of every colour in one batch (as :attr:`batches`, unlimited length): for
        kernels that need no work array per batch (matrix-free products), one parallel loop per
        colour."""
        return self._colour_batches(None)

    def cell_groups(self, keep: np.ndarray) -> list[np.ndarray]:
        """The cells in ``keep`` (n_cells,) bool as :attr:`colour_groups`: one batch per colour
        that has any, its slabs' kept cells split between the groups by their number (a particle's
        neighbourhood, a few slabs, is shared by every thread, not left to the one whose slabs
        hold it)."""
        return self._colour_batches(None, keep)

    def _colour_batches(self, length: int | None, keep: np.ndarray | None = None) -> list[np.ndarray]:
        n_groups = GROUPS_PER_THREAD * max_threads()
        out = []
        for slabs in self.mesh.cell_colours():
            if keep is not None:
                slabs = [s[keep[s]] for s in slabs if keep[s].any()]
                if not slabs:
                    continue
            seqs = [np.concatenate(part) for part in _balanced_pieces(slabs, n_groups)]
            longest = max(len(q) for q in seqs)
            step = longest if length is None else length
            for start in range(0, longest, step):
                batch = np.full((len(seqs), step), -1, dtype=np.int64)
                for g, q in enumerate(seqs):
                    piece = q[start:start + step]
                    batch[g, :len(piece)] = piece
                out.append(batch)
        return out

    # -- reference tables (local matrix = coefficients @ table) --------------------------------
    @cached_property
    def table_mass(self) -> np.ndarray:
        """``phi_a phi_b`` per point: (nq, nl * nl)."""
        return np.einsum("qa,qb->qab", self.phi, self.phi).reshape(self.phi.shape[0], -1)

    @cached_property
    def table_mass_upper(self) -> tuple[np.ndarray, np.ndarray]:
        """Upper triangle of the symmetric mass table and the map ``(a, b) -> column``.

        Returns table (nq, nl (nl + 1) / 2) float64 and sym (nl, nl) int64.
        """
        nl = self.phi.shape[1]
        ia, ib = np.triu_indices(nl)
        sym = np.empty((nl, nl), dtype=np.int64)
        sym[ia, ib] = np.arange(ia.size)
        sym[ib, ia] = np.arange(ia.size)
        return np.ascontiguousarray(self.phi[:, ia] * self.phi[:, ib]), sym

    @cached_property
    def table_convection(self) -> np.ndarray:
        """``phi_a dphi_b/dxi_l``, rows ``(q, l)``: (nq * d, nl * nl)."""
        t = np.einsum("qa,qbl->qlab", self.phi, self.dphi)
        return t.reshape(t.shape[0] * t.shape[1], -1)

    @cached_property
    def table_mass_laplace(self) -> np.ndarray:
        """The mass table's rows, then the Laplacian's ``dphi_a/dxi_l dphi_b/dxi_m`` with the
        symmetric pairs folded (``l < m``: the ``(l, m)`` and ``(m, l)`` terms summed), rows
        ``q``, then ``(q, l <= m)``: (nq (1 + d (d + 1) / 2), nl * nl)."""
        d = self.dphi.shape[2]
        full = np.einsum("qal,qbm->qlmab", self.dphi, self.dphi)
        rows = [full[:, k, m] + (full[:, m, k] if m != k else 0.0) for k in range(d) for m in range(k, d)]
        folded = np.stack(rows, axis=1)  # (nq, pairs, nl, nl)
        return np.vstack([self.table_mass, folded.reshape(folded.shape[0] * folded.shape[1], -1)])

    @cached_property
    def cell_axes(self) -> np.ndarray | None:
        """Where every cell's map is affine and axis-aligned (a box or rectilinear mesh: ``d xi /
        d x`` one diagonal matrix per cell), per cell ``det J`` and ``det J (d xi_l / d x_l)^2``
        for every axis ``l``: (n_cells, 1 + d) float64, the cell's weights of the rows of
        :attr:`table_mass_laplace_axes`; else None."""
        J = self.Jinv
        if J.shape[1] > 1 and J.strides[1] != 0:  # not one matrix per cell: not affine
            return None
        J = J[:, 0]
        diagonal = np.einsum("cll->cl", J)
        size = np.abs(diagonal).sum(axis=1)
        if (np.abs(J).sum(axis=(1, 2)) - size > 1e-13 * size).any():  # a cell's axes turned
            return None
        det = self.detJw[:, 0] / self.weights[0]
        return np.column_stack([det, det[:, None] * diagonal**2])

    @cached_property
    def table_mass_laplace_axes(self) -> np.ndarray:
        """:attr:`table_mass_laplace` summed over the points for a cell of :attr:`cell_axes`
        (``det J`` the same at every point, the Laplacian's pairs ``l != m`` zero): the mass
        table's rows weighted, then for every axis ``l`` the Laplacian's ``(l, l)`` rows
        weighted, (1 + d, nl * nl). The local ``alpha M + beta L`` of such a cell is its
        :attr:`cell_axes` row, the first entry times ``alpha`` and the others ``beta``, times
        this table: ``1 + d`` products per entry instead of ``nq (1 + d (d + 1) / 2)``."""
        d, w = self.dim, self.weights
        nq, pairs = w.size, d * (d + 1) // 2
        table = self.table_mass_laplace
        diagonal = [k for k, (a, b) in enumerate((a, b) for a in range(d) for b in range(a, d)) if a == b]
        laplace = table[nq:].reshape(nq, pairs, -1)
        return np.vstack([w @ table[:nq]] + [w @ laplace[:, k] for k in diagonal])

    @cached_property
    def table_mass_laplace_cells(self) -> np.ndarray:
        """The mass and Laplace table of this space's cells: :attr:`table_mass_laplace_axes`
        where :attr:`cell_axes` are there, else :attr:`table_mass_laplace`."""
        return self.table_mass_laplace_axes if self.cell_axes is not None else self.table_mass_laplace

    @cached_property
    def table_convection_mass_laplace(self) -> np.ndarray:
        """:attr:`table_convection`'s rows, then :attr:`table_mass_laplace_cells`': the local
        ``s N + alpha M + beta L`` from one product."""
        return np.vstack([self.table_convection, self.table_mass_laplace_cells])

    # -- helpers ------------------------------------------------------------------------------
    def free_node_components(self, free: np.ndarray) -> np.ndarray:
        """Labels (n_v,) int64 of the connected components of the ``free`` (n_v,) bool velocity
        nodes, two nodes joined where they share a cell (the smallest node index of the
        component); -1 where not free."""
        return _kernels.free_components(self.V.cell_dofs, np.asarray(free, dtype=np.bool_))

    def scalar_matrix(self, data: np.ndarray) -> sp.csr_matrix:
        """CSR matrix on the scalar Q2 pattern with the given data (no copy)."""
        return sp.csr_matrix((data, self.indices, self.indptr), shape=(self.n_v, self.n_v))

    @cached_property
    def block_diagonal_pattern(self) -> tuple[np.ndarray, np.ndarray]:
        """CSR ``(indptr, indices)`` of a velocity block with ``dim`` equal diagonal blocks only
        (Stokes, Picard/Oseen): row ``(i, r)`` holds component ``i``'s columns, entry at
        ``i nnz + indptr[r] + off``. A third of the coupled pattern in 3D."""
        d, n = self.dim, self.n_v
        indptr = np.concatenate([[0]] + [i * self.nnz + self.indptr[1:] for i in range(d)])
        indices = np.concatenate([self.indices + i * n for i in range(d)]).astype(np.int32)
        return indptr, indices

    def coupled_matrix(self, data: np.ndarray) -> sp.csr_matrix:
        """CSR velocity block with the given data (no copy): the coupled pattern when
        ``data.size == dim**2 nnz``, the block-diagonal one when ``data.size == dim nnz``."""
        if data.size == self.dim * self.nnz and self.dim > 1:
            indptr, indices = self.block_diagonal_pattern
        else:
            indptr, indices = self.coupled_pattern
        return sp.csr_matrix((data, indices, indptr), shape=(self.n_u, self.n_u))

    def __repr__(self) -> str:
        return (f"FlowSpace(dim={self.dim}, cells={self.mesh.n_cells}, n_v={self.n_v}, "
                f"n_p={self.n_p}, n_dofs={self.n_dofs})")


def _balanced_pieces(slabs: list[np.ndarray], n: int) -> list[list[np.ndarray]]:
    """``slabs`` cut into at most ``n`` non-empty runs of consecutive slabs with about equal
    numbers of cells (a run ends at the first slab where the running count reaches its share)."""
    counts = np.cumsum([s.size for s in slabs])
    ends = np.searchsorted(counts, counts[-1] * np.arange(1, n) / n) + 1
    bounds = np.unique(np.concatenate([[0], np.minimum(ends, len(slabs)), [len(slabs)]]))
    return [slabs[a:b] for a, b in zip(bounds[:-1], bounds[1:])]


def _uniform_along(a: np.ndarray, axis: int, rtol: float = 1e-13) -> np.ndarray:
    """``a`` itself, or, where its slices along ``axis`` all equal the first one to ``rtol``
    of ``a``'s largest entry, a read-only broadcast view of that slice with ``a``'s shape (the
    memory of one slice: the cell geometry of a structured box mesh is 27 times smaller)."""
    first = np.take(a, [0], axis=axis)
    if a.size == 0 or np.abs(a - first).max() > rtol * np.abs(a).max():
        return a
    return np.broadcast_to(first, a.shape)  # np.take made ``first`` a copy
