"""A structured mesh split into Cartesian blocks of cells, one per process, each with ``w``
layers of halo cells towards each neighbour (one by default): slabs along the last axis where
the process grid is ``(1, ..., 1, P)``.

The processes form a grid of ``g_a`` processes along every axis ``a`` (``prod g_a = P``; process
``r``'s grid coordinates ``c`` with ``r = c_0 + g_0 (c_1 + g_1 c_2)``, the first axis fastest,
as the mesh's own numbering). Along every axis the process owns the cell layers ``[a, b)`` of
its coordinate and holds ``[a - w, b + w)`` (no halo beyond the mesh's ends): its *block mesh*,
the product of the held layers. A node plane shared by two processes' owned layers belongs to
the lower one: along an axis the process owns the node planes ``2 a + 1`` to ``2 b`` (from plane
0 at the first coordinate), and a node is owned where it is owned along every axis; the P1disc
pressures of the owned cells are owned. Everything else on a block mesh is a *ghost*, a copy of
what a neighbour owns (the neighbours are the processes at grid offsets in ``{-1, 0, 1}^dim``,
faces, edges and corners).

Along a periodic axis divided among processes the blocks form a ring: the first and the last
coordinate are neighbours, every block holds ``w`` halo layers on both sides, those beyond an
end of the mesh being the layers at its other end (their node planes and cells taken modulo the
axis's ``2 n`` planes and ``n`` layers, their coordinates moved by the period, so that the block
mesh is one piece and not periodic along that axis); plane ``2 n`` is plane 0 and belongs to the
last coordinate. A block and its two halos must then stay shorter than the axis. A periodic
axis that is not divided stays periodic on every block mesh.

An operator assembled or applied cell by cell on the block mesh gives the whole mesh's rows at
every node of the owned cells and at the owned cells' pressures; only the rows of the outer halo
planes miss cells. A vector is *consistent* when its ghosts hold their owners' values
(:meth:`~fbmflow.parallel.blocks.BlockPartition.update_ghosts`: one exchange per grid offset, at
most ``3^dim - 1``, each process sending towards the offset and receiving from the opposite
one). Local vectors are the saddle-point system's ``[u, p]``: ``dim`` velocity components of the
block's ``n_v`` nodes, then ``dim + 1`` P1disc values per block cell.
"""
from __future__ import annotations

import itertools

import numpy as np
import scipy.sparse as sp
from scipy.sparse import csgraph

from ..mesh import StructuredMesh
from .comm import SerialComm


def cut_box(mesh: StructuredMesh, lower, upper) -> StructuredMesh:
    """The cells of ``mesh`` in the layers ``[lower[a], upper[a])`` along every axis ``a`` as a
    mesh of their own (its cells and vertices the global ones, in order). Along a periodic axis
    the bounds may leave ``[0, n]``: layer ``k`` is layer ``k mod n``, its vertices moved by the
    period times ``floor(k / n)``; the piece stays periodic along an axis only where it holds the
    whole ring (``[0, n)``), and otherwise keeps the whole mesh's periods as its
    :attr:`~fbmflow.mesh.structured.StructuredMesh.images` (particles and points repeat by
    them)."""
    dim = mesh.dim
    counts = [m + 1 for m in mesh.shape]
    grid = mesh.vertices.reshape(counts[::-1] + [dim])
    sources, shifts, periodic = [], [], []
    for a, (n, lo, hi) in enumerate(zip(mesh.shape, lower, upper)):
        planes = np.arange(lo, hi + 1)
        whole = (lo, hi) == (0, n)
        if (planes.min() < 0 or planes.max() > n) and not mesh.periodic[a]:
            raise ValueError(f"layers [{lo}, {hi}) leave the mesh's {n} layers along axis {a}, which is not "
                             "periodic")
        if mesh.periodic[a]:
            sources.append(np.where(planes == n, n, planes % n))
            shifts.append(np.where(planes == n, 0.0, np.floor_divide(planes, n) * mesh.periods[a]))
        else:
            sources.append(planes)
            shifts.append(np.zeros(planes.size))
        periodic.append(bool(mesh.periodic[a]) and whole)
    vertices = grid[np.ix_(*sources[::-1])].copy()
    for a in range(dim):
        view = [None] * dim
        view[dim - 1 - a] = slice(None)
        vertices[..., a] += shifts[a][tuple(view)]
    vertices = vertices.reshape(-1, dim)
    cut = [(lo, hi) != (0, n) for n, lo, hi in zip(mesh.shape, lower, upper)]
    lower_ = tuple(float(vertices[:, a].min()) if cut[a] else mesh.lower[a] for a in range(dim))
    upper_ = tuple(float(vertices[:, a].max()) if cut[a] else mesh.upper[a] for a in range(dim))
    shape = tuple(int(hi - lo) for lo, hi in zip(lower, upper))
    ring = any(p and c for p, c in zip(mesh.periodic, cut))
    images = tuple(float(L) for L in mesh.periods) if ring else mesh.images
    return StructuredMesh(shape, lower_, upper_, tuple(periodic), vertices, images)


