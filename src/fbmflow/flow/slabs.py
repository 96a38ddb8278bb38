"""The flow levels of one process among several: every multigrid level's slab
(:mod:`fbmflow.parallel.slabs`) with its operators, the transfers between the slabs, and the
whole coarsest mesh, which every process holds (:mod:`fbmflow.solvers.distributed`).

The fine mesh is coarsened as for one process (:func:`~fbmflow.flow.levels.coarse_levels`). The
slabs are cut on the fine mesh in whole multiples of ``2^J`` cell layers, so that they stay
slabs of two layers at least on the ``J`` coarser levels; the level below the last slab level is
the coarsest, held whole.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..fem.dofmap import DofMap, PressureDofMap
from ..mesh import StructuredMesh
from ..parallel import SlabPartition, sum_over
from ..parallel.slabs import cut_layers, split_layers
from ..solvers.distributed import SlabLevel
from ..solvers.transfer import prolongation_p1disc, prolongation_q2
from .boundary import DoNothing
from .levels import FlowLevel


class SlabFlowLevels:
    """Process ``comm.rank``'s slabs of the multigrid levels of ``mesh``.

    Parameters
    ----------
    mesh : StructuredMesh, the fine mesh (its last axis not periodic: the slabs' axis)
    boundary : dict, the whole mesh's boundary conditions (:mod:`fbmflow.flow.boundary`)
    pressure_fixed : bool, whether ``int p = 0`` closes the system (a closed domain)
    comm : the processes' communicator
    min_cells : int, the coarsest level keeps at least so many cells

    Attributes
    ----------
    partitions : list of SlabPartition, finest first, the slab levels
    levels : list of FlowLevel, on the slab meshes
    coarsest : FlowLevel, on the whole coarsest mesh
    """

    def __init__(self, mesh: StructuredMesh, boundary: dict, pressure_fixed: bool, comm, min_cells: int = 1):
        size, rank = comm.size, comm.rank
        meshes = [mesh]
        while all(n % 2 == 0 for n in meshes[-1].shape) and meshes[-1].n_cells // 2**mesh.dim >= min_cells:
            try:
                meshes.append(meshes[-1].coarsen())
            except ValueError:
                break
        n_last = mesh.shape[-1]
        deepest = [j for j in range(len(meshes) - 1) if n_last // 2**j >= 2 * size]
        if not deepest:
            raise ValueError(f"{size} processes need two cell layers each on a level above the coarsest; the "
                             f"mesh has {n_last} along its last axis and {len(meshes)} level(s): use at most "
                             f"{max(n_last // 4, 1)} processes or a finer mesh")
        J = deepest[-1]
        bounds = split_layers(n_last, size, 2**J)
        self.comm = comm
        self.partitions = [SlabPartition(meshes[j], size, rank, bounds // 2**j) for j in range(J + 1)]
        self.levels = [FlowLevel(part.mesh, _slab_boundary(boundary, part), pressure_fixed)
                       for part in self.partitions]
        self.coarsest = FlowLevel(meshes[J + 1], boundary, pressure_fixed)
        holders = self.partitions[1:] + [None]
        self.prolongations = [_slab_prolongation(part, meshes[j + 1], holders[j])
                              for j, part in enumerate(self.partitions)]

    def inject(self, u: np.ndarray) -> list[np.ndarray]:
        """A consistent fine velocity ``u`` (local) injected into every coarser level: the slab
        levels' local vectors (consistent) and the whole coarsest mesh's (the same on every
        process)."""
        out = [u]
        for j, part in enumerate(self.partitions[1:] + [None]):
            fine = self.partitions[j]
            coarse_mesh = part.whole if part is not None else self.coarsest.mesh
            d = fine.dim
            n_c = part.n_v if part is not None else self.coarsest.space.n_v
            first = part.nodes[0] if part is not None else 0
            coarse_nodes = np.arange(first, first + n_c)
            fine_nodes = _fine_node(coarse_mesh, coarse_nodes) - fine.nodes[0]
            inside = (fine_nodes >= 0) & (fine_nodes < fine.n_v)
            inside[inside] &= fine.owned_nodes[fine_nodes[inside]]
            v = np.zeros((d, n_c))
            v[:, inside] = out[-1].reshape(d, -1)[:d, fine_nodes[inside]]
            if part is not None:
                local = np.concatenate([v.ravel(), np.zeros(part.n_cells * (d + 1))])
                part.update_ghosts(local, self.comm)
                out.append(local[:d * n_c])
            else:
                out.append(sum_over(v.ravel(), self.comm))
        return out

    def systems(self, u: np.ndarray, m: float, a: float, rho: float, mu: float, convection: bool):
        """The Picard systems ``m rho M + a (mu L + rho N(u))`` of every level at the consistent
        local fine velocity ``u``: the slab levels (:class:`~fbmflow.solvers.distributed.SlabLevel`,
        finest first, their prolongations set) and the whole coarsest mesh's system."""
        velocities = self.inject(u)
        out = []
        for part, level, P, v in zip(self.partitions, self.levels, self.prolongations, velocities):
            system = level.system(v, m, a, rho, mu, convection, newton=False)
            system.prolongation = P
            out.append(SlabLevel(part, system))
        return out, self.coarsest.system(velocities[-1], m, a, rho, mu, convection, newton=False)


def _slab_boundary(boundary: dict, part: SlabPartition) -> dict:
    """The conditions on a slab mesh's faces: the whole mesh's, the faces cut between slabs
    unconstrained (their rows are the neighbours')."""
    tags = part.whole.tags
    local = dict(boundary)
    if part.rank > 0:
        local[tags[-2]] = DoNothing()
    if part.rank < part.size - 1:
        local[tags[-1]] = DoNothing()
    return local


def _node_counts(mesh: StructuredMesh) -> list[int]:
    """Q2 nodes along every axis of ``mesh``."""
    return [2 * n if p else 2 * n + 1 for n, p in zip(mesh.shape, mesh.periodic)]


def _fine_node(coarse: StructuredMesh, nodes: np.ndarray) -> np.ndarray:
    """The next finer mesh's node at every Q2 node ``nodes`` of ``coarse`` (global numbers)."""
    counts = _node_counts(coarse)
    fine = [2 * c if p else 2 * c - 1 for c, p in zip(counts, coarse.periodic)]
    out = np.zeros_like(nodes)
    rest, stride = nodes.copy(), 1
    for c, f in zip(counts, fine):
        out += 2 * (rest % c) * stride
        rest //= c
        stride *= f
    return out


def _slab_prolongation(fine: SlabPartition, coarse_mesh: StructuredMesh, coarse: SlabPartition | None):
    """The scalar Q2 and P1disc prolongations ``(P_v, P_p)`` from the coarser level's local
    vectors (``coarse``'s slab, or the whole ``coarse_mesh`` where None) onto ``fine``'s slab:
    built between the coarse cell layers under the fine slab and their refinement, the rows of
    the fine slab's nodes and cells taken."""
    fa, fb = fine.held
    sa, sb = fa // 2, (fb + 1) // 2
    ca, cb = coarse.held if coarse is not None else (0, coarse_mesh.shape[-1])
    sub = cut_layers(coarse_mesh, sa, sb)
    refined = cut_layers(fine.whole, 2 * sa, 2 * sb)
    P_v = prolongation_q2(DofMap(sub), DofMap(refined))
    P_p = prolongation_p1disc(PressureDofMap(sub), PressureDofMap(refined))
    npl = fine.dim + 1
    fine_plane, coarse_plane = fine.plane, int(np.prod(_node_counts(coarse_mesh)[:-1]))
    fine_layer, coarse_layer = int(np.prod(fine.whole.shape[:-1])), int(np.prod(coarse_mesh.shape[:-1]))
    n_v_c = (2 * (cb - ca) + 1) * coarse_plane
    n_p_c = (cb - ca) * coarse_layer * npl

    def cut(P, row0, n_rows, col0, n_cols):
        P = P.tocsr()[row0:row0 + n_rows]
        return sp.csr_matrix((P.data, P.indices + col0, P.indptr), shape=(n_rows, n_cols))

    return (cut(P_v, 2 * (fa - 2 * sa) * fine_plane, fine.n_v, 2 * (sa - ca) * coarse_plane, n_v_c),
            cut(P_p, (fa - 2 * sa) * fine_layer * npl, fine.n_cells * npl, (sa - ca) * coarse_layer * npl,
                n_p_c))

