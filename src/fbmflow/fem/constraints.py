"""Constraints of the discrete problem and their application to the saddle-point operators.

* **Dirichlet** values on velocity DOFs: the constrained rows of the velocity block become unit
  rows and the matching columns of ``B^T`` are zeroed. Newton updates are then zero there; the
  values are set in the first iterate (deal.II step-57 style).
* **Row constraints** ``C u = g`` that replace the momentum equations of some velocity DOFs
  (:class:`RowConstraints`; the sharp fictitious boundary, :mod:`fbmflow.coupling.sharp`, where a
  node inside a particle carries the flow continued through the surface). Their DOFs stay
  unknowns: the continuity equations keep their columns, their rows of the velocity block become
  ``s C`` with a row scale ``s`` of the size of the momentum equations they replace, and they
  carry no pressure gradient. Being linear, they hold after the first Newton update.
* **Continuity rows** of some cells replaced (:class:`ContinuityRows`, e.g. integrated over the
  part of a cut cell outside the particle).
* **Pressure extension**: the pressures of some cells continued from other cells
  (:class:`PressureExtension`).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.sparse as sp

from . import _kernels
from .continuity_block import ContinuityBlock
from .sorted_sets import among_sorted


@dataclass(frozen=True)
class RowConstraints:
    """Linear constraints ``(C u)_k = g_k``, one per constrained velocity DOF.

    Attributes
    ----------
    dofs : (n_r,) int64   constrained entries of the component-blocked velocity vector, sorted
    matrix : (n_r, n_u) CSR float64   ``C``; row ``k`` belongs to ``dofs[k]``
    values : (n_r,) float64   ``g``
    """

    dofs: np.ndarray
    matrix: sp.csr_matrix
    values: np.ndarray

    def residual(self, u: np.ndarray) -> np.ndarray:
        """``C u - g`` for the velocity ``u (n_u,)``, (n_r,)."""
        return self.matrix @ u - self.values

    def select(self, keep: np.ndarray) -> "RowConstraints":
        """The constraints of the DOFs where ``keep (n_r,) bool`` is True."""
        return RowConstraints(self.dofs[keep], self.matrix[keep], self.values[keep])

    def same_matrix(self, other: "RowConstraints | None") -> bool:
        """True when ``other`` constrains the same DOFs with the same ``C``."""
        return (other is not None and np.array_equal(self.dofs, other.dofs)
                and self.matrix.shape == other.matrix.shape and (self.matrix != other.matrix).nnz == 0)

    def write_rows(self, A: sp.csr_matrix, scale: np.ndarray) -> sp.csr_matrix:
        """``A`` (sorted indices) with rows ``dofs`` replaced by ``scale[:, None] * C``
        (``scale (n_r,)``): in place when ``C``'s entries lie in ``A``'s pattern, else a new CSR
        matrix (``A``'s own rows then zeroed)."""
        R = sp.csr_matrix(sp.diags(scale) @ self.matrix)
        R.sum_duplicates()
        R.sort_indices()
        if _kernels.replace_rows(A.indptr, A.indices, A.data, self.dofs, R.indptr, R.indices, R.data):
            return A
        counts = np.zeros(A.shape[0], dtype=np.int64)
        counts[self.dofs] = np.diff(R.indptr)
        indptr = np.zeros(A.shape[0] + 1, dtype=np.int64)
        np.cumsum(counts, out=indptr[1:])
        in_rows = np.zeros(A.shape[0], dtype=bool)
        in_rows[self.dofs] = True
        A.data[np.repeat(in_rows, np.diff(A.indptr))] = 0.0
        out = (A + sp.csr_matrix((R.data, R.indices, indptr), shape=A.shape)).tocsr()
        out.sort_indices()
        return out


@dataclass(frozen=True)
class ContinuityRows:
    """Continuity rows ``B^T`` of some cells replaced.

    Attributes
    ----------
    cells : (n_c,) int64
    data : (n_c, dim + 1, width) float64   the cells' rows in the layout of
        :func:`~fbmflow.fem.assembly.assemble_divergence` (``width = dim * nl`` entries per row)
    """

    cells: np.ndarray
    data: np.ndarray

    def apply(self, D: ContinuityBlock) -> ContinuityBlock:
        """The continuity block ``D`` with the rows of ``cells`` replaced (in their pattern)."""
        npl, width = self.data.shape[1:]
        rows = (self.cells[:, None] * npl + np.arange(npl)).ravel()
        current = D[rows]
        if not np.array_equal(np.diff(current.indptr), np.full(rows.size, width)):
            raise ValueError("ContinuityRows.apply: the rows of the cells are no longer the divergence's")
        R = sp.csr_matrix((self.data.ravel(), current.indices, current.indptr), shape=current.shape)
        return D.splice(rows, R)

    def product(self, BT: sp.csr_matrix, U, base: np.ndarray | None = None) -> np.ndarray:
        """``apply(ContinuityBlock(BT)) @ U`` for the level's divergence ``BT`` (CSR): ``BT @ U``,
        then the replaced rows from ``data`` alone, (n_p, k) dense for ``U`` (n_u, k) dense or
        sparse. ``base``: ``BT @ U`` (n_p, k) where the caller has it (made elsewhere: on the
        linear solver's device), its replaced rows then written in place where it is dense."""
        npl, width = self.data.shape[1:]
        if base is None:
            base = ContinuityBlock(BT) @ U  # dense: rows in parallel; sparse: the rows that reach U's
        out = base.toarray() if sp.issparse(base) else base
        if self.cells.size:
            rows = (self.cells[:, None] * npl + np.arange(npl)).ravel()
            columns = BT.indices.reshape(-1, npl, width)[self.cells].ravel()
            R = sp.csr_matrix((self.data.ravel(), columns, np.arange(rows.size + 1) * width),
                              shape=(rows.size, BT.shape[1]))
            replaced = R @ U
            out[rows] = replaced.toarray() if sp.issparse(replaced) else replaced
        return out


@dataclass(frozen=True)
class PressureExtension:
    """Pressures of some cells continued from other cells: ``p_c = E p`` on the DOFs of cell
    ``c`` (P1disc is linear in physical coordinates, so a cell's pressure continues exactly into
    a neighbour). The continuity equations of the continued cells are added to those of the cells
    they continue from, tested with the continued basis (``r + E^T r``), and their own rows become
    ``s (p_c - E p)``.

    Attributes
    ----------
    dofs : (k,) int64   pressure DOFs of the continued cells, sorted
    matrix : (n_p, n_p) CSR   ``E``, non-zero rows only at ``dofs``
    scale : (k,) float64   row scale ``s``
    """

    dofs: np.ndarray
    matrix: sp.csr_matrix
    scale: np.ndarray

    def transfer(self, r: np.ndarray) -> np.ndarray:
        """Continuity residuals ``r (n_p,)`` or ``(n_p, k)`` moved to the continuing cells:
        ``r + E^T r`` with the rows of ``dofs`` zeroed (a copy)."""
        out = r + self.matrix.T @ r
        out[self.dofs] = 0.0
        return out

    def transfer_matrix(self, D: ContinuityBlock) -> ContinuityBlock:
        """The same on the rows of the continuity block ``D`` (n_p, n_u): the rows of ``dofs``
        and of the continuing cells replaced
        (:meth:`~fbmflow.fem.continuity_block.ContinuityBlock.splice`)."""
        ET = self.matrix.T.tocsr()
        rows = np.union1d(self.dofs, np.flatnonzero(np.diff(ET.indptr)))
        keep = np.ones(rows.size)
        keep[np.isin(rows, self.dofs)] = 0.0
        return D.splice(rows, sp.diags(keep) @ (D[rows] + ET[rows] @ D))

    def residual(self, p: np.ndarray) -> np.ndarray:
        """``s (p - E p)`` on ``dofs``, (k,)."""
        return self.scale * (p[self.dofs] - (self.matrix @ p)[self.dofs])

    def block(self, n_p: int) -> sp.csr_matrix:
        """The rows ``s (e_c - E)`` of ``dofs`` as an (n_p, n_p) CSR matrix (zero elsewhere)."""
        k = len(self.dofs)
        S = sp.csr_matrix((self.scale, (self.dofs, np.arange(k))), shape=(n_p, k))
        unit = sp.csr_matrix((np.ones(k), (np.arange(k), self.dofs)), shape=(k, n_p))
        return (S @ (unit - self.matrix[self.dofs])).tocsr()

    def exclude(self, P: sp.csr_matrix | None) -> sp.csr_matrix | None:
        """``P`` (n_p, n_p) with the rows and columns of ``dofs`` zeroed (None if nothing is left)."""
        if P is None:
            return None
        keep = np.ones(P.shape[0])
        keep[self.dofs] = 0.0
        D = sp.diags(keep)
        Q = (D @ P @ D).tocsr()
        Q.eliminate_zeros()
        return Q if Q.nnz else None


@dataclass(frozen=True)
class DirichletConstraints:
    """The constraints of one discrete problem: velocity DOFs with prescribed values and,
    optionally, the sharp boundary's row constraints, continuity rows and pressure extension.

    Attributes
    ----------
    dofs : (n_c,) int64   constrained entries of the component-blocked velocity vector, sorted
    values : (n_c,) float64   prescribed values (for the DOFs of ``rows``: a first guess only)
    rows : RowConstraints or None   the DOFs among ``dofs`` whose momentum equations are replaced
        by linear constraints instead of fixed values
    continuity : ContinuityRows or None   replaced continuity rows
    extension : PressureExtension or None   continued cell pressures
    """

    dofs: np.ndarray
    values: np.ndarray
    rows: RowConstraints | None = None
    continuity: ContinuityRows | None = None
    extension: PressureExtension | None = None

    @cached_property
    def fixed(self) -> np.ndarray:
        """The DOFs with fixed values: ``dofs`` less those of ``rows``, (n_f,) int64 sorted."""
        if self.rows is None:
            return self.dofs
        return np.setdiff1d(self.dofs, self.rows.dofs, assume_unique=True)

    @property
    def sharp(self) -> bool:
        """True when the constraints carry rows, continuity rows or a pressure extension."""
        return self.rows is not None or self.continuity is not None or self.extension is not None

    def merged(self, other: "DirichletConstraints | None") -> "DirichletConstraints":
        """Union with ``other``; where both constrain a DOF, ``self`` wins (its value, or its row
        constraint). Continuity rows and extensions come from the side that has them."""
        if other is None or other.dofs.size == 0:
            return self
        dofs = np.concatenate([other.dofs, self.dofs])
        values = np.concatenate([other.values, self.values])
        # keep the last occurrence (self) of every DOF
        rev_unique, rev_index = np.unique(dofs[::-1], return_index=True)
        if self.sharp and other.sharp:
            raise NotImplementedError("row constraints from both sides of a merge")
        source = self if self.sharp else other
        rows = source.rows
        if rows is not None and source is other:
            rows = rows.select(~among_sorted(rows.dofs, self.dofs))
        if rows is not None and rows.dofs.size == 0:
            rows = None
        return DirichletConstraints(rev_unique, values[::-1][rev_index], rows, source.continuity,
                                    source.extension)

    def homogeneous(self) -> "DirichletConstraints":
        """The same DOFs, all with fixed zero values (for coarse multigrid levels)."""
        return DirichletConstraints(self.dofs, np.zeros(self.dofs.size))

    def apply_to_vector(self, u: np.ndarray) -> None:
        """Set the fixed entries of ``u (dim * n_v,)`` in place (those of ``rows`` keep theirs)."""
        if self.rows is None:
            u[self.dofs] = self.values
        else:
            u[self.fixed] = self.values[np.searchsorted(self.dofs, self.fixed)]

    def zero_rows(self, matrix: sp.csr_matrix) -> None:
        """Turn the constrained rows of square CSR ``matrix`` into unit rows, in place."""
        _kernels.set_identity_rows(matrix.indptr, matrix.indices, self.dofs, matrix.data)

    def constrain_divergence(self, D: ContinuityBlock, fixed_only: bool = False) -> ContinuityBlock:
        """The continuity block ``D`` (n_p, n_u) with the constrained velocity columns zeroed
        (only the fixed ones with ``fixed_only``: the DOFs of ``rows`` remain unknowns of the
        continuity equations)."""
        return D.zero_columns(self.fixed if fixed_only else self.dofs)

    def continuity_matrix(self, D: ContinuityBlock) -> ContinuityBlock:
        """The continuity block ``D`` with the replaced rows and the extension's transfer
        (``D`` itself without either)."""
        if self.continuity is not None:
            D = self.continuity.apply(D)
        if self.extension is not None:
            D = self.extension.transfer_matrix(D)
        return D
