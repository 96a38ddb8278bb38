"""Particles on the mesh: the owner of every Q2 velocity node and the fictitious-boundary
constraints ``u = U_i + omega_i x (x - X_i)`` on the nodes inside particle ``i``.

The candidate nodes of a particle come from its bounding box turned into lattice index ranges of
the structured mesh (no search over all nodes); only they get the inside test.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..fem.constraints import DirichletConstraints
from ..fem.dofmap import DofMap


def candidate_dofs(V: DofMap, centres: np.ndarray, radii: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Q2 nodes of the boxes ``centres[i] +- radii[i]`` on a tensor-product (uniform or
    rectilinear) mesh: (particle (k,), node (k,)) int64, every particle's nodes once, the box
    widened to the enclosing nodes. All boxes at once, no loop over particles.

    Periodic axes (uniform) wrap around (a particle crossing a periodic side finds its nodes on
    both sides). On a piece of a periodic mesh (:attr:`~fbmflow.mesh.structured.StructuredMesh.images`)
    every particle's images one period either side are looked at too (a node may then come twice
    for one particle, and a few nodes at the piece's ends that no image reaches come as well:
    the inside test sorts them out).
    """
    mesh = V.mesh
    centres = np.atleast_2d(np.asarray(centres, dtype=float))
    radii = np.broadcast_to(np.asarray(radii, dtype=float), (len(centres),))
    shape = np.array(V.lattice_shape)
    periodic = np.array(mesh.periodic)
    index = np.arange(len(centres))  # the particle of every box
    images = np.flatnonzero((mesh.periods > 0) & ~periodic)
    if images.size:
        shifts = np.stack(np.meshgrid(*[[-1.0, 0.0, 1.0]] * images.size, indexing="ij"), -1)
        shifts = shifts.reshape(-1, images.size)
        index = np.tile(index, len(shifts))
        centres = centres[index]
        centres[:, images] += np.repeat(shifts, len(radii), axis=0) * mesh.periods[images]
        radii = radii[index]
    lo = np.empty(centres.shape, dtype=np.int64)
    hi = np.empty(centres.shape, dtype=np.int64)
    for d, nodes in enumerate(V.lattice_axes):  # per axis, all particles at once
        a, b = centres[:, d] - radii, centres[:, d] + radii
        if periodic[d]:
            step = nodes[1] - nodes[0]
            lo[:, d] = np.floor((a - nodes[0]) / step)
            hi[:, d] = np.minimum(np.ceil((b - nodes[0]) / step), lo[:, d] + shape[d] - 1)
        else:
            lo[:, d] = np.maximum(np.searchsorted(nodes, a, side="right") - 1, 0)
            hi[:, d] = np.minimum(np.searchsorted(nodes, b, side="left"), shape[d] - 1)
    count = np.maximum(hi - lo + 1, 0)                       # (n, dim) lattice points per axis
    total = np.prod(count, axis=1)
    part = np.repeat(np.arange(len(centres)), total)
    local = np.arange(total.sum()) - np.repeat(np.cumsum(total) - total, total)
    lat = np.empty((len(part), mesh.dim), dtype=np.int64)
    for d in reversed(range(mesh.dim)):                       # row-major offsets within each box
        c = count[part, d]
        lat[:, d] = lo[part, d] + local % c
        local //= c
    lat = np.where(periodic, lat % shape, lat)
    return index[part], V._lattice_to_dof(lat)


