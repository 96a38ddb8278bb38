"""Grid transfer between nested Q2/P1disc levels.

* Q2 prolongation: exact interpolation of the coarse Q2 field at the fine Q2 nodes (on each
  coarse cell the fine nodes sit at reference coordinates ``{-1, -1/2, 0, 1/2, 1}^dim``).
* P1disc prolongation: exact, because P1disc is linear in physical coordinates. With coarse frame
  ``(C, S)`` and fine frame ``(c, s)``, ``(x - C)/S = (c - C)/S + (s/S) (x - c)/s``.
* Restrictions are the transposes (:class:`BlockTransfer` applies both to the saddle point's
  velocity components and pressure from the scalar blocks). Injection (fine values at the
  coarse nodes) carries the convecting velocity to coarse levels for re-discretisation.

Periodic identification comes with the DOF maps.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..fem.dofmap import DofMap, PressureDofMap
from ..fem.elements import ElementQ2
from .sparse import matvec, rmatvec


def _fine_lattice_in_coarse_cells(coarse: DofMap) -> tuple[np.ndarray, np.ndarray]:
    """Fine lattice indices (n_cells_c, 5**dim, dim) and reference points (5**dim, dim)."""
    dim = coarse.mesh.dim
    local = np.indices((5,) * dim).reshape(dim, -1, order="F").T  # (5**dim, dim)
    lat = 4 * coarse.mesh.cell_indices()[:, None, :] + local[None, :, :]
    return lat, local * 0.5 - 1.0


def prolongation_q2(coarse: DofMap, fine: DofMap) -> sp.csr_matrix:
    """Scalar Q2 interpolation, (fine.n_dofs, coarse.n_dofs) CSR."""
    if tuple(2 * n for n in coarse.mesh.shape) != fine.mesh.shape:
        raise ValueError("fine mesh is not the refinement of the coarse mesh")
    lat, xi = _fine_lattice_in_coarse_cells(coarse)
    phi, _ = ElementQ2(coarse.mesh.dim).tabulate(xi)  # (5**dim, 27)
    rows = np.broadcast_to(fine._lattice_to_dof(lat)[:, :, None], lat.shape[:2] + (phi.shape[1],))
    cols = np.broadcast_to(coarse.cell_dofs[:, None, :], rows.shape)
    vals = np.broadcast_to(phi[None, :, :], rows.shape)
    keep = np.abs(vals) > 1e-14
    rows, cols, vals = rows[keep], cols[keep], vals[keep]
    key = rows * coarse.n_dofs + cols
    _, first = np.unique(key, return_index=True)  # shared fine nodes: take each entry once
    return sp.csr_matrix((vals[first], (rows[first], cols[first])), shape=(fine.n_dofs, coarse.n_dofs))


def prolongation_p1disc(coarse: PressureDofMap, fine: PressureDofMap) -> sp.csr_matrix:
    """P1disc prolongation, (fine.n_dofs, coarse.n_dofs) CSR (exact for P1disc functions)."""
    dim = fine.mesh.dim
    npl = dim + 1
    fidx = fine.mesh.cell_indices()
    parent_idx = fidx // 2
    strides = np.cumprod((1,) + coarse.mesh.shape[:-1])
    parent = (parent_idx * strides).sum(axis=1)
    n_f = fine.mesh.n_cells
    C, S = coarse.centre[parent], coarse.scale[parent]
    c, s = fine.centre, fine.scale
    rows, cols, vals = [np.arange(n_f) * npl], [parent * npl], [np.ones(n_f)]
    for ax in range(dim):
        rows += [np.arange(n_f) * npl, np.arange(n_f) * npl + 1 + ax]
        cols += [parent * npl + 1 + ax, parent * npl + 1 + ax]
        vals += [(c[:, ax] - C[:, ax]) / S[:, ax], s[:, ax] / S[:, ax]]
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                         shape=(fine.n_dofs, coarse.n_dofs))


def injection_q2(coarse: DofMap, fine: DofMap) -> np.ndarray:
    """Fine DOF at every coarse node (coarse nodes are fine nodes): (coarse.n_dofs,) int64."""
    return fine._lattice_to_dof(2 * coarse.lattice)


class BlockTransfer:
    """The transfers between two levels of the saddle-point system, ``d`` velocity components
    and the pressure: the prolongation ``P = K diag(P_v, ..., P_v, P_p)`` with ``K`` the 0/1
    diagonal ``keep`` (the fine DOFs that are no PDE unknowns get no correction), and the
    restriction ``P^T``, applied from the scalar blocks without a block matrix of their own.

    Parameters
    ----------
    P_v : (n_v, n_v_coarse) CSR, the scalar Q2 prolongation
    P_p : (n_p, n_p_coarse) CSR, the P1disc prolongation
    keep : (d n_v + n_p,) bool, the fine DOFs whose rows of ``P`` are kept
    dim : int, ``d``
    """

    def __init__(self, P_v: sp.csr_matrix, P_p: sp.csr_matrix, keep: np.ndarray, dim: int):
        # the level's own matrices where they are CSR (the GPU keeps its copies by their identity)
        self.P_v, self.P_p = (M if sp.issparse(M) and M.format == "csr" else sp.csr_matrix(M)
                              for M in (P_v, P_p))
        self.keep, self.dim = keep, dim
        self.shape = (dim * P_v.shape[0] + P_p.shape[0], dim * P_v.shape[1] + P_p.shape[1])

    def _blocks(self) -> list[tuple[sp.csr_matrix, slice, slice]]:
        """``(M, fine rows, coarse rows)`` of each diagonal block."""
        (nf, nc), (pf, pc) = self.P_v.shape, self.P_p.shape
        d = self.dim
        out = [(self.P_v, slice(i * nf, (i + 1) * nf), slice(i * nc, (i + 1) * nc)) for i in range(d)]
        return out + [(self.P_p, slice(d * nf, d * nf + pf), slice(d * nc, d * nc + pc))]

    def prolongate(self, e: np.ndarray) -> np.ndarray:
        """``P e`` for a coarse vector (n_coarse,) -> (n_fine,) float64."""
        out = np.empty(self.shape[0])
        for M, fine, coarse in self._blocks():
            out[fine] = matvec(M, np.ascontiguousarray(e[coarse]))
        out[~self.keep] = 0.0
        return out

    def restrict(self, r: np.ndarray) -> np.ndarray:
        """``P^T r`` for a fine vector (n_fine,) -> (n_coarse,) float64."""
        r = np.where(self.keep, r, 0.0)
        out = np.empty(self.shape[1])
        for M, fine, coarse in self._blocks():
            out[coarse] = rmatvec(M, r[fine])
        return out

    def tocsr(self) -> sp.csr_matrix:
        """``P`` assembled, (n_fine, n_coarse) CSR without the dropped rows' entries."""
        P = sp.diags(self.keep.astype(np.float64)) @ sp.block_diag([self.P_v] * self.dim + [self.P_p],
                                                                   format="csr")
        P.eliminate_zeros()
        return P.tocsr()
