"""The velocity block of a Picard (Oseen) linearisation, stored once per scalar.

Without the Newton term every velocity component sees the same scalar operator

    S = m rho M + a (mu L + rho N(u)),      A = diag(S, ..., S)      (d blocks),

and only the constrained rows differ: unit rows for fixed values, ``s C`` for the sharp
boundary's row constraints (:class:`~fbmflow.fem.constraints.RowConstraints`). Assembled as a
CSR matrix, ``A`` stores ``d`` copies of ``S`` and their column indices (and, where the row
constraints reach outside the Q2 pattern, a second matrix): at ten Cate level 1 241 MB, 866
bytes per unknown. :class:`VelocityBlock` keeps ``S``'s values once on the space's scalar
pattern and the constrained rows as a small CSR matrix: 139 bytes per unknown there.

It offers what the solvers use of an assembled block: products with vectors and (sparse)
matrices, rows, the diagonal, the nodes whose ``d`` rows are one scalar row (the Vanka
smoother's "regular" nodes) and their scalar rows, and :meth:`VelocityBlock.tocsr` for the direct
solvers.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from . import _kernels
from .sorted_sets import difference_sorted
from .space import FlowSpace

#: blocks with at least this many stored scalar entries are applied in parallel
#: (:data:`fbmflow.solvers.sparse.PARALLEL_NNZ` over ``dim``: the same work as an assembled block's)
PARALLEL_NNZ = 70_000


class VelocityBlock:
    """``diag(S, ..., S)`` (d blocks) with the rows ``fixed`` unit rows and the rows ``rows``
    those of ``matrix``.

    Parameters
    ----------
    space : FlowSpace, the scalar pattern ``(space.indptr, space.indices)``
    data : (space.nnz,) float64, ``S`` on that pattern (kept, not copied)
    fixed : (n_f,) int64, velocity DOFs (component-blocked) with unit rows
    rows : (n_r,) int64 or None, velocity DOFs whose rows are those of ``matrix``
    matrix : (n_r, d n_v) sparse or None, the replacing rows (already scaled)
    """

    ndim = 2
    dtype = np.dtype(np.float64)

    def __init__(self, space: FlowSpace, data: np.ndarray, fixed: np.ndarray, rows: np.ndarray | None = None,
                 matrix: sp.spmatrix | None = None):
        d, n_v = space.dim, space.n_v
        if d not in (2, 3):
            raise ValueError(f"VelocityBlock: dimension {d}; 2 or 3")
        if data.shape != (space.nnz,):
            raise ValueError(f"VelocityBlock: data has shape {data.shape}, the scalar pattern has "
                             f"{space.nnz} entries")
        self.space, self.data = space, data
        self.shape = (d * n_v, d * n_v)
        fixed = np.asarray(fixed, dtype=np.int64)
        rows = np.zeros(0, dtype=np.int64) if rows is None else np.asarray(rows, dtype=np.int64)
        fixed = difference_sorted(fixed, rows)
        parts = [sp.csr_matrix((np.ones(fixed.size), (np.arange(fixed.size), fixed)),
                               shape=(fixed.size, self.shape[1]))]
        if rows.size:
            parts.append(sp.csr_matrix(matrix))
        dofs = np.concatenate([fixed, rows])
        order = np.argsort(dofs, kind="stable")
        if np.any(np.diff(dofs[order]) == 0):
            raise ValueError("VelocityBlock: a DOF is both fixed and row-constrained, or listed twice")
        R = sp.vstack(parts, format="csr")[order]
        R.sum_duplicates()
        R.sort_indices()
        #: the replaced rows: their DOFs (n_o,) int64 sorted, and the rows (n_o, d n_v) CSR
        self.dofs, self.rows = dofs[order], R
        self._pos = np.full(self.shape[0], -1, dtype=np.int32)
        self._pos[self.dofs] = np.arange(self.dofs.size, dtype=np.int32)
        # nodes whose d rows are one scalar row: those without replaced rows, and those whose
        # replaced rows are shifted copies (all components fixed; one stencil for all of them)
        replaced = np.zeros(n_v, dtype=bool)
        replaced[self.dofs % n_v] = True
        nodes = np.flatnonzero(replaced)
        pos = self._pos.reshape(d, n_v)[:, nodes].T.astype(np.int64)
        self.regular = np.ones(n_v, dtype=bool)
        self.regular[nodes] = _kernels.shifted_copies(R.indptr, R.indices, R.data, pos, n_v)

    @property
    def nnz(self) -> int:
        """Entries of the assembled block (``d`` copies of ``S``, the replaced rows' own)."""
        d = self.space.dim
        replaced = self.dofs % self.space.n_v
        return int(d * self.space.nnz - np.diff(self.space.indptr)[replaced].sum() + self.rows.nnz)

    def scalar(self) -> sp.csr_matrix:
        """``S`` (n_v, n_v) CSR, sharing the values and the space's pattern."""
        return self.space.scalar_matrix(self.data)

    def __matmul__(self, v):
        """Product with a vector (d n_v,) (float64 result), a dense matrix (d n_v, k) (dense) or
        a sparse one (CSR)."""
        if sp.issparse(v):
            return self._sparse(sp.csr_matrix(v))
        v = np.asarray(v, dtype=np.float64)
        if v.ndim == 2:
            return np.column_stack([self @ v[:, k] for k in range(v.shape[1])])
        s = self.space
        out = np.empty(self.shape[0])
        apply = _kernels.block_apply if s.nnz >= PARALLEL_NNZ else _kernels.block_apply_serial
        apply(s.indptr, s.indices, self.data, s.dim, np.ascontiguousarray(v), out)
        R = self.rows
        _kernels.override_rows(self.dofs, R.indptr, R.indices, R.data, v, out)
        return out

    def _sparse(self, W: sp.csr_matrix) -> sp.csr_matrix:
        """``self @ W`` from the rows of ``S`` that reach ``W``'s non-zero rows only: the
        pattern is symmetric (nodes that share a cell), so those are the rows of the nodes in
        theirs (a rigid response's liftings, on one particle's nodes: ten Cate level 2, 0.38 s
        of a step on the whole ``S`` otherwise)."""
        s = self.space
        S = self.scalar()
        nodes = np.unique(np.flatnonzero(np.diff(W.indptr)) % s.n_v)
        near = np.unique(S[nodes].indices)
        local = sp.vstack([S[near] @ W[i * s.n_v:(i + 1) * s.n_v] for i in range(s.dim)], format="csr")
        rows = np.concatenate([i * s.n_v + near for i in range(s.dim)])
        out = sp.csr_matrix((np.ones(rows.size), (rows, np.arange(rows.size))),
                            shape=(self.shape[0], rows.size)) @ local
        keep = np.ones(self.shape[0])
        keep[self.dofs] = 0.0
        embed = sp.csr_matrix((np.ones(self.dofs.size), (self.dofs, np.arange(self.dofs.size))),
                              shape=(self.shape[0], self.dofs.size))
        return (sp.diags(keep) @ out + embed @ (self.rows @ W)).tocsr()

    def _gather(self, rows: np.ndarray, dtype=np.float64, shift: bool = True) -> tuple:
        s, R = self.space, self.rows
        ptr = _kernels.gather_lengths(rows, s.indptr, s.n_v, self._pos, R.indptr)
        idx, val = np.empty(ptr[-1], dtype=np.int32), np.empty(ptr[-1], dtype=dtype)
        _kernels.gather_rows(rows, s.indptr, s.indices, self.data, s.n_v, self._pos, R.indptr, R.indices,
                             R.data, shift, ptr, idx, val)
        return ptr, idx, val

    def __getitem__(self, rows) -> sp.csr_matrix:
        """The rows ``rows`` (k,) int (or a boolean mask) of the block, CSR (k, d n_v)."""
        rows = np.asarray(rows)
        rows = np.flatnonzero(rows) if rows.dtype == bool else rows.astype(np.int64)
        ptr, idx, val = self._gather(rows)
        return sp.csr_matrix((val, idx, ptr), shape=(rows.size, self.shape[1]))

    def select(self, keep: np.ndarray) -> sp.csr_matrix:
        """The block with the rows where ``keep`` (d n_v,) bool is False left empty, CSR."""
        ptr, idx, val = _embed(self._gather(np.flatnonzero(keep)), keep)
        return sp.csr_matrix((val, idx, ptr), shape=self.shape)

    def scalar_rows(self, keep: np.ndarray, dtype=np.float64) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """CSR arrays ``(ptr, indices, data)`` (int64, int32, ``dtype``) of the scalar rows (node
        columns) of the regular nodes where ``keep`` (n_v,) bool, the other rows empty: an
        ``(n_v, n_v)`` matrix."""
        if np.any(keep & ~self.regular):
            raise ValueError("VelocityBlock.scalar_rows: an irregular node has no scalar row")
        return _embed(self._gather(np.flatnonzero(keep), dtype, shift=False), keep)

    def parts(self) -> list[tuple[sp.csr_matrix, int]]:
        """The block as CSR parts that cover every stored entry: ``(M, offset)`` places ``M``'s
        rows and columns at ``offset`` (``S`` once per component; the replaced rows, all
        columns, at 0). Entries of ``S`` in replaced rows are listed too."""
        S, n_v = self.scalar(), self.space.n_v
        return [(S, i * n_v) for i in range(self.space.dim)] + [(self.select(self._pos >= 0), 0)]

    def diagonal(self) -> np.ndarray:
        """The diagonal (d n_v,) float64."""
        s = self.space
        rows = np.repeat(np.arange(s.n_v), np.diff(s.indptr))
        diag = np.zeros(s.n_v)
        on = s.indices == rows
        diag[rows[on]] = self.data[on]
        out = np.tile(diag, s.dim)
        out[self.dofs] = self.rows[np.arange(self.dofs.size), self.dofs].A1 if self.dofs.size else 0.0
        return out

    def tocsr(self) -> sp.csr_matrix:
        """The assembled block (d n_v, d n_v) CSR, sorted indices: ``d`` copies of ``S`` on the
        space's block-diagonal pattern with the replaced rows written in (a new pattern where they
        reach outside it, as :meth:`~fbmflow.fem.constraints.RowConstraints.write_rows`). ``d``
        times the memory of this object: for direct solvers and small levels."""
        s, R = self.space, self.rows
        A = s.coupled_matrix(np.tile(self.data, s.dim))
        if _kernels.replace_rows(A.indptr, A.indices, A.data, self.dofs, R.indptr, R.indices, R.data):
            return A
        keep = np.ones(self.shape[0], dtype=bool)
        keep[self.dofs] = False
        A.data[~np.repeat(keep, np.diff(A.indptr))] = 0.0
        out = (A + self.select(~keep)).tocsr()
        out.sort_indices()
        return out

    def __repr__(self) -> str:
        return (f"VelocityBlock(dim={self.space.dim}, n_v={self.space.n_v}, scalar entries={self.space.nnz}, "
                f"replaced rows={self.dofs.size}, irregular nodes={int((~self.regular).sum())})")


def _embed(part: tuple, keep: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """CSR arrays of the rows ``part`` placed at the rows where ``keep`` (n,) bool is True, the
    other rows empty."""
    ptr, idx, val = part
    indptr = np.zeros(keep.size + 1, dtype=np.int64)
    indptr[1:][keep] = np.diff(ptr)
    np.cumsum(indptr, out=indptr)
    return indptr, idx, val
