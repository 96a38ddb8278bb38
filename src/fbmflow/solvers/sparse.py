"""Sparse matrix-vector products that use every thread.

SciPy's ``csr_matrix @ x`` runs on one thread; in a multigrid cycle the residual and the
transfers between levels are such products (``csr_matvec`` took 1.9 of 21.1 s of a ten Cate
level-1 step at 16 threads, the rest of the cycle running on all of them). :func:`matvec`
splits the rows of a large CSR matrix among Numba's threads and leaves a small one to SciPy:
a parallel region costs a barrier, which another busy process can stretch to a scheduler tick
(measured: a coloured apply went from 6 to 30-55 ms beside another job), more than the product
of a coarse level's matrix takes.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .._jit import njit, prange
from ..fem.continuity_block import ContinuityBlock

#: matrices with at least this many stored entries are multiplied in parallel (about 1 ms of work
#: on one thread)
PARALLEL_NNZ = 200_000


@njit(parallel=True)
def _csr_matvec(indptr, indices, data, x, out):
    """``out = M x`` for the CSR arrays of ``M``, rows in parallel; each row's sum in storage
    order, so the result does not depend on the number of threads (and equals SciPy's)."""
    for i in prange(out.shape[0]):
        s = 0.0
        for j in range(indptr[i], indptr[i + 1]):
            s += data[j] * x[indices[j]]
        out[i] = s


def matvec(M: sp.spmatrix, x: np.ndarray) -> np.ndarray:
    """``M @ x`` for a sparse ``M (m, n)`` and ``x (n,)`` float64: rows in parallel for a CSR
    matrix of float64 with at least :data:`PARALLEL_NNZ` entries, SciPy's product otherwise.
    Returns (m,) float64."""
    if getattr(M, "format", None) != "csr" or M.nnz < PARALLEL_NNZ or M.dtype != np.float64 or x.ndim != 1:
        return M @ x
    out = np.empty(M.shape[0])
    _csr_matvec(M.indptr, M.indices, M.data, np.ascontiguousarray(x, dtype=np.float64), out)
    return out


#: row chunks of a transposed product (:func:`rmatvec`), each summed into a vector of its own,
#: the vectors then added in order: the result does not depend on the number of threads
TRANSPOSED_CHUNKS = 8


@njit(parallel=True)
def _csr_rmatvec(indptr, indices, data, x, parts):
    """``parts[t] = M[rows of chunk t]^T x[those rows]`` for the CSR arrays of ``M (m, n)``, the
    ``k`` chunks of rows ``t m // k .. (t + 1) m // k`` in parallel; parts (k, n) float64."""
    k = parts.shape[0]
    m = indptr.shape[0] - 1
    for t in prange(k):
        part = parts[t]
        part[:] = 0.0
        for i in range(t * m // k, (t + 1) * m // k):
            xi = x[i]
            for j in range(indptr[i], indptr[i + 1]):
                part[indices[j]] += data[j] * xi


def rmatvec(M: sp.csr_matrix, x: np.ndarray) -> np.ndarray:
    """``M^T x`` for a CSR ``M (m, n)`` and ``x (m,)`` float64, without the transpose stored: rows
    in :data:`TRANSPOSED_CHUNKS` chunks in parallel, each into its own (n,) vector (for a
    restriction, ``n`` a coarse level's size), for a float64 matrix of at least
    :data:`PARALLEL_NNZ` entries; SciPy's product with the zero-copy transpose otherwise.
    Returns (n,) float64."""
    if getattr(M, "format", None) != "csr" or M.nnz < PARALLEL_NNZ or M.dtype != np.float64:
        return M.T @ x
    parts = np.empty((TRANSPOSED_CHUNKS, M.shape[1]))
    _csr_rmatvec(M.indptr, M.indices, M.data, np.ascontiguousarray(x, dtype=np.float64), parts)
    return parts.sum(axis=0)


@njit(parallel=True)
def _cell_rows_transposed(cells, npl, indptr, indices, data, x, out):
    """``out += M^T x`` for the CSR arrays of ``M (n_cells npl, n)`` whose rows ``c npl .. c npl +
    npl - 1`` reach only cell ``c``'s unknowns; ``cells (n_groups, length)`` one colour's cells
    (no two share an unknown, -1 = padding), the groups in parallel."""
    n_groups, length = cells.shape
    for g in prange(n_groups):
        for j in range(length):
            c = cells[g, j]
            if c < 0:
                continue
            for r in range(c * npl, (c + 1) * npl):
                xr = x[r]
                for k in range(indptr[r], indptr[r + 1]):
                    out[indices[k]] += data[k] * xr


def cell_transposed_matvec(M: sp.csr_matrix, x: np.ndarray, colours: list[np.ndarray],
                           npl: int) -> np.ndarray:
    """``M^T x`` for a CSR ``M (n_cells npl, n)`` whose ``npl`` rows per cell reach only that
    cell's unknowns (the discrete divergence ``B^T``: the gradient ``B p`` without a matrix of its
    own), ``x (n_cells npl,)``; ``colours``: the cells colour by colour, as
    :attr:`~fbmflow.fem.space.FlowSpace.colour_groups`. Every entry of the result sums its terms
    colour by colour, so it does not depend on the number of threads. Returns (n,) float64."""
    out = np.zeros(M.shape[1])
    x = np.ascontiguousarray(x, dtype=np.float64)
    for cells in colours:
        _cell_rows_transposed(cells, npl, M.indptr, M.indices, M.data, x, out)
    return out


class DivergenceProducts:
    """The gradient ``B p`` and the continuity rows ``B^T u`` of a level's divergence ``BT (n_p,
    n_u)`` CSR in the cell-local pattern (:func:`~fbmflow.fem.assembly.assemble_divergence`:
    ``dim + 1`` rows per cell, in cell order) on ``space``, host arrays in and out, on the CPU's
    threads: the gradient by :func:`cell_transposed_matvec` (the space's cells in colours), the
    continuity rows by :class:`~fbmflow.fem.continuity_block.ContinuityBlock`'s product."""

    def __init__(self, space, BT: sp.csr_matrix):
        self.space, self.BT = space, BT

    def gradient(self, p: np.ndarray) -> np.ndarray:
        """``B p`` for pressures ``p (n_p,)`` -> (n_u,) float64."""
        return cell_transposed_matvec(self.BT, p, self.space.colour_groups, self.space.dim + 1)

    def continuity(self, u: np.ndarray) -> np.ndarray:
        """``B^T u`` for velocities ``u (n_u,)`` -> (n_p,) float64."""
        return ContinuityBlock(self.BT) @ u
