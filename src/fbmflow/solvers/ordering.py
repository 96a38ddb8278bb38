"""Orders of the unknowns on a structured mesh: the cell patches of a multiplicative
(Gauss–Seidel) smoother sweep, split into slabs that threads sweep at the same time, and the
nested dissection that a sparse direct factorisation eliminates in
(:func:`~fbmflow.solvers.ordering.nested_dissection`).

The cells are cut into ``n_slabs`` (a power of two) slabs of whole cell layers along the axis
with the most cells. A sweep has two phases, each one parallel loop over the slabs of one
parity, every slab's patches updated strictly in lexicographic cell order: first the even
slabs, then the odd ones. Two patches whose cells are at least ``gap`` layers apart never touch
a DOF that the other reads or writes, where ``gap`` follows from how far a matrix row reaches
(:func:`unknown_reach`); every slab is at least ``gap`` layers thick, so no two slabs of one
parity come closer. The sweep is therefore a sequential block Gauss–Seidel sweep in a fixed
order, whatever the number of threads: the slabs depend on the mesh only.

A mesh of at least :data:`BLOCK_CELLS` cells whose slabs give fewer than :data:`MIN_GROUPS` per
phase is cut along its other axes as well (the longest first, but never along the first,
fastest-varying one, so that a block's cells stay in long runs) until they do: blocks, in four
phases by the parities of their two slab indices, so that 16 threads have work. Two blocks of
one phase lie a whole block apart along one of the axes at least. The few patches whose rows
reach further than most (:func:`near_patches`: a particle's sharp boundary) stay out of the
phases, which would otherwise need a wider gap everywhere, and are updated after them, one
after the other. ten Cate level 1 (12 x 12 x 64 cells, rows at the sphere reaching 6 half-cells):
4 slabs per phase and a smoothing sweep 2.1 times faster at 16 threads than at one with slabs
only; see docs/validation/multigrid-with-fictitious-boundaries.md for the blocks.

Lexicographic order keeps the matrix rows that neighbouring patches share in cache, and a few
parallel loops per sweep, not one per colour of a multi-colour ordering, keep a sweep from
waiting on a descheduled thread at every colour when other processes share the cores. The slabs
are also the layout of a slab domain decomposition: what a halo exchange between neighbouring
slabs would have to supply are the layers within ``gap`` of a slab boundary.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..fem.continuity_block import ContinuityBlock
from ..fem.velocity_block import VelocityBlock
from ..kept import KeptByIdentity
from . import _kernels

#: a slab holds at least this many cell layers
MIN_SLAB_LAYERS = 4
#: at most this many slabs along one axis
MAX_SLABS = 64
#: meshes of at least this many cells are cut into blocks along further axes ...
BLOCK_CELLS = 4096
#: ... while the axes cut so far give fewer than this many groups per phase
MIN_GROUPS = 32
#: a block holds at least this many cell layers along the axes after the first
MIN_BLOCK_LAYERS = 3
#: at most this share of the patches are left out of the phases for the reach of their rows (they
#: are updated one after the other: a larger share would cap what threads can gain)
FAR_SHARE = 0.02


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


def unknown_reach(system) -> np.ndarray:
    """How far the row of every unknown of a saddle-point system reaches: the largest distance,
    in half-cells along any axis (modulo the period on a periodic axis), from the unknown's
    lattice point (:func:`lattice_points`) to that of a column of its row in any block (velocity
    block ``A``, gradient, continuity rows ``B^T``, pressure block); (n_u + n_p,) int64. 2 in the
    plain Q2/P1disc discretisation; ghost-node rows of the sharp boundary and Galerkin coarse rows
    near a particle reach further. What a space and a level's divergence give every system (the
    lattice points, the reach of the scalar pattern that a
    :class:`~fbmflow.fem.velocity_block.VelocityBlock` holds on every component, the divergence's
    rows, and the gradient's where the system's ``gradient_BT`` gives ``B``'s pattern) is
    computed once and kept (``_KEPT``)."""
    space, n_u = system.space, system.n_u
    points, periods, scalar_reach = _KEPT.get(space, "reach", _space_reach)
    out = np.zeros(len(points), dtype=np.int64)
    if isinstance(system.A, VelocityBlock):  # the scalar pattern on every component, then the replaced rows
        out[:n_u] = np.tile(scalar_reach, space.dim)
        A = system.A.parts()[space.dim:]
    else:
        A = [(system.A, 0)]
    G = None
    if system.gradient_BT is None:
        G = system.gradient
    else:  # B's pattern is the level's gradient_BT's transposed: its rows' reach kept
        kept = _KEPT.get(system.gradient_BT, "gradient reach", lambda _: _gradient_reach(
            system.gradient_rows(np.arange(n_u)), points, periods))
        np.maximum(out[:n_u], kept, out=out[:n_u])
    D = system.BT
    block = isinstance(D, ContinuityBlock)
    for M, r, c in ([(M, r, r) for M, r in A] + [(G, 0, n_u), (None if block else D, n_u, 0),
                                                   (system.pressure_block, n_u, n_u)]):
        if M is not None:
            M = sp.csr_matrix(M)
            _kernels.row_reach(M.indptr, M.indices, points, periods, r, c, out)
    if block:  # the level's rows, then the changed rows in place of theirs
        reach = np.zeros_like(out)
        reach[n_u:] = _KEPT.get(D.base, "continuity reach",
                                lambda base: _continuity_reach(base, points, periods))
        reach[n_u + D.dofs] = 0
        changed = D.changed_rows()
        _kernels.row_reach(changed.indptr, changed.indices, points, periods, n_u, 0, reach)
        np.maximum(out, reach, out=out)
    return out


#: what :func:`unknown_reach` keeps of a space and of a level's divergence
_KEPT = KeptByIdentity()


def _space_reach(space) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A space's :func:`lattice_points`, its periods in half-cells (0: not periodic) (dim,) and
    the reach of its scalar pattern's rows (n_v,) int64."""
    mesh = space.mesh
    points = lattice_points(space)
    periods = np.array([2 * n if periodic else 0 for n, periodic in zip(mesh.shape, mesh.periodic)],
                       dtype=np.int64)
    scalar = np.zeros(space.n_v, dtype=np.int64)
    _kernels.row_reach(space.indptr, space.indices, points, periods, 0, 0, scalar)
    return points, periods, scalar


