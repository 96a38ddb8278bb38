"""A structured mesh split into slabs of cell layers along its last axis, one per process, each
with ``w`` layers of halo cells towards each neighbour (one by default).

Process ``r`` of ``P`` *owns* the cell layers ``[a_r, b_r)`` and holds the layers
``[a_r - w, b_r + w)`` (no halo layer beyond the mesh's ends): its *slab mesh*. In
:mod:`fbmflow.fem.dofmap`'s numbering (node ``I + L_x (J + L_y K)``) a slab's Q2 nodes are the
node planes ``2 (a_r - w)`` to ``2 (b_r + w)``, one run of global numbers, and its cells one run
too. A node plane shared by two slabs' owned cells belongs to the lower slab: process ``r`` owns
the node planes ``2 a_r + 1`` to ``2 b_r`` (from plane 0 on process 0), and the P1disc pressures
of its owned cells; everything else on its slab mesh is a *ghost*, a copy of what a neighbour
owns.

Along a periodic last axis the slabs form a ring: the first and the last process are neighbours,
every slab holds ``w`` halo layers on both sides, those beyond an end of the mesh being the
layers at its other end (their node planes and cells taken modulo the axis's ``2 n`` planes and
``n`` layers, their coordinates moved by the period, so that the slab mesh is one piece and not
periodic along the axis), and process ``r`` owns the node planes ``2 a_r + 1`` to ``2 b_r``,
plane ``2 n`` being plane 0. A slab and its two halos must then stay shorter than the axis.

An operator assembled or applied cell by cell on the slab mesh gives the whole mesh's rows at
every node of the owned cells (the planes ``2 a_r`` to ``2 b_r``: their cells are all on the
slab mesh) and at the owned cells' pressures; only the rows of the outer halo planes miss cells.
A vector is *consistent* when its ghosts hold their owners' values
(:meth:`~fbmflow.parallel.slabs.SlabPartition.update_ghosts`, one exchange with each neighbour).
Local vectors are the saddle-point system's ``[u, p]``: ``dim`` velocity components of the slab's
``n_v`` nodes, then ``dim + 1`` P1disc values per slab cell.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse import csgraph

from ..mesh import StructuredMesh
from .comm import SerialComm


def cut_layers(mesh: StructuredMesh, a: int, b: int) -> StructuredMesh:
    """The cells of ``mesh`` in the layers ``[a, b)`` along its last axis as a mesh of their own
    (its cells and vertices the global ones, in order). Along a periodic last axis ``a`` may be
    negative and ``b`` beyond the axis's ``n`` layers: layer ``k`` is layer ``k mod n``, its
    vertices moved by the period times ``floor(k / n)``; the piece is periodic along the axis
    only where it is the whole ring (``[0, n)``), and keeps the period otherwise as its
    :attr:`~fbmflow.mesh.structured.StructuredMesh.images` (particles and points repeat by it)."""
    n = mesh.shape[-1]
    vertex_plane = int(np.prod([m + 1 for m in mesh.shape[:-1]]))
    planes = np.arange(a, b + 1)
    if (planes.min() < 0 or planes.max() > n) and not mesh.periodic[-1]:
        raise ValueError(f"layers [{a}, {b}) leave the mesh's {n} layers along its last axis, which is "
                         "not periodic")
    shift = np.floor_divide(planes, n) * mesh.periods[-1] if mesh.periodic[-1] else np.zeros(planes.size)
    source = np.where(planes == n, n, planes % n) if mesh.periodic[-1] else planes
    vertices = mesh.vertices.reshape(-1, vertex_plane, mesh.dim)[source].copy()
    vertices[..., -1] += np.where(planes == n, 0.0, shift)[:, None]
    vertices = vertices.reshape(-1, mesh.dim)
    lower = mesh.lower[:-1] + (float(vertices[:, -1].min()),)
    upper = mesh.upper[:-1] + (float(vertices[:, -1].max()),)
    if (a, b) == (0, n) or not mesh.periodic[-1]:
        return StructuredMesh(mesh.shape[:-1] + (b - a,), lower, upper, mesh.periodic, vertices, mesh.images)
    return StructuredMesh(mesh.shape[:-1] + (b - a,), lower, upper, mesh.periodic[:-1] + (False,), vertices,
                          tuple(float(L) for L in mesh.periods))


def split_layers(n_layers: int, size: int, multiple: int = 1) -> np.ndarray:
    """Bounds ``(size + 1,)`` of ``size`` slabs of ``n_layers`` cell layers, as even as they go
    in whole multiples of ``multiple`` layers (so that ``multiple = 2^k`` slabs stay slabs on
    ``k`` coarser levels)."""
    units = n_layers // multiple
    return np.linspace(0, units, size + 1).round().astype(np.int64) * multiple


class SlabPartition:
    """Process ``rank``'s slab of ``mesh`` among ``size`` processes (see the module docstring).

    Parameters
    ----------
    mesh : StructuredMesh, 2D or 3D (periodic along its last axis: the slabs form a ring)
    size, rank : int, the number of processes and this one's rank (0-based)
    bounds : (size + 1,) int or None, the slabs' first cell layers and the last one's end
        (:func:`split_layers` where None); every slab needs ``halo + 1`` layers at least,
        so that a neighbour's ghosts are all owned by this slab
    halo : int, the halo's cell layers towards each neighbour
    comm : the processes' communicator (mpi4py's, or anything with its ``Sendrecv`` and
        ``allreduce``; :class:`~fbmflow.parallel.comm.SerialComm` where None), which the exchanges
        and sums use

    Attributes
    ----------
    layers : (int, int), the owned cell layers ``[a, b)`` along the last axis
    held : (int, int), the slab mesh's layers ``[a - halo, b + halo)`` (clipped to the mesh, or
        past its ends on a ring)
    mesh : StructuredMesh, the slab mesh
    cells : (n_cells,) int64, the slab mesh's global cells
    nodes : (n_nodes,) int64, the global Q2 node of every slab node (one run of numbers, or two
        on a ring's first and last slab)
    owned_nodes, owned_cells : bool masks over the slab's nodes and cells
    owned : (dim n_nodes + (dim + 1) n_cells,) bool, the owned unknowns of a local vector
    """

    def __init__(self, mesh: StructuredMesh, size: int, rank: int, bounds=None, comm=None, halo: int = 1):
        n_last = mesh.shape[-1]
        w = int(halo)
        if w < 1:
            raise ValueError(f"a slab's halo needs one cell layer at least, not {halo}")
        least = w + 1  # the halo's last node plane is the neighbour's own
        #: whether the slabs form a ring (a periodic last axis divided among processes)
        self.ring = ring = bool(mesh.periodic[-1]) and size > 1
        if not 0 <= rank < size:
            raise ValueError(f"rank {rank} is not one of {size} processes")
        bounds = split_layers(n_last, size) if bounds is None else np.asarray(bounds, dtype=np.int64)
        if size > 1 and (bounds.shape != (size + 1,) or bounds[0] != 0 or bounds[-1] != n_last
                         or np.diff(bounds).min() < least):
            need = "two cell layers each" if w == 1 else f"{least} cell layers each (a halo of {w})"
            raise ValueError(f"{size} processes need {need} along the last axis, the mesh has "
                             f"{n_last}: use at most {n_last // least} processes or a finer mesh")
        if ring and np.diff(bounds).max() + 2 * w >= n_last:
            raise ValueError(f"{size} processes on a periodic last axis of {n_last} cell layers: a slab and "
                             f"its two halos would wrap onto itself (a halo of {w}); use more processes or a "
                             "finer mesh")
        self.size, self.rank, self.bounds, self.halo = size, rank, bounds, w
        self.comm = comm if comm is not None else SerialComm()
        a, b = int(bounds[rank]), int(bounds[rank + 1])
        ha, hb = (a - w if rank > 0 or ring else a), (b + w if rank < size - 1 or ring else b)
        self.layers, self.held = (a, b), (ha, hb)
        self.whole = mesh
        self.mesh = cut_layers(mesh, ha, hb)
        per_layer = int(np.prod(mesh.shape[:-1]))
        plane = int(np.prod([2 * n if p else 2 * n + 1 for n, p in zip(mesh.shape[:-1], mesh.periodic[:-1])]))
        self.plane = plane
        #: node planes and cell layers of the whole mesh (a ring's wrap round)
        self.n_planes = 2 * n_last if mesh.periodic[-1] else 2 * n_last + 1
        last = 2 * hb if self.mesh.periodic[-1] else 2 * hb + 1  # one process: the whole ring
        node_plane = np.arange(2 * ha, last).repeat(plane)  # the whole mesh's plane, unwrapped
        cell_layer = np.arange(ha, hb).repeat(per_layer)
        self.nodes = (node_plane % self.n_planes) * plane + np.tile(np.arange(plane), last - 2 * ha)
        self.cells = (cell_layer % n_last) * per_layer + np.tile(np.arange(per_layer), hb - ha)
        first = node_plane > 2 * a if rank > 0 or ring else node_plane >= 0
        self.owned_nodes = first & (node_plane <= 2 * b)
        self.owned_cells = (cell_layer >= a) & (cell_layer < b)
        dim, npl = mesh.dim, mesh.dim + 1
        self.dim, self.n_v, self.n_cells = dim, self.nodes.size, self.cells.size
        self.owned = np.concatenate([np.tile(self.owned_nodes, dim), np.repeat(self.owned_cells, npl)])
        n_v_whole = plane * self.n_planes
        #: the whole mesh's unknown of every local one
        self.unknowns_of_whole = np.concatenate([self.nodes + k * n_v_whole for k in range(dim)]
                                                + [dim * n_v_whole + (self.cells[:, None] * npl
                                                                      + np.arange(npl)).ravel()])

        def unknowns(planes, layers):  # local unknowns of global node planes and cell layers
            v = np.flatnonzero(np.isin(node_plane, planes))
            c = np.flatnonzero(np.isin(cell_layer, layers))
            return np.concatenate([v + k * self.n_v for k in range(dim)]
                                  + [dim * self.n_v + (c[:, None] * npl + np.arange(npl)).ravel()])

        #: per neighbour ``(rank, send, receive)``: the local unknowns this process owns that are
        #: the neighbour's ghosts, and its ghosts that the neighbour owns, in global order
        self.neighbours = []
        if ha < a:  # the lower neighbour's ghosts: planes 2a+1 .. 2(a+w), layers a .. a+w-1
            self.neighbours.append(((rank - 1) % size,
                                    unknowns(np.arange(2 * a + 1, 2 * (a + w) + 1), np.arange(a, a + w)),
                                    unknowns(np.arange(2 * ha, 2 * a + 1), np.arange(ha, a))))
        if hb > b:  # the upper neighbour's: planes 2(b-w) .. 2b, layers b-w .. b-1
            self.neighbours.append(((rank + 1) % size,
                                    unknowns(np.arange(2 * (b - w), 2 * b + 1), np.arange(b - w, b)),
                                    unknowns(np.arange(2 * b + 1, 2 * hb + 1), np.arange(b, hb))))
        if rank % 2:  # odd ranks talk to the upper neighbour first, even ones to the lower one
            self.neighbours.reverse()

    def local_nodes(self, nodes: np.ndarray) -> np.ndarray:
        """The slab's local node at each of the whole mesh's Q2 ``nodes`` (int array), -1 where
        the slab mesh does not hold it."""
        nodes = np.asarray(nodes, dtype=np.int64)
        first = 2 * self.held[0]
        offset = nodes // self.plane - first
        if self.ring:
            offset %= self.n_planes
        inside = (offset >= 0) & (offset <= 2 * (self.held[1] - self.held[0]))
        return np.where(inside, offset * self.plane + nodes % self.plane, -1)

    def local_cells(self, cells: np.ndarray) -> np.ndarray:
        """The slab's local cell at each of the whole mesh's ``cells`` (int array), -1 where the
        slab mesh does not hold it."""
        cells = np.asarray(cells, dtype=np.int64)
        per_layer = int(np.prod(self.whole.shape[:-1]))
        offset = cells // per_layer - self.held[0]
        if self.ring:
            offset %= self.whole.shape[-1]
        inside = (offset >= 0) & (offset < self.held[1] - self.held[0])
        return np.where(inside, offset * per_layer + cells % per_layer, -1)

    def update_ghosts(self, x: np.ndarray, comm=None) -> None:
        """Copy the owners' values into the ghosts of the local vector ``x`` in place (``comm``:
        another communicator than the partition's): one exchange with each neighbour, in two
        rounds whatever the number of processes. ``x`` may be a velocity alone (its first
        ``dim n_nodes`` entries), and may have columns (``(n, k)``: ``k`` vectors)."""
        comm = comm or self.comm
        n = len(x)
        for other, send, receive in self.neighbours:
            if n < self.owned.size:
                send, receive = send[send < n], receive[receive < n]
            buffer = np.empty((receive.size,) + x.shape[1:])
            comm.Sendrecv(np.ascontiguousarray(x[send]), dest=other, recvbuf=buffer, source=other)
            x[receive] = buffer

    def add_ghosts(self, x: np.ndarray, comm=None) -> None:
        """Add the ghosts' values of ``x`` to their owners' and zero the ghosts, in place: the
        whole sum at every owned unknown of a vector summed cell by cell (a restricted
        residual), each process holding a part."""
        comm = comm or self.comm
        for other, send, receive in self.neighbours:
            buffer = np.empty(send.size)
            comm.Sendrecv(np.ascontiguousarray(x[receive]), dest=other, recvbuf=buffer, source=other)
            x[send] += buffer
        x[~self.owned] = 0.0

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
        """The whole mesh's connected components of nodes from every slab's own: ``labels
        (n_nodes,)`` int64 labels a component of the slab's nodes by its smallest local node (-1:
        in none), two nodes joined where the slab mesh's cells join them. Components of two slabs
        that share a node are one; as the slab meshes' cells cover the whole mesh's, these are the
        whole mesh's components.

        Returns the smallest global node of every local node's component (-1 where in none),
        ``(n_nodes,)`` int64, and every component of the whole mesh by that node, ascending, with
        its number of nodes: ``roots (m,)`` int64 and ``sizes (m,)`` int64, the same on every
        process (one ``allgather`` of the nodes on the planes two slabs share and of the slab
        components' owned node counts)."""
        comm = comm or self.comm
        inside = labels >= 0
        smallest = np.full(self.n_v, np.iinfo(np.int64).max)  # a slab component's smallest global node
        np.minimum.at(smallest, labels[inside], self.nodes[inside])  # (a ring's: not its first local one)
        ids = np.where(inside, smallest[np.maximum(labels, 0)], -1)
        shared = np.unique(np.concatenate([np.zeros(0, np.int64)] + [
            np.concatenate([send[send < self.n_v], receive[receive < self.n_v]])
            for _, send, receive in self.neighbours]))
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
        """The slab's part of a whole mesh's vector ``[u, p]`` (a copy)."""
        return whole[self.unknowns_of_whole]
