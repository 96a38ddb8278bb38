"""Particles on the mesh: the owner of every Q2 velocity node and the fictitious-boundary
constraints ``u = U_i + omega_i x (x - X_i)`` on the nodes inside particle ``i``.

The candidate nodes of a particle come from its bounding box turned into lattice index ranges of
the structured mesh (no search over all nodes); only they get the inside test.
"""
from __future__ import annotations

import numpy as np

from ..fem.constraints import DirichletConstraints
from ..fem.dofmap import DofMap


def candidate_dofs(V: DofMap, centre: np.ndarray, radius: float) -> np.ndarray:
    """Q2 nodes of the box ``centre +- radius`` on an undeformed mesh, (n,) int64.

    Periodic axes wrap around (a particle crossing a periodic side finds its nodes on both sides).
    """
    mesh = V.mesh
    step = mesh.spacing / 2.0
    lo = np.floor((centre - radius - np.array(mesh.lower)) / step).astype(np.int64)
    hi = np.ceil((centre + radius - np.array(mesh.lower)) / step).astype(np.int64)
    ranges = []
    for d in range(mesh.dim):
        if mesh.periodic[d]:
            r = np.arange(lo[d], hi[d] + 1) % V.lattice_shape[d]
            ranges.append(np.unique(r))
        else:
            ranges.append(np.arange(max(lo[d], 0), min(hi[d], V.lattice_shape[d] - 1) + 1))
    if any(r.size == 0 for r in ranges):
        return np.zeros(0, dtype=np.int64)
    grids = np.meshgrid(*ranges, indexing="ij")
    lat = np.stack([g.ravel() for g in grids], axis=1)
    return V._lattice_to_dof(lat)


def periodic_offset(V: DofMap, x: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """``x - centre`` with the minimum-image convention on periodic axes, (n, dim)."""
    rel = x - centre
    mesh = V.mesh
    for d in range(mesh.dim):
        if mesh.periodic[d]:
            L = mesh.upper[d] - mesh.lower[d]
            rel[:, d] -= L * np.round(rel[:, d] / L)
    return rel


def node_owner(V: DofMap, centres: np.ndarray, shapes: list, rotations: np.ndarray | None = None) -> np.ndarray:
    """Particle owning every Q2 node (-1: fluid), (n_dofs,) int64.

    Parameters
    ----------
    centres : (n_particles, dim) float64, centres of mass
    shapes : list of shapes with ``inside`` and ``bounding_radius``
    rotations : (n_particles, dim, dim) float64, body-to-world rotations (identity if omitted)
    """
    if not V.mesh.is_uniform:
        raise NotImplementedError("fictitious boundaries need an undeformed mesh for now")
    owner = np.full(V.n_dofs, -1, dtype=np.int64)
    for i, (centre, shape) in enumerate(zip(centres, shapes)):
        dofs = candidate_dofs(V, centre, shape.bounding_radius)
        rel = periodic_offset(V, V.coordinates[dofs], centre)
        if rotations is not None:
            rel = rel @ rotations[i]  # world -> body: R^T x, row-wise
        inside = dofs[shape.inside(rel)]
        owner[inside[owner[inside] < 0]] = i
    return owner


def rigid_body_constraints(V: DofMap, owner: np.ndarray, centres: np.ndarray, velocities: np.ndarray,
                           angular: np.ndarray) -> DirichletConstraints:
    """Constraints ``u = U_i + omega_i x (x - X_i)`` on every node owned by a particle.

    ``velocities (n_particles, dim)``; ``angular (n_particles,)`` in 2D (rotation rate about z) or
    ``(n_particles, 3)`` in 3D.
    """
    nodes = np.flatnonzero(owner >= 0)
    pid = owner[nodes]
    dim, n = V.mesh.dim, V.n_dofs
    rel = np.empty((nodes.size, dim))
    for i in np.unique(pid):
        sel = pid == i
        rel[sel] = periodic_offset(V, V.coordinates[nodes[sel]], centres[i])
    vel = velocities[pid].astype(float).copy()
    if dim == 2:
        w = np.asarray(angular, dtype=float).reshape(-1)[pid]
        vel[:, 0] -= w * rel[:, 1]
        vel[:, 1] += w * rel[:, 0]
    else:
        vel += np.cross(np.asarray(angular, dtype=float)[pid], rel)
    dofs = np.concatenate([k * n + nodes for k in range(dim)])
    order = np.argsort(dofs)
    return DirichletConstraints(dofs[order], vel.T.ravel()[order])