def _continuity_reach(base: sp.csr_matrix, points: np.ndarray, periods: np.ndarray) -> np.ndarray:
    """The reach of the rows of a level's continuity block ``base`` (n_p, n_u), (n_p,) int64."""
    n_p, n_u = base.shape
    reach = np.zeros(n_u + n_p, dtype=np.int64)
    _kernels.row_reach(base.indptr, base.indices, points, periods, n_u, 0, reach)
    return reach[n_u:]


def _gradient_reach(B: sp.csr_matrix, points: np.ndarray, periods: np.ndarray) -> np.ndarray:
    """The reach of the rows of a level's gradient ``B`` (n_u, n_p), (n_u,) int64."""
    n_u, n_p = B.shape
    B = sp.csr_matrix(B)
    reach = np.zeros(n_u + n_p, dtype=np.int64)
    _kernels.row_reach(B.indptr, B.indices, points, periods, 0, n_u, reach)
    return reach[:n_u]


def near_patches(reach: np.ndarray) -> np.ndarray:
    """Which patches the parallel phases sweep, from every patch's reach ``(m,)`` int64 (the largest
    :func:`unknown_reach` of its unknowns): those whose reach is at most the smallest
    one that leaves out no more than :data:`FAR_SHARE` of them. The others, whose rows reach far
    (a few cells at a particle's sharp boundary), would widen the gap between every pair of slabs
    (ten Cate level 1: reach 6 half-cells instead of 2, so 4 slabs per phase instead of 8); they
    are swept one after the other after the phases. Returns (m,) bool."""
    if reach.size == 0:
        return np.zeros(0, dtype=bool)
    values = np.sort(reach)
    kept = values[min(reach.size - 1, int(np.ceil((1.0 - FAR_SHARE) * reach.size)) - 1)]
    return reach <= kept


