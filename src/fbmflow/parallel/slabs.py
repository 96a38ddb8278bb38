"""A structured mesh split into slabs of cell layers along its last axis, one per process.

Process ``r`` of ``P`` owns the cell layers ``[a_r, b_r)`` (the layers split as evenly as they
go) and every Q2 node of its cells: the node planes ``2 a_r`` to ``2 b_r`` of the lattice
(:mod:`fbmflow.fem.dofmap`: node ``I + L_x (J + L_y K)``, so a process's nodes are one run of
global numbers). Neighbouring slabs share one node plane. An operator applied cell by cell on a
slab's own mesh gives, at a shared node, the part of its cells;
:meth:`~fbmflow.parallel.slabs.SlabPartition.sum_shared` adds the neighbour's part, exchanged
with that neighbour only, and then every process holds the whole operator's value at each of its
nodes. A shared node belongs to the lower slab in sums over nodes
(:meth:`~fbmflow.parallel.slabs.SlabPartition.dot`), so that each node counts once. A cell reads
only its own nodes, so no halo cells are needed for these products; the smoother's patches will
need them.
"""
from __future__ import annotations

import numpy as np

from ..mesh import StructuredMesh


class SlabPartition:
    """Process ``rank``'s slab of ``mesh`` among ``size`` processes.

    Parameters
    ----------
    mesh : StructuredMesh, 2D or 3D, not periodic along its last axis
    size, rank : int, the number of processes and this one's rank (0-based)

    Attributes
    ----------
    layers : (int, int), the owned cell layers ``[a, b)`` along the last axis
    mesh : StructuredMesh, the slab's own mesh (its cells are the global cells ``cells``, in
        order; its vertices the global ones)
    cells : (n_cells,) int64, the slab's global cells
    nodes : (n_nodes,) int64, the global Q2 node of every slab node (one run of numbers)
    plane : int, Q2 nodes per lattice plane normal to the last axis (the shared ones)
    """

    def __init__(self, mesh: StructuredMesh, size: int, rank: int):
        n_last = mesh.shape[-1]
        if mesh.periodic[-1]:
            raise ValueError("slabs need a last axis that is not periodic; periodic axes may come first")
        if not 1 <= size <= n_last:
            raise ValueError(f"{size} processes need at least as many cell layers along the last axis, "
                             f"the mesh has {n_last}: use fewer processes or a finer mesh")
        if not 0 <= rank < size:
            raise ValueError(f"rank {rank} is not one of {size} processes")
        self.size, self.rank = size, rank
        bounds = np.linspace(0, n_last, size + 1).round().astype(int)
        a, b = int(bounds[rank]), int(bounds[rank + 1])
        self.layers = (a, b)
        per_layer = int(np.prod(mesh.shape[:-1]))
        self.cells = np.arange(a * per_layer, b * per_layer, dtype=np.int64)
        vertex_plane = int(np.prod([n + 1 for n in mesh.shape[:-1]]))
        vertices = mesh.vertices[a * vertex_plane:(b + 1) * vertex_plane]
        shape = mesh.shape[:-1] + (b - a,)
        lower = mesh.lower[:-1] + (float(vertices[:, -1].min()),)
        upper = mesh.upper[:-1] + (float(vertices[:, -1].max()),)
        self.mesh = StructuredMesh(shape, lower, upper, mesh.periodic, vertices.copy())
        self.plane = int(np.prod([2 * n if p else 2 * n + 1
                                  for n, p in zip(mesh.shape[:-1], mesh.periodic[:-1])]))
        self.nodes = np.arange(2 * a * self.plane, (2 * b + 1) * self.plane, dtype=np.int64)

    @property
    def owned(self) -> np.ndarray:
        """(n_nodes,) bool: the slab nodes this process counts in sums over nodes (all but the
        plane it shares with the slab below)."""
        own = np.ones(self.nodes.size, dtype=bool)
        if self.rank > 0:
            own[:self.plane] = False
        return own

    def sum_shared(self, values: np.ndarray, comm) -> None:
        """Add the neighbours' parts at the shared node planes to ``values`` (k, n_nodes) float64,
        in place: one exchange with each neighbour (``comm``: an mpi4py communicator, or anything
        with its ``Sendrecv``), in two rounds whatever the number of processes (even ranks with
        the slab above first, odd ones with the slab below first). The lower slab's part is added
        first on both sides, so the two copies of a shared node hold the same bits."""
        p = self.plane
        lower = np.ascontiguousarray(values[:, :p]) if self.rank > 0 else None
        upper = np.ascontiguousarray(values[:, -p:]) if self.rank < self.size - 1 else None
        rounds = [(upper, self.rank + 1), (lower, self.rank - 1)]
        received = {}
        for mine, other in rounds if self.rank % 2 == 0 else rounds[::-1]:
            if mine is not None:
                received[other] = np.empty_like(mine)
                comm.Sendrecv(mine, dest=other, recvbuf=received[other], source=other)
        if lower is not None:
            values[:, :p] = received[self.rank - 1] + lower
        if upper is not None:
            values[:, -p:] = upper + received[self.rank + 1]

    def dot(self, x: np.ndarray, y: np.ndarray, comm) -> float:
        """``sum x y`` over all nodes of the mesh, each once, for slab vectors ``x, y`` (k, n_nodes)
        (one reduction)."""
        own = self.owned
        return float(comm.allreduce(float(np.sum(x[:, own] * y[:, own]))))