def split_layers(n_layers: int, size: int, multiple: int = 1) -> np.ndarray:
    """Bounds ``(size + 1,)`` of ``size`` pieces of ``n_layers`` cell layers, as even as they go
    in whole multiples of ``multiple`` layers (so that ``multiple = 2^k`` pieces stay pieces on
    ``k`` coarser levels)."""
    units = n_layers // multiple
    return np.linspace(0, units, size + 1).round().astype(np.int64) * multiple


def process_grids(size: int, dim: int) -> list[tuple[int, ...]]:
    """Every grid of ``size`` processes over ``dim`` axes (tuples whose product is ``size``)."""
    divisors = [d for d in range(1, size + 1) if size % d == 0]
    return [g for g in itertools.product(divisors, repeat=dim) if int(np.prod(g)) == size]


def halo_faces(shape, grid) -> int:
    """The cell faces between blocks of a ``grid`` of processes on a mesh of ``shape`` cells (a
    periodic axis counted as open): what the halo exchanges grow with."""
    return int(sum((g - 1) * np.prod([n for b, n in enumerate(shape) if b != a]) for a, g in enumerate(grid)))


class _Axis:
    """One axis of the process grid: ``n`` cell layers (``periodic``), ``parts`` processes with
    layer ``bounds`` and a halo of ``w`` layers."""

    def __init__(self, n: int, periodic: bool, parts: int, bounds: np.ndarray, w: int):
        self.n, self.periodic, self.parts, self.bounds, self.w = n, periodic, parts, bounds, w
        self.ring = periodic and parts > 1
        self.whole = parts == 1
        self.n_planes = 2 * n if periodic else 2 * n + 1  # the whole mesh's node planes

    def held(self, c: int) -> tuple[int, int]:
        """The held layers ``[a - w, b + w)`` of coordinate ``c`` (clipped at a closed axis's ends)."""
        a, b = int(self.bounds[c]), int(self.bounds[c + 1])
        lower = a - self.w if c > 0 or self.ring else a
        return lower, (b + self.w if c < self.parts - 1 or self.ring else b)

    def planes(self, c: int, shift: int = 0) -> np.ndarray:
        """Coordinate ``c``'s node planes, unwrapped, moved by ``shift`` layers."""
        ha, hb = self.held(c)
        last = 2 * hb if self.whole and self.periodic else 2 * hb + 1
        return np.arange(2 * ha, last) + 2 * shift

    def layers_held(self, c: int, shift: int = 0) -> np.ndarray:
        ha, hb = self.held(c)
        return np.arange(ha, hb) + shift

    def own_planes(self, c: int, planes: np.ndarray, shift: int = 0) -> np.ndarray:
        """Which of the unwrapped ``planes`` coordinate ``c`` (moved by ``shift`` layers) owns."""
        if self.whole:
            return np.ones(planes.size, dtype=bool)
        a, b = int(self.bounds[c]) + shift, int(self.bounds[c + 1]) + shift
        first = planes > 2 * a if c > 0 or self.ring else planes >= 2 * a
        return first & (planes <= 2 * b)

    def own_layers(self, c: int, layers: np.ndarray, shift: int = 0) -> np.ndarray:
        a, b = int(self.bounds[c]) + shift, int(self.bounds[c + 1]) + shift
        return (layers >= a) & (layers < b)

    def neighbour(self, c: int, o: int) -> tuple[int, int] | None:
        """The coordinate at offset ``o`` from ``c`` and the layers its unwrapped numbers are moved
        by (a ring's wrap), or None where there is none."""
        if o == 0:
            return c, 0
        if self.whole or (not self.ring and not 0 <= c + o < self.parts):
            return None
        return (c + o) % self.parts, (c + o) // self.parts * self.n