def periodic_offset(V: DofMap, x: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """``x - centre`` (``x (..., dim)``, ``centre`` broadcasting to it) with the minimum-image
    convention on periodic axes, (..., dim) float64: ``(x - k L) - centre``, the image of ``x``
    taken first, so that a point of a slab moved by the period (a ring of slabs' halo,
    :attr:`~fbmflow.mesh.structured.StructuredMesh.images`) gives the whole mesh's offset to the
    bit wherever the move was exact (measured: with ``x - centre - k L`` a halo node exactly on
    the surface of a disk at (0.7, 0.1) across the periodic sides was outside on the slab and
    inside on the whole mesh, and the solves on two processes stalled at a residual reduction of
    4e-6)."""
    rel = x - centre
    L = V.mesh.periods
    for d in np.flatnonzero(L):
        k = np.round(rel[..., d] / L[d])
        rel[..., d] = (x[..., d] - k * L[d]) - np.broadcast_to(centre, x.shape)[..., d]
    return rel


def node_owner(V: DofMap, centres: np.ndarray, shapes: list,
               rotations: np.ndarray | None = None) -> np.ndarray:
    """Particle owning every Q2 node (-1: fluid; the lowest index where particles overlap),
    (n_dofs,) int64. Candidate nodes of all particles at once; one vectorised inside test per
    distinct shape object.

    Parameters
    ----------
    centres : (n_particles, dim) float64, centres of mass
    shapes : list of shapes with ``inside`` and ``bounding_radius``
    rotations : (n_particles, dim, dim) float64, body-to-world rotations (identity if omitted)
    """
    if V.mesh.axis_coordinates is None:
        raise NotImplementedError("fictitious boundaries need a tensor-product (uniform or rectilinear) "
                                  "mesh; point location on a deformed mesh is not implemented")
    owner = np.full(V.n_dofs, -1, dtype=np.int64)
    group = np.unique(np.array([id(s) for s in shapes], dtype=np.int64), return_inverse=True)[1]
    first = [shapes[k] for k in np.unique(group, return_index=True)[1]]
    radii = np.array([s.bounding_radius for s in first])[group]
    part, dofs = candidate_dofs(V, centres, radii)
    rel = periodic_offset(V, V.coordinates[dofs], centres[part])
    if rotations is not None:
        rel = np.einsum("kd,kde->ke", rel, rotations[part])  # world -> body: R^T x, row-wise
    inside = np.zeros(len(dofs), dtype=bool)
    for g, shape in enumerate(first):
        rows = np.flatnonzero(group[part] == g)
        inside[rows] = shape.inside(rel[rows])
    part, dofs = part[inside], dofs[inside]
    order = np.lexsort((part, dofs))
    dofs, part = dofs[order], part[order]
    lead = np.ones(len(dofs), dtype=bool)
    lead[1:] = dofs[1:] != dofs[:-1]
    owner[dofs[lead]] = part[lead]
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
    rel = periodic_offset(V, V.coordinates[nodes], np.asarray(centres, dtype=float)[pid])
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


def rigid_liftings(V: DofMap, owner: np.ndarray, centres: np.ndarray, free: np.ndarray) -> sp.csc_matrix:
    """Unit rigid motions of the particles on their nodes: (dim * n_v, k) sparse, one column per
    True entry of ``free (n_particles, r)`` (row-major; ``r = 3`` in 2D: ``U_x, U_y, omega_z``;
    6 in 3D: ``U, omega``), the velocity field ``e_b`` or ``e_b x (x - X_i)`` on the nodes owned by
    particle ``i`` and zero elsewhere. Built for all particles at once."""
    nodes = np.flatnonzero(owner >= 0)
    pid = owner[nodes]
    dim, n = V.mesh.dim, V.n_dofs
    rel = periodic_offset(V, V.coordinates[nodes], np.asarray(centres, dtype=float)[pid])
    column = np.full(free.shape, -1, dtype=np.int64)
    column[free] = np.arange(int(free.sum()))
    rows, cols, vals = [], [], []
    for b in range(free.shape[1]):  # the r rigid motions, each for every particle at once
        sel = free[pid, b]
        motion = np.zeros((int(sel.sum()), dim))
        if b < dim:
            motion[:, b] = 1.0
        elif dim == 2:
            motion[:, 0], motion[:, 1] = -rel[sel, 1], rel[sel, 0]
        else:
            axis = np.zeros(3)
            axis[b - dim] = 1.0
            motion = np.cross(axis, rel[sel])
        for a in range(dim):
            nz = motion[:, a] != 0.0
            rows.append(a * n + nodes[sel][nz])
            cols.append(column[pid[sel][nz], b])
            vals.append(motion[nz, a])
    return sp.csc_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                         shape=(dim * n, int(free.sum())))
