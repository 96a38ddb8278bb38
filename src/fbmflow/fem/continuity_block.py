"""The continuity block of a saddle-point system, stored as the level's divergence and the rows
that differ from it.

A system's continuity rows ``D`` (n_p, n_u) are the discrete divergence ``B^T`` of the level
with a few rows changed: the columns of fixed velocities zeroed (walls, a particle's nodes), the
rows of cut cells integrated outside the particle
(:class:`~fbmflow.fem.constraints.ContinuityRows`), the rows of continued pressures moved
(:class:`~fbmflow.fem.constraints.PressureExtension`), the rows of orphaned pressure modes
dropped. As a CSR matrix ``D`` is a copy of ``B^T``: 129 bytes per unknown at ten Cate level 1
(86 of values, 43 of column indices, the pressure extension's rows leaving the divergence's
pattern), 2 GB at level 3. :class:`ContinuityBlock` keeps ``B^T`` (the level's, shared, never
written) and only the changed rows; ten Cate's change under a tenth of them (the cells at the
walls and at the sphere).

It offers what the solvers use of ``D``: products with vectors and matrices (both sides), rows,
the number of stored entries and :meth:`ContinuityBlock.tocsr` for the direct solvers and the
set-up of small levels. The changes are applied by :meth:`ContinuityBlock.splice` and
:meth:`ContinuityBlock.zero_columns`, each returning a new block; every row keeps the entries a
CSR matrix changed the same way keeps (explicit zeros included), so that
:meth:`ContinuityBlock.tocsr` is that matrix, entry for entry.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from . import _kernels
from .sorted_sets import union_sorted


def splice_rows(M: sp.csr_matrix, rows: np.ndarray, R: sp.csr_matrix) -> sp.csr_matrix:
    """``M`` (CSR, sorted indices) with its rows ``rows`` (k,) int64, ascending, replaced by those
    of ``R`` (k, n): on a copy of ``M``'s values and ``M``'s own index arrays where ``R``'s
    entries lie in ``M``'s pattern, else a new matrix. Either way every other row keeps its
    entries, explicit zeros included (a SciPy sum drops them), so that the divergence's rows
    stay in its cell-local pattern. Sorted indices."""
    R = sp.csr_matrix(R)
    R.sum_duplicates()
    R.sort_indices()
    data = M.data.copy()
    if M.has_sorted_indices and _kernels.replace_rows(M.indptr, M.indices, data, rows, R.indptr, R.indices,
                                                      R.data):
        return sp.csr_matrix((data, M.indices, M.indptr), shape=M.shape)
    counts = np.diff(M.indptr)
    keep = np.ones(M.shape[0], dtype=bool)
    keep[rows] = False
    old = np.repeat(keep, counts)
    counts[rows] = np.diff(R.indptr)
    indptr = np.zeros(M.shape[0] + 1, dtype=np.int64)
    np.cumsum(counts, out=indptr[1:])
    new = np.repeat(keep, counts)
    indices = np.empty(indptr[-1], dtype=M.indices.dtype)
    values = np.empty(indptr[-1])
    indices[new], values[new] = M.indices[old], M.data[old]
    indices[~new], values[~new] = R.indices, R.data
    return sp.csr_matrix((values, indices, indptr), shape=M.shape)


def zero_columns(M: sp.csr_matrix, columns: np.ndarray | None) -> sp.csr_matrix:
    """Copy of the CSR matrix ``M`` with the given columns zeroed (its pattern kept); ``M``
    itself when there are none."""
    if columns is None or len(columns) == 0:
        return M
    mask = np.zeros(M.shape[1], dtype=bool)
    mask[columns] = True
    return sp.csr_matrix((np.where(mask[M.indices], 0.0, M.data), M.indices, M.indptr), shape=M.shape)


class ContinuityBlock:
    """``B^T`` (n_p, n_u) with the rows ``dofs`` those of ``rows``.

    Parameters
    ----------
    base : (n_p, n_u) CSR float64, the same number of entries in every row, sorted indices
        (the divergence in its cell-local pattern, :func:`~fbmflow.fem.assembly.assemble_divergence`);
        kept, never written
    dofs : (n_o,) int64, sorted, or None: the changed rows
    rows : (n_o, n_u) CSR float64, sorted indices, or None: their entries
    """

    ndim = 2
    dtype = np.dtype(np.float64)
    format = "continuity"

    def __init__(self, base: sp.csr_matrix, dofs: np.ndarray | None = None,
                 rows: sp.csr_matrix | None = None):
        n_p, n_u = base.shape
        width = int(base.indptr[1] - base.indptr[0]) if n_p else 0
        if base.nnz != n_p * width or not base.has_sorted_indices:
            raise ValueError("ContinuityBlock: the base needs the same number of entries in every row, "
                             "sorted indices")
        self.base, self.width, self.shape = base, width, (n_p, n_u)
        self.dofs = np.zeros(0, dtype=np.int64) if dofs is None else np.asarray(dofs, dtype=np.int64)
        self.rows = sp.csr_matrix((self.dofs.size, n_u)) if rows is None else rows
        if self.rows.shape != (self.dofs.size, n_u):
            raise ValueError(f"ContinuityBlock: {self.dofs.size} changed rows, their matrix has shape "
                             f"{self.rows.shape}")
        #: for every row its position in ``rows``, -1 where it is ``base``'s: (n_p,) int32
        self.position = np.full(n_p, -1, dtype=np.int32)
        self.position[self.dofs] = np.arange(self.dofs.size, dtype=np.int32)

    @property
    def nnz(self) -> int:
        """Entries of the assembled block."""
        return int(self.base.nnz - self.width * self.dofs.size + self.rows.nnz)

    def __getitem__(self, rows) -> sp.csr_matrix:
        """The rows ``rows`` (k,) int (or a boolean mask) of the block, CSR (k, n_u), sorted
        indices."""
        rows = np.asarray(rows)
        return self._rows(np.flatnonzero(rows) if rows.dtype == bool else rows.astype(np.int64))

    def _rows(self, rows: np.ndarray, zero: np.ndarray | None = None) -> sp.csr_matrix:
        """The rows ``rows`` (k,) int64 as :meth:`__getitem__` gives them, the values in the
        columns where ``zero`` (n_u,) bool is set written as zeros (the pattern kept); gathered
        by :func:`~fbmflow.fem._kernels.continuity_rows`, rows in parallel."""
        pos = self.position[rows]
        own = pos >= 0
        lengths = np.full(rows.size, self.width, dtype=np.int64)
        lengths[own] = np.diff(self.rows.indptr)[pos[own]]
        indptr = np.zeros(rows.size + 1, dtype=np.int64)
        np.cumsum(lengths, out=indptr[1:])
        indices = np.empty(indptr[-1], dtype=self.base.indices.dtype)
        values = np.empty(indptr[-1])
        R = self.rows
        _kernels.continuity_rows(rows, self.position, self.width, self.base.indices, self.base.data, R.indptr,
                                 R.indices, R.data, np.zeros(0, dtype=np.bool_) if zero is None else zero,
                                 indptr, indices, values)
        return sp.csr_matrix((values, indices, indptr), shape=(rows.size, self.shape[1]))

    def tocsr(self) -> sp.csr_matrix:
        """The assembled block (n_p, n_u) CSR, sorted indices: ``base`` itself where no row
        changed, else a copy (for direct solvers and small levels), of the values only (sharing
        ``base``'s index arrays) where every changed row kept its pattern."""
        if self.dofs.size == 0:
            return self.base
        R, w = self.rows, self.width
        if R.nnz == w * self.dofs.size and np.array_equal(
                R.indices, self.base.indices.reshape(-1, w)[self.dofs].ravel()):
            values = self.base.data.copy()
            values.reshape(-1, w)[self.dofs] = R.data.reshape(-1, w)
            return sp.csr_matrix((values, self.base.indices, self.base.indptr), shape=self.shape)
        return self[np.arange(self.shape[0])]

    def changed_rows(self) -> sp.csr_matrix:
        """The changed rows in place, (n_p, n_u) CSR, the other rows empty (sharing ``rows``'
        entries)."""
        lengths = np.zeros(self.shape[0], dtype=np.int64)
        lengths[self.dofs] = np.diff(self.rows.indptr)
        indptr = np.zeros(self.shape[0] + 1, dtype=np.int64)
        np.cumsum(lengths, out=indptr[1:])
        return sp.csr_matrix((self.rows.data, self.rows.indices, indptr), shape=self.shape)

    def __matmul__(self, v):
        """Product with a vector (n_u,) (float64 result, rows in parallel), a dense matrix
        (n_u, k) (dense, column by column) or a sparse one (CSR)."""
        if sp.issparse(v):
            out = self._base_times_sparse(sp.csr_matrix(v))
            keep = np.ones(self.shape[0])
            keep[self.dofs] = 0.0
            return (sp.diags(keep) @ out + self.changed_rows() @ v).tocsr()
        v = np.asarray(v, dtype=np.float64)
        if v.ndim == 2:  # column by column, each in parallel
            return np.column_stack([self @ v[:, k] for k in range(v.shape[1])]).reshape(self.shape[0], -1)
        out = np.empty(self.shape[0])
        _kernels.uniform_rows_apply(self.base.indices, self.base.data, self.width, np.ascontiguousarray(v),
                                    out)
        R = self.rows
        _kernels.override_rows(self.dofs, R.indptr, R.indices, R.data, v, out)
        return out

    def _base_times_sparse(self, v: sp.csr_matrix) -> sp.csr_matrix:
        """``base @ v`` (n_p, k) CSR for a sparse ``v`` (n_u, k) from the rows of ``base`` that
        reach ``v``'s non-zero rows only (a particle's liftings: the cells about it, where SciPy's
        product runs through every row: at ten Cate level 2, 23 M entries for each product);
        the same sums in the same order."""
        reach = np.zeros(self.shape[1], dtype=np.bool_)
        reach[np.diff(v.indptr) > 0] = True
        rows = np.flatnonzero(_kernels.rows_touching(self.base.indices, self.shape[0], self.width, reach))
        part = sp.csr_matrix(self.base[rows] @ v)
        lengths = np.zeros(self.shape[0], dtype=np.int64)
        lengths[rows] = np.diff(part.indptr)
        indptr = np.zeros(self.shape[0] + 1, dtype=np.int64)
        np.cumsum(lengths, out=indptr[1:])
        return sp.csr_matrix((part.data, part.indices, indptr), shape=(self.shape[0], v.shape[1]))

    def __rmatmul__(self, S) -> sp.csr_matrix:
        """``S @ D`` for a sparse ``S`` (k, n_p) with few non-zero columns, CSR: the same sums in
        the same order as the product with :meth:`tocsr` (``S``'s rows taken in column order)."""
        S = sp.csr_matrix(S, copy=True)
        S.sort_indices()
        columns = np.unique(S.indices)
        S = sp.csr_matrix((S.data, np.searchsorted(columns, S.indices), S.indptr),
                          shape=(S.shape[0], columns.size))
        return (S @ self[columns]).tocsr()

    def splice(self, rows: np.ndarray, R: sp.csr_matrix) -> "ContinuityBlock":
        """The block with its rows ``rows`` (k,) int64, ascending, replaced by those of ``R``
        (k, n_u), as :func:`splice_rows` replaces them in the assembled block (in that row's
        pattern where all of ``R``'s entries fit the rows' patterns, else ``R``'s own)."""
        rows = np.asarray(rows, dtype=np.int64)
        new = splice_rows(self[rows], np.arange(rows.size), R)
        return self._with(rows, new)

    def zero_columns(self, columns: np.ndarray | None) -> "ContinuityBlock":
        """The block with the given columns zeroed (the pattern kept), as :func:`zero_columns`;
        the block itself when there are none."""
        if columns is None or len(columns) == 0:
            return self
        mask = np.zeros(self.shape[1], dtype=bool)
        mask[columns] = True
        touched = _kernels.rows_touching(self.base.indices, self.shape[0], self.width, mask)
        touched[self.dofs] = True  # the changed rows, whatever their pattern
        rows = np.flatnonzero(touched)
        return self._with(rows, self._rows(rows, mask))

    def _with(self, rows: np.ndarray, R: sp.csr_matrix) -> "ContinuityBlock":
        """The block with the rows ``rows`` (ascending) those of ``R`` (CSR, sorted indices): the
        changed rows, old and new, gathered into one CSR matrix by
        :func:`~fbmflow.fem._kernels.stack_rows`."""
        R = sp.csr_matrix(R)
        dofs = union_sorted(self.dofs, rows)
        second = np.zeros(dofs.size, dtype=np.bool_)  # the row from R, else from self.rows
        pos = np.zeros(dofs.size, dtype=np.int64)  # ... its row there
        pos[np.searchsorted(dofs, self.dofs)] = np.arange(self.dofs.size)
        new = np.searchsorted(dofs, rows)
        second[new], pos[new] = True, np.arange(rows.size)
        old = self.rows
        lengths = np.empty(dofs.size, dtype=np.int64)
        lengths[~second] = np.diff(old.indptr)[pos[~second]]
        lengths[second] = np.diff(R.indptr)[pos[second]]
        indptr = np.zeros(dofs.size + 1, dtype=np.int64)
        np.cumsum(lengths, out=indptr[1:])
        indices = np.empty(indptr[-1], dtype=self.base.indices.dtype)
        values = np.empty(indptr[-1])
        _kernels.stack_rows(second, pos, old.indptr, old.indices, old.data, R.indptr, R.indices, R.data,
                            indptr, indices, values)
        return ContinuityBlock(self.base, dofs, sp.csr_matrix((values, indices, indptr),
                                                              shape=(dofs.size, self.shape[1])))

    def __repr__(self) -> str:
        return f"ContinuityBlock(n_p={self.shape[0]}, n_u={self.shape[1]}, changed rows={self.dofs.size})"
