"""Dirichlet constraints on velocity DOFs and their application to the saddle-point operators.

Constrained rows of the velocity block become unit rows; the matching rows of ``B`` (equivalently
the columns of ``B^T``, which shares its data) are zeroed. Newton updates are then zero on the
constrained DOFs, whose values are set in the first iterate (deal.II step-57 style).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from . import _kernels


@dataclass(frozen=True)
class DirichletConstraints:
    """Prescribed velocity values.

    Attributes
    ----------
    dofs : (n_c,) int64   constrained entries of the component-blocked velocity vector, sorted
    values : (n_c,) float64
    """

    dofs: np.ndarray
    values: np.ndarray

    def merged(self, other: "DirichletConstraints | None") -> "DirichletConstraints":
        """Union with ``other``; where both constrain a DOF, ``self``'s value wins."""
        if other is None or other.dofs.size == 0:
            return self
        dofs = np.concatenate([other.dofs, self.dofs])
        values = np.concatenate([other.values, self.values])
        # keep the last occurrence (self) of every DOF
        rev_unique, rev_index = np.unique(dofs[::-1], return_index=True)
        return DirichletConstraints(rev_unique, values[::-1][rev_index])

    def apply_to_vector(self, u: np.ndarray) -> None:
        """Set the constrained entries of ``u (dim * n_v,)`` in place."""
        u[self.dofs] = self.values

    def zero_rows(self, matrix: sp.csr_matrix) -> None:
        """Turn the constrained rows of square CSR ``matrix`` into unit rows, in place."""
        _kernels.set_identity_rows(matrix.indptr, matrix.indices, self.dofs, matrix.data)

    def constrain_divergence(self, BT: sp.csr_matrix) -> sp.csr_matrix:
        """Copy of ``B^T`` (n_p, n_u) with the constrained velocity columns zeroed."""
        mask = np.zeros(BT.shape[1], dtype=bool)
        mask[self.dofs] = True
        data = np.where(mask[BT.indices], 0.0, BT.data)
        return sp.csr_matrix((data, BT.indices, BT.indptr), shape=BT.shape)
