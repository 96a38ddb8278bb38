"""Orders of the unknowns on a structured mesh: the cell patches of a multiplicative
(Gauss–Seidel) smoother sweep, split into slabs that threads sweep at the same time, and the
nested dissection that a sparse direct factorisation eliminates in
(:func:`~fbmflow.solvers.ordering.nested_dissection`).

The cells are cut into ``n_slabs`` (a power of two) slabs of whole cell layers along the axis
with the most cells. A sweep has two phases, each one parallel loop over the slabs of one
parity, every slab's patches updated strictly in lexicographic cell order: first the even
slabs, then the odd ones. Two patches whose cells are at least ``gap`` layers apart never touch
a DOF that the other reads or writes, where ``gap`` follows from how far a matrix row reaches
along the axis (:func:`plane_reach`); every slab is at least ``gap`` layers thick, so no two
slabs of one parity come closer. The sweep is therefore a sequential block Gauss–Seidel sweep
in a fixed order, whatever the number of threads: the slabs depend on the mesh only.

Lexicographic order keeps the matrix rows that neighbouring patches share in cache, and two
parallel loops per sweep, not one per colour of a multi-colour ordering, keep a sweep from
waiting on a descheduled thread at every colour when other processes share the cores. The slabs
are also the layout of a slab domain decomposition: what a halo exchange between neighbouring
slabs would have to supply are the layers within ``gap`` of a slab boundary.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from . import _kernels

#: a slab holds at least this many cell layers
MIN_SLAB_LAYERS = 4
#: at most this many slabs (parallel groups per phase)
MAX_SLABS = 64


def slab_axis(shape: tuple[int, ...]) -> int:
    """The axis with the most cells (the slowest-varying one, i.e. the last, among equals)."""
    return len(shape) - 1 - int(np.argmax(np.asarray(shape)[::-1]))


def dof_planes(space, axis: int) -> np.ndarray:
    """Position of every unknown of ``space`` (a FlowSpace) along ``axis`` in half-cell units:
    a velocity DOF at its Q2 lattice coordinate, a pressure DOF of the cell in layer ``z`` at
    ``2 z + 1``; (n_u + n_p,) int64."""
    lattice = space.V.lattice[:, axis]
    layer = space.mesh.cell_indices()[:, axis]
    return np.concatenate([np.tile(lattice, space.dim), np.repeat(2 * layer + 1, space.dim + 1)])


def lattice_points(space) -> np.ndarray:
    """Position of every unknown of ``space`` on all axes in half-cell units (:func:`dof_planes`),
    (n_u + n_p, dim) int64."""
    return np.column_stack([dof_planes(space, axis) for axis in range(space.dim)])


#: unknowns at most in a leaf of :func:`nested_dissection` (measured on the coarsest level of
#: dfg-3d-1z level 3, 24 173 unknowns: SuperLU factorises in 2.1 s with leaves of 128, 2.9 s
#: with 32, 10.3 s in COLAMD's order)
DISSECTION_LEAF = 128


def nested_dissection(points: np.ndarray, leaf: int = DISSECTION_LEAF) -> np.ndarray:
    """Geometric nested dissection of unknowns at lattice ``points`` (n, dim) int, half-cell
    units (cell boundaries at even positions, :func:`lattice_points`): the box the points span
    is cut at the cell boundary nearest its middle across its longest side; the unknowns on
    either side come first (each dissected in turn), those on the cut last. In the plain
    Q2/P1disc discretisation, where a row reaches at most one cell (two half-cells), the cut
    separates the two sides, and eliminating in this order fills the factors about as little as
    a graph partitioner's order would. Boxes of at most ``leaf`` unknowns keep the given order.
    Returns the permutation, (n,) int64."""
    points = np.asarray(points)
    parts: list[np.ndarray] = []

    def dissect(idx: np.ndarray) -> None:
        p = points[idx]
        lo, hi = p.min(axis=0), p.max(axis=0)
        axis = int(np.argmax(hi - lo))
        cut = (lo[axis] + hi[axis]) // 2
        cut += cut % 2 if cut - cut % 2 <= lo[axis] else -(cut % 2)
        if idx.size <= leaf or not lo[axis] < cut < hi[axis]:
            parts.append(idx)
            return
        side = p[:, axis]
        dissect(idx[side < cut])
        dissect(idx[side > cut])
        parts.append(idx[side == cut])

    if len(points):
        dissect(np.arange(len(points)))
    return np.concatenate(parts) if parts else np.zeros(0, dtype=np.int64)


def plane_reach(k_ptr: np.ndarray, k_idx: np.ndarray, planes: np.ndarray, period: int = 0,
                row_offset: int = 0, col_offset: int = 0) -> int:
    """How far a row of the CSR matrix ``(k_ptr, k_idx)`` reaches along the axis: the largest
    ``|planes[col_offset + column] - planes[row_offset + row]|`` (modulo ``period`` half-cells on a
    periodic axis, 0: not periodic; the offsets place the rows and columns of a block). 2 for the
    plain Q2/P1disc discretisation; ghost-node rows of the sharp boundary or Galerkin coarse rows
    may reach further."""
    return int(_kernels.plane_reach(k_ptr, k_idx, planes, period, row_offset, col_offset))


def system_reach(system, planes: np.ndarray, period: int = 0) -> int:
    """:func:`plane_reach` of every block of a saddle-point system (velocity block ``A``,
    gradient, continuity rows ``B^T``, pressure block)."""
    n_u = system.n_u
    blocks = [(system.A, 0, 0), (system.gradient, 0, n_u), (system.BT, n_u, 0),
              (system.pressure_block, n_u, n_u)]
    return max(plane_reach(sp.csr_matrix(M).indptr, sp.csr_matrix(M).indices, planes, period, r, c)
               for M, r, c in blocks if M is not None)


def slab_phases(shape: tuple[int, ...], periodic: tuple[bool, ...], cell_index: np.ndarray, cells: np.ndarray,
                reach: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """The two phases of a slab-ordered sweep over the patches of ``cells``: the even slabs,
    then the odd ones.

    Parameters
    ----------
    shape, periodic : the mesh's cells per axis and periodic axes
    cell_index : (n_cells, dim) int64, logical index of every cell
    cells : (m,) int64, the cell of every patch to sweep (patch ``k`` is cell ``cells[k]``)
    reach : int, :func:`plane_reach` of the rows of the patches' unknowns

    Returns
    -------
    list of ``(gptr, order)``: per phase, the patches ``order[gptr[g]:gptr[g + 1]]`` (indices into
    ``cells``, int64) of group ``g`` (a slab), to be updated in that order; the groups of one
    phase may run at the same time. Empty phases are left out. :func:`reversed_phases` gives
    the sweep backwards.
    """
    axis = slab_axis(shape)
    n = shape[axis]
    gap = int(np.floor(1 + reach / 2)) + 1  # patches this many layers apart are independent
    n_slabs = 1
    while 2 * n_slabs <= MAX_SLABS and n // (2 * n_slabs) >= max(MIN_SLAB_LAYERS, gap):
        n_slabs *= 2
    bounds = np.array([n * s // n_slabs for s in range(n_slabs + 1)])
    slab = np.searchsorted(bounds, cell_index[cells, axis], side="right") - 1
    order = np.argsort(cells, kind="stable")  # lexicographic cell order
    phases = []
    for parity in (0, 1):
        groups = [order[slab[order] == s] for s in range(parity, n_slabs, 2)]
        groups = [g for g in groups if g.size]
        if groups:
            gptr = np.concatenate([[0], np.cumsum([g.size for g in groups])]).astype(np.int64)
            phases.append((gptr, np.concatenate(groups).astype(np.int64)))
    return phases


def reversed_phases(phases: list[tuple[np.ndarray, np.ndarray]]) -> list[tuple[np.ndarray, np.ndarray]]:
    """The sweep of :func:`slab_phases` backwards: the phases in reverse, every group reversed."""
    out = []
    for gptr, order in phases[::-1]:
        groups = [order[gptr[g]:gptr[g + 1]][::-1] for g in range(gptr.size - 1)]
        out.append((gptr.copy(), np.concatenate(groups)))
    return out
