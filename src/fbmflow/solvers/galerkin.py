"""Coarse multigrid systems that see the fine level's constraints: Galerkin rows near them.

On nested meshes the re-discretised coarse operator equals the Galerkin product ``R K P`` of the
fine one wherever the fine rows are the plain discretisation. Near fictitious boundaries they are
not: fine velocity DOFs there are fixed or carry row constraints (the sharp boundary's ghost
nodes), pressure modes are orphaned or continued from a neighbour, continuity rows are integrated
over the fluid part. A coarse level that re-discretises with its own (coarser) picture of the
obstacle sees a different obstacle than the fine level (measured: the V-cycle stalls at a factor
0.55, or diverges with an enlarged coarse obstacle whose weakly seen pressure modes blow up).

Here the coarse rows of every DOF in a *zone* around the fine level's irregular cells are the
rows of ``P_t^T K P_t``, with ``P_t`` the prolongation truncated on the fine DOFs that are no PDE
unknowns (fixed velocities, row-constrained velocities, orphaned or continued pressures): the
coarse basis functions are cut off where the fine level prescribes. The zone is every DOF of the
coarse cells that contain an irregular fine cell, and of their neighbours (so rows outside the
zone never couple to a truncated column). A coarse DOF whose truncated prolongation is empty (it
lies inside a particle) becomes a fixed DOF; the pressure modes no coarse velocity sees are found
as orphans (:func:`~fbmflow.solvers.system.orphan_pressure_modes`). Everything is local: rows of
the fine matrices, the prolongation, and cell neighbours, which a halo exchange could supply.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..fem.continuity_block import ContinuityBlock, zero_columns
from . import _kernels
from .system import SaddlePointSystem, without_orphaned_modes
from .transfer import BlockTransfer


def _cell_incidence(cell_dofs: np.ndarray, n_v: int) -> sp.csr_matrix:
    n_cells, nl = cell_dofs.shape
    return sp.csr_matrix((np.ones(cell_dofs.size), (np.repeat(np.arange(n_cells), nl), cell_dofs.ravel())),
                         shape=(n_cells, n_v))


def dilate_cells(cell_dofs: np.ndarray, n_v: int, cells: np.ndarray, layers: int) -> np.ndarray:
    """``cells`` grown by ``layers`` layers of cells that share a node with them, (k,) int64 sorted."""
    incidence = _cell_incidence(cell_dofs, n_v)
    mask = np.zeros(cell_dofs.shape[0])
    mask[cells] = 1.0
    for _ in range(layers):
        mask = incidence @ (incidence.T @ mask)
    return np.flatnonzero(mask > 0)


def parent_cells(P_p: sp.csr_matrix, npl: int) -> np.ndarray:
    """The coarse cell of every fine cell, from the P1disc prolongation (its constant mode's row
    has entries in the parent's modes only): (n_fine_cells,) int64."""
    rows = P_p.tocsr()[::npl]
    return rows.indices[rows.indptr[:-1]] // npl


def system_rows(system: SaddlePointSystem, rows: np.ndarray) -> sp.csr_matrix:
    """Rows ``rows`` (sorted, into ``[u, p]``) of the unbordered saddle-point matrix, CSR."""
    n_u = system.n_u
    ru, rp = rows[rows < n_u], rows[rows >= n_u] - n_u
    C = system.pressure_block
    C = sp.csr_matrix((system.n_p, system.n_p)) if C is None else sp.csr_matrix(C)
    top = sp.hstack([system.A[ru], system.gradient_rows(ru)], format="csr")
    bottom = sp.hstack([system.BT[rp], C[rp]], format="csr")
    return sp.vstack([top, bottom], format="csr")


def truncated_prolongation(system: SaddlePointSystem, P_v: sp.csr_matrix,
                           P_p: sp.csr_matrix) -> BlockTransfer:
    """The block prolongation ``diag(P_v, ..., P_v, P_p)`` onto ``system``'s level with the rows
    of the fine DOFs that are no PDE unknowns dropped: fixed and row-constrained velocities,
    pressure DOFs in rows of the pressure block (orphaned or continued modes)."""
    keep = np.ones(system.n_u + system.n_p, dtype=bool)
    for dofs in (system.fixed, system.rows):
        if dofs is not None:
            keep[dofs] = False
    C = system.pressure_block
    if C is not None:
        keep[system.n_u + np.flatnonzero(np.diff(sp.csr_matrix(C).indptr))] = False
    return BlockTransfer(P_v, P_p, keep, system.space.dim)


def galerkin_coarse_system(fine: SaddlePointSystem, coarse: SaddlePointSystem, P_v: sp.csr_matrix,
                           P_p: sp.csr_matrix, injection: np.ndarray,
                           irregular: np.ndarray) -> tuple[SaddlePointSystem, np.ndarray]:
    """``coarse`` (re-discretised, walls constrained) with the rows of the zone around the fine
    ``irregular (k,)`` cells replaced by Galerkin rows (see the module docstring). ``injection
    (n_v_coarse,)``: the fine node at every coarse node.

    Returns the new coarse system and its zone cells (k_c,) int64: the irregular cells of the
    next coarser level. ``coarse`` must carry no row constraints.
    """
    space = coarse.space
    d, npl, n_u = space.dim, space.dim + 1, coarse.n_u
    cd = space.V.cell_dofs
    parent = parent_cells(P_p, npl)
    zone = dilate_cells(cd, space.n_v, np.unique(parent[irregular]), 1)
    zone_u = np.unique(np.concatenate([cd[zone] + i * space.n_v for i in range(d)], axis=None))
    zone_p = (zone[:, None] * npl + np.arange(npl)).ravel()
    zone_rows = np.concatenate([zone_u, n_u + zone_p])
    Pt = truncated_prolongation(fine, P_v, P_p).tocsr()
    R = Pt.T.tocsr()[zone_rows]                              # (n_zone, n_fine)
    support = np.unique(R.indices)
    G = (R[:, support] @ system_rows(fine, support) @ Pt).tocsr()   # (n_zone, n_coarse)
    # coarse velocity DOFs on truncated fine ones (their node is the fine node ``injection``):
    # fixed, as the fine DOF is; the others keep their own fine DOF, so P_t has full column rank
    n_v_fine = P_v.shape[0]
    cut = np.diff(Pt.indptr[:d * n_v_fine + 1]) == 0  # truncated fine velocity DOFs (empty rows)
    on_cut = cut.reshape(d, n_v_fine)[:, injection].ravel()
    fixed = np.union1d(coarse.fixed if coarse.fixed is not None else np.zeros(0, np.int64),
                       np.flatnonzero(on_cut))
    K = _replace_rows(coarse.matrix(bordered=False), zone_rows, G)
    A = K[:n_u, :n_u].tocsr()
    is_fixed = np.zeros(n_u, dtype=bool)
    is_fixed[fixed] = True
    A = _unit_rows(A, fixed)
    gradient = _zero_rows(K[:n_u, n_u:].tocsr(), is_fixed)
    BT = zero_columns(K[n_u:, :n_u].tocsr(), fixed)
    gradient_BT = _standard_pattern(gradient.T.tocsr(), coarse)  # B's fixed rows: zero already
    system = SaddlePointSystem(A, BT, coarse.mean_weights, fixed, space, fixed_always=coarse.fixed_always,
                               gradient_BT=gradient_BT, transient=coarse.transient)
    if system.orphans is not None:  # the orphaned modes' continuity equations drop out
        system.BT = without_orphaned_modes(system.BT, system.orphans)
    return system, zone


def _replace_rows(K: sp.csr_matrix, rows: np.ndarray, G: sp.csr_matrix) -> sp.csr_matrix:
    keep = np.ones(K.shape[0])
    keep[rows] = 0.0
    embed = sp.csr_matrix((np.ones(rows.size), (rows, np.arange(rows.size))), shape=(K.shape[0], rows.size))
    out = (sp.diags(keep) @ K + embed @ G).tocsr()
    out.sort_indices()
    return out


def _unit_rows(A: sp.csr_matrix, dofs: np.ndarray) -> sp.csr_matrix:
    keep = np.ones(A.shape[0])
    keep[dofs] = 0.0
    unit = np.zeros(A.shape[0])
    unit[dofs] = 1.0
    out = (sp.diags(keep) @ A + sp.diags(unit)).tocsr()
    out.sort_indices()
    return out


def _zero_rows(M: sp.csr_matrix, mask: np.ndarray) -> sp.csr_matrix:
    return sp.csr_matrix((M.data * np.repeat(~mask, np.diff(M.indptr)), M.indices, M.indptr), shape=M.shape)


def _standard_pattern(GT: sp.csr_matrix, coarse: SaddlePointSystem) -> sp.csr_matrix:
    """``GT`` (n_p, n_u) written into the cell-local pattern of the discrete divergence (what
    :func:`~fbmflow.solvers.system.orphan_pressure_modes` reads); the Galerkin rows of nested
    meshes stay within a coarse cell."""
    ref = coarse.gradient_BT if coarse.gradient_BT is not None else coarse.BT
    ref = (ref.base if isinstance(ref, ContinuityBlock) else ref).copy()
    ref.sort_indices()
    GT.sort_indices()
    data = np.empty(ref.nnz)
    if not _kernels.scatter_into_pattern(GT.indptr, GT.indices, GT.data, ref.indptr, ref.indices, data):
        raise RuntimeError("a Galerkin divergence row reaches beyond its coarse cell")
    return sp.csr_matrix((data, ref.indices, ref.indptr), shape=ref.shape)