def _mask_product(per_axis: list[np.ndarray]) -> np.ndarray:
    """The product of per-axis masks, flattened as :func:`box_numbers` numbers it."""
    mask = per_axis[0]
    for m in per_axis[1:]:
        mask = (m[:, None] & mask[None, :]).ravel()
    return mask


def _rank(coordinate, grid) -> int:
    """The rank at grid ``coordinate`` (the first axis fastest)."""
    rank, stride = 0, 1
    for c, g in zip(coordinate, grid):
        rank += c * stride
        stride *= g
    return rank


def box_numbers(per_axis: list[np.ndarray], counts: list[int]) -> np.ndarray:
    """The numbers, the first axis fastest with ``counts`` per axis, of the product of per-axis
    indices, in that order (the first axis fastest)."""
    index = np.zeros(1, dtype=np.int64)
    stride = 1
    for idx, m in zip(per_axis, counts):
        index = (index[None, :] + (np.asarray(idx, dtype=np.int64)[:, None] * stride)).ravel()
        stride *= m
    return index


class BlockPartition:
    """Process ``rank``'s block of ``mesh`` in a ``grid`` of processes (see the module docstring).

    Parameters
    ----------
    mesh : StructuredMesh, 2D or 3D (a periodic axis divided among processes: a ring of blocks)
    size, rank : int, the number of processes and this one's rank (0-based)
    bounds : list over the axes of ``(grid[a] + 1,)`` int, or None (:func:`split_layers` on every
        axis); every block
        needs ``halo + 1`` layers along a divided axis at least, so that a neighbour's ghosts are
        all owned by this block
    comm : the processes' communicator (mpi4py's, or anything with its ``Sendrecv``, ``Send``,
        ``Recv`` and ``allreduce``; :class:`~fbmflow.parallel.comm.SerialComm` where None), which the
        exchanges and sums use
    halo : int, the halo's cell layers towards each neighbour
    grid : tuple of int or None, the processes along every axis (product ``size``; None: slabs
        along the last axis, ``(1, ..., 1, size)``)

    Attributes
    ----------
    grid, coordinate : tuples of int, the process grid and this process's place in it
    layers, held : tuple over the axes of ``(int, int)``, the owned cell layers ``[a, b)`` and the
        block mesh's ``[a - halo, b + halo)`` (clipped to the mesh, or past its ends on a ring)
    mesh : StructuredMesh, the block mesh
    cells : (n_cells,) int64, the block mesh's global cells
    nodes : (n_nodes,) int64, the global Q2 node of every block node
    node_counts, cell_counts : lists of int, the block mesh's Q2 nodes and cells along every axis
    owned_nodes, owned_cells : bool masks over the block's nodes and cells
    owned : (dim n_nodes + (dim + 1) n_cells,) bool, the owned unknowns of a local vector
    """

    def __init__(self, mesh: StructuredMesh, size: int, rank: int, bounds=None, comm=None, halo: int = 1,
                 grid=None):
        dim = mesh.dim
        w = int(halo)
        if w < 1:
            raise ValueError(f"a block's halo needs one cell layer at least, not {halo}")
        if not 0 <= rank < size:
            raise ValueError(f"rank {rank} is not one of {size} processes")
        grid = tuple(int(g) for g in grid) if grid is not None else (1,) * (dim - 1) + (size,)
        if len(grid) != dim or int(np.prod(grid)) != size:
            raise ValueError(f"a grid {grid} of processes for {size} processes on a {dim}D mesh")
        if bounds is None:
            bounds = [split_layers(n, g) for n, g in zip(mesh.shape, grid)]
        bounds = [np.asarray(b, dtype=np.int64) for b in bounds]
        least = w + 1  # the halo's last node plane is the neighbour's own
        for a, (n, g, b) in enumerate(zip(mesh.shape, grid, bounds)):
            if g > 1 and (b.shape != (g + 1,) or b[0] != 0 or b[-1] != n or np.diff(b).min() < least):
                need = "two cell layers each" if w == 1 else f"{least} cell layers each (a halo of {w})"
                raise ValueError(f"{g} processes need {need} along axis {a}, the mesh has {n}: use at most "
                                 f"{n // least} processes there or a finer mesh")
            if g > 1 and mesh.periodic[a] and np.diff(b).max() + 2 * w >= n:
                raise ValueError(f"{g} processes on a periodic axis of {n} cell layers: a block and its "
                                 f"two halos would wrap onto itself (a halo of {w}); use more processes or a "
                                 "finer mesh")
        coordinate, rest = [], rank
        for g in grid:
            coordinate.append(rest % g)
            rest //= g
        self.size, self.rank, self.grid, self.coordinate, self.halo = size, rank, grid, tuple(coordinate), w
        self.comm = comm if comm is not None else SerialComm()
        self.whole = mesh
        self.dim = dim
        axes = [_Axis(n, bool(p), g, b, w) for n, p, g, b in zip(mesh.shape, mesh.periodic, grid, bounds)]
        self._axes = axes
        self.bounds = bounds
        self.layers = tuple((int(ax.bounds[c]), int(ax.bounds[c + 1])) for ax, c in zip(axes, coordinate))
        self.held = tuple(ax.held(c) for ax, c in zip(axes, coordinate))
        self.mesh = cut_box(mesh, [h[0] for h in self.held], [h[1] for h in self.held])
        planes = [ax.planes(c) for ax, c in zip(axes, coordinate)]
        layers = [ax.layers_held(c) for ax, c in zip(axes, coordinate)]
        self.node_counts = [p.size for p in planes]
        self.cell_counts = [k.size for k in layers]
        self.n_planes = [ax.n_planes for ax in axes]
        self.nodes = box_numbers([p % ax.n_planes for p, ax in zip(planes, axes)], self.n_planes)
        self.cells = box_numbers([k % ax.n for k, ax in zip(layers, axes)], list(mesh.shape))
        self.owned_nodes = _mask_product([ax.own_planes(c, p) for ax, c, p in zip(axes, coordinate, planes)])
        self.owned_cells = _mask_product([ax.own_layers(c, k) for ax, c, k in zip(axes, coordinate, layers)])
        npl = dim + 1
        self.n_v, self.n_cells = self.nodes.size, self.cells.size
        self.owned = np.concatenate([np.tile(self.owned_nodes, dim), np.repeat(self.owned_cells, npl)])
        n_v_whole = int(np.prod(self.n_planes))
        #: the whole mesh's unknown of every local one
        self.unknowns_of_whole = np.concatenate([self.nodes + k * n_v_whole for k in range(dim)]
                                                + [dim * n_v_whole + (self.cells[:, None] * npl
                                                                      + np.arange(npl)).ravel()])

        def unknowns(node_sets, cell_sets):  # local unknowns of per-axis local node and cell indices
            v = box_numbers(node_sets, self.node_counts)
            c = box_numbers(cell_sets, self.cell_counts)
            return np.concatenate([v + k * self.n_v for k in range(dim)]
                                  + [dim * self.n_v + (c[:, None] * npl + np.arange(npl)).ravel()])

        #: per grid offset ``(dest, send, source, receive)``: the local unknowns this process owns
        #: that are ghosts of the process ``dest`` at that offset, and its ghosts that the process
        #: ``source`` at the opposite offset owns, in one order on both sides (lexicographic in the
        #: unwrapped node planes and cell layers; None: no such process)
        self.exchanges = []
        for offset in itertools.product((-1, 0, 1), repeat=dim):
            if not any(offset):
                continue
            ends = []
            for sign in (1, -1):  # towards the offset (dest), and from the opposite one (source)
                found = [ax.neighbour(c, sign * o) for ax, c, o in zip(axes, coordinate, offset)]
                ends.append(None if any(f is None for f in found) else found)
            dest, source = ends
            if dest is None and source is None:
                continue
            send = receive = None
            if dest is not None:  # my owned unknowns in dest's held box
                node_sets = [np.flatnonzero(ax.own_planes(c, p) & np.isin(p, ax.planes(d, s)))
                             for ax, c, p, (d, s) in zip(axes, coordinate, planes, dest)]
                cell_sets = [np.flatnonzero(ax.own_layers(c, k) & np.isin(k, ax.layers_held(d, s)))
                             for ax, c, k, (d, s) in zip(axes, coordinate, layers, dest)]
                send = unknowns(node_sets, cell_sets)
                dest = _rank([d for d, _ in dest], grid)
            if source is not None:  # my held unknowns that source owns
                node_sets = [np.flatnonzero(ax.own_planes(d, p, s))
                             for ax, p, (d, s) in zip(axes, planes, source)]
                cell_sets = [np.flatnonzero(ax.own_layers(d, k, s))
                             for ax, k, (d, s) in zip(axes, layers, source)]
                receive = unknowns(node_sets, cell_sets)
                source = _rank([d for d, _ in source], grid)
            self.exchanges.append((dest, send, source, receive))

    def local_nodes(self, nodes: np.ndarray) -> np.ndarray:
        """The block's local node at each of the whole mesh's Q2 ``nodes`` (int array), -1 where
        the block mesh does not hold it."""
        return self._local(np.asarray(nodes, dtype=np.int64), self.n_planes, self.node_counts,
                           [2 * h[0] for h in self.held])

    def local_cells(self, cells: np.ndarray) -> np.ndarray:
        """The block's local cell at each of the whole mesh's ``cells`` (int array), -1 where the
        block mesh does not hold it."""
        return self._local(np.asarray(cells, dtype=np.int64), list(self.whole.shape), self.cell_counts,
                           [h[0] for h in self.held])

    def _local(self, numbers, whole_counts, counts, first) -> np.ndarray:
        out = np.zeros_like(numbers)
        inside = np.ones(numbers.shape, dtype=bool)
        rest, stride = numbers.copy(), 1
        for ax, m, count, f in zip(self._axes, whole_counts, counts, first):
            offset = (rest % m - f) % m if ax.ring else rest % m - f
            rest //= m
            inside &= (offset >= 0) & (offset < count)
            out += offset * stride
            stride *= count
        return np.where(inside, out, -1)

    def _shift(self, x: np.ndarray, comm, forward: bool) -> None:
        """Every exchange: owners' values into the ghosts (``forward``), or the ghosts' values
        added to their owners'."""
        comm = comm or self.comm
        n = len(x)
        for dest, send, source, receive in self.exchanges:
            if send is not None and n < self.owned.size:
                send = send[send < n]
            if receive is not None and n < self.owned.size:
                receive = receive[receive < n]
            if forward:
                out, to, back, frm = send, dest, receive, source
            else:
                out, to, back, frm = receive, source, send, dest
            buffer = None if back is None else np.empty((back.size,) + x.shape[1:])
            data = None if out is None else np.ascontiguousarray(x[out])
            if to is not None and frm is not None:
                comm.Sendrecv(data, dest=to, recvbuf=buffer, source=frm)
            elif to is not None:
                comm.Send(data, dest=to)
            else:
                comm.Recv(buffer, source=frm)
            if buffer is not None:
                if forward:
                    x[back] = buffer
                else:
                    x[back] += buffer
        if not forward:
            x[~self.owned[:n]] = 0.0

    def update_ghosts(self, x: np.ndarray, comm=None) -> None:
        """Copy the owners' values into the ghosts of the local vector ``x`` in place (``comm``:
        another communicator than the partition's): one exchange per grid offset (two for slabs).
        ``x`` may be a velocity alone (its first ``dim n_nodes`` entries), and may have columns
        (``(n, k)``: ``k`` vectors)."""
        self._shift(x, comm, True)

    def add_ghosts(self, x: np.ndarray, comm=None) -> None:
        """Add the ghosts' values of ``x`` to their owners' and zero the ghosts, in place: the
        whole sum at every owned unknown of a vector summed cell by cell (a restricted
        residual), each process holding a part."""
        self._shift(x, comm, False)

    def dot(self, x: np.ndarray, y: np.ndarray, comm=None) -> float:
        """``x · y`` over the whole mesh's unknowns, each once, for local vectors (one reduction);
        velocities alone too."""
        comm = comm or self.comm
        own = self.owned[:x.size]
        return float(comm.allreduce(float(x[own] @ y[own])))

    def pressure_dot(self, p: np.ndarray, q: np.ndarray) -> float:
        """``p · q`` over the whole mesh's pressure unknowns, each once, for local pressures
        ``(dim + 1) n_cells`` (one reduction)."""
        own = self.owned[self.dim * self.n_v:]
        return float(self.comm.allreduce(float(p[own] @ q[own])))

    def join_components(self, labels: np.ndarray, comm=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The whole mesh's connected components of nodes from every block's own: ``labels
        (n_nodes,)`` int64 labels a component of the block's nodes by its smallest local node (-1:
        in none), two nodes joined where the block mesh's cells join them. Components of two blocks
        that share a node are one; as the block meshes' cells cover the whole mesh's, these are the
        whole mesh's components.

        Returns the smallest global node of every local node's component (-1 where in none),
        ``(n_nodes,)`` int64, and every component of the whole mesh by that node, ascending, with
        its number of nodes: ``roots (m,)`` int64 and ``sizes (m,)`` int64, the same on every
        process (one ``allgather`` of the nodes two blocks share and of the block
        components' owned node counts)."""
        comm = comm or self.comm
        inside = labels >= 0
        smallest = np.full(self.n_v, np.iinfo(np.int64).max)  # a block component's smallest global node
        np.minimum.at(smallest, labels[inside], self.nodes[inside])  # (a ring's: not its first local one)
        ids = np.where(inside, smallest[np.maximum(labels, 0)], -1)
        shared = np.unique(np.concatenate([np.zeros(0, np.int64)] + [
            ends[ends < self.n_v] for _, send, _, receive in self.exchanges
            for ends in (send, receive) if ends is not None]))
        shared = shared[inside[shared]]
        counted, counts = np.unique(ids[inside & self.owned_nodes], return_counts=True)
        parts = comm.allgather((self.nodes[shared], ids[shared], np.unique(ids[inside]), counted, counts))
        nodes = np.concatenate([q[0] for q in parts])
        joined = np.concatenate([q[1] for q in parts])
        every = np.unique(np.concatenate([q[2] for q in parts]))
        index = np.searchsorted(every, joined)
        order = np.argsort(nodes, kind="stable")  # a shared node's ids side by side: join them
        same = nodes[order][1:] == nodes[order][:-1]
        a, b = index[order][:-1][same], index[order][1:][same]
        graph = sp.coo_matrix((np.ones(a.size), (a, b)), shape=(every.size, every.size))
        _, component = csgraph.connected_components(graph, directed=False)
        root_of = np.full(component.max(initial=-1) + 1, np.iinfo(np.int64).max)
        np.minimum.at(root_of, component, every)  # every id is its part's smallest node
        sizes = np.zeros(root_of.size, dtype=np.int64)
        for _, _, _, c, n in parts:
            np.add.at(sizes, component[np.searchsorted(every, c)], n)
        out = np.full(labels.shape, -1, dtype=np.int64)
        out[inside] = root_of[component[np.searchsorted(every, ids[inside])]]
        order = np.argsort(root_of)
        return out, root_of[order], sizes[order]

    def gather(self, x: np.ndarray, n_whole: int, root: int = 0, comm=None) -> np.ndarray | None:
        """The whole mesh's vector ``(n_whole,)`` of every process's local ``x`` (its owned
        unknowns) on process ``root``, None on the others (one ``gather``)."""
        comm = comm or self.comm
        parts = comm.gather((self.unknowns_of_whole[self.owned], x[self.owned]), root=root)
        if comm.rank != root:
            return None
        whole = np.empty(n_whole)
        for index, values in parts:
            whole[index] = values
        return whole

    def local(self, whole: np.ndarray) -> np.ndarray:
        """The block's part of a whole mesh's vector ``[u, p]`` (a copy)."""
        return whole[self.unknowns_of_whole]