def _slab_bounds(n: int, thickness: int) -> np.ndarray:
    """Bounds of the slabs along an axis of ``n`` cell layers: as many as fit (a power of two, at
    most :data:`MAX_SLABS`) of at least ``thickness`` layers each, (n_slabs + 1,) int64. An even
    number of slabs or one, so a periodic axis's first and last slab differ in parity."""
    n_slabs = 1
    while 2 * n_slabs <= MAX_SLABS and n // (2 * n_slabs) >= thickness:
        n_slabs *= 2
    return np.array([n * s // n_slabs for s in range(n_slabs + 1)], dtype=np.int64)


def slab_phases(shape: tuple[int, ...], periodic: tuple[bool, ...], cell_index: np.ndarray, cells: np.ndarray,
                reach: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """The phases of a slab-ordered sweep over the patches of ``cells``: the even slabs, then the
    odd ones (blocks in four phases on a large mesh; see the module's docstring).

    Parameters
    ----------
    shape, periodic : the mesh's cells per axis and periodic axes
    cell_index : (n_cells, dim) int64, logical index of every cell
    cells : (m,) int64, the cell of every patch to sweep (patch ``k`` is cell ``cells[k]``)
    reach : int, the largest :func:`unknown_reach` of the patches' unknowns

    Returns
    -------
    list of ``(gptr, order)``: per phase, the patches ``order[gptr[g]:gptr[g + 1]]`` (indices into
    ``cells``, int64) of group ``g`` (a slab or block), to be updated in that order; the groups of
    one phase may run at the same time. Empty phases are left out. :func:`reversed_phases` gives
    the sweep backwards.
    """
    gap = int(np.floor(1 + reach / 2)) + 1  # patches this many layers apart are independent
    axes = [slab_axis(shape)]
    bounds = [_slab_bounds(shape[axes[0]], max(MIN_SLAB_LAYERS, gap))]
    # not the fastest-varying axis: cut along it, a block's cells come in runs of a few, and a
    # sweep on one thread took 1.65 times as long (ten Cate level 1; 1.11 times without it)
    rest = sorted(set(range(1, len(shape))) - set(axes), key=lambda a: (shape[a], a), reverse=True)
    for axis in rest:  # the longest first, the slower-varying among equals
        per_phase = np.prod([b.size - 1 for b in bounds]) / 2 ** len(axes)
        if np.prod(shape) < BLOCK_CELLS or per_phase >= MIN_GROUPS:
            break
        cut = _slab_bounds(shape[axis], max(MIN_BLOCK_LAYERS, gap))
        if cut.size > 2:
            axes.append(axis)
            bounds.append(cut)
    slabs = [np.searchsorted(b, cell_index[cells, a], side="right") - 1 for a, b in zip(axes, bounds)]
    block = np.zeros(cells.size, dtype=np.int64)
    parity = np.zeros(cells.size, dtype=np.int64)
    for s, b in zip(slabs, bounds):
        block = block * (b.size - 1) + s
        parity = 2 * parity + s % 2
    order = np.argsort(cells, kind="stable")  # lexicographic cell order
    by_block = order[np.argsort(block[order], kind="stable")]  # blocks in turn, each lexicographic
    phases = []
    for phase in range(2 ** len(axes)):
        chosen = by_block[parity[by_block] == phase]
        if chosen.size:
            sizes = np.bincount(block[chosen])
            gptr = np.concatenate([[0], np.cumsum(sizes[sizes > 0])]).astype(np.int64)
            phases.append((gptr, chosen.astype(np.int64)))
    return phases


def reversed_phases(phases: list[tuple[np.ndarray, np.ndarray]]) -> list[tuple[np.ndarray, np.ndarray]]:
    """The sweep of :func:`slab_phases` backwards: the phases in reverse, every group reversed
    in its place (no loop over the groups: in colour order every patch is a group of its own)."""
    out = []
    for gptr, order in phases[::-1]:
        sizes = np.diff(gptr)
        group = np.repeat(np.arange(sizes.size), sizes)
        mirror = gptr[group] + gptr[group + 1] - 1 - np.arange(order.size)  # j -> its group's other end
        out.append((gptr.copy(), order[mirror]))
    return out


def colour_phases(shape: tuple[int, ...], periodic: tuple[bool, ...], cell_index: np.ndarray,
                  cells: np.ndarray, reach: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """The patches of ``cells`` in colours, one phase per colour and every patch a group of its
    own (the order of the GPU's sweeps, :mod:`fbmflow.gpu`: a colour's patches at once): a cell
    of index ``i_a`` along axis ``a`` takes the colour ``(i_a mod m_a)_a``, with ``m_a`` the gap
    of :func:`slab_phases` (patches that many layers apart are independent), or on a periodic
    axis of ``n_a`` cells its smallest divisor at least as large, so that two cells of one colour
    lie a multiple of ``m_a`` apart around the period too (``m_a = n_a``, every layer a colour of
    its own, where none is). In 3D with the plain discretisation's reach, 27 colours. Arguments
    and result as :func:`slab_phases`'s; within a colour the patches go in lexicographic order."""
    gap = int(np.floor(1 + reach / 2)) + 1
    colour = np.zeros(cells.size, dtype=np.int64)
    for a, (n, wrap) in enumerate(zip(shape, periodic)):
        m = min(gap, n)
        if wrap:
            m = next(k for k in range(m, n + 1) if n % k == 0)
        colour = colour * m + cell_index[cells, a] % m
    order = np.argsort(cells, kind="stable")
    by_colour = order[np.argsort(colour[order], kind="stable")]
    sizes = np.bincount(colour)
    bounds = np.concatenate([[0], np.cumsum(sizes)])
    return [(np.arange(sizes[c] + 1, dtype=np.int64), by_colour[bounds[c]:bounds[c + 1]].astype(np.int64))
            for c in range(sizes.size) if sizes[c]]
