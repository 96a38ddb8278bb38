"""Hydrodynamic forces and torques on fictitious-boundary particles: the volume integral over the
cells cut by each particle, and, for steady flows past bodies at rest, the integral against a test
function that is one on the body and falls to zero within the next layer of cells."""
from __future__ import annotations

import numpy as np

from ..fem.quadrature import gauss_tensor
from ..fem.space import FlowSpace
from . import _kernels


def cut_cells(space: FlowSpace, owner: np.ndarray) -> np.ndarray:
    """Cells whose nodes are not all owned by one and the same particle but some are owned:
    (n_cut,) int64."""
    o = owner[space.V.cell_dofs]
    return np.flatnonzero((o.max(axis=1) >= 0) & (o.min(axis=1) != o.max(axis=1)))


def hydrodynamic_forces(space: FlowSpace, owner: np.ndarray, centres: np.ndarray, u: np.ndarray,
                        p: np.ndarray, mu: float):
    """Force (n_particles, dim) [N] and torque (n_particles, 3) [N m] from the flow ``u (dim * n_v,)``,
    ``p (n_p,)`` with dynamic viscosity ``mu``; periodic minimum images are not applied to the
    torque arm (particles must not straddle a periodic side)."""
    cells = cut_cells(space, owner)
    d = space.dim
    return _kernels.fbm_force_torque(cells, owner, len(centres), np.asarray(centres, dtype=float),
                                     np.ascontiguousarray(u.reshape(d, space.n_v)), p, mu,
                                     space.V.cell_dofs, space.phi, space.dphi, space.detJw,
                                     space.Jinv, space.psi, space.xq)


def mirror_images(force: np.ndarray, torque: np.ndarray, axes) -> tuple[np.ndarray, np.ndarray]:
    """Force and torque of whole particles cut by symmetry planes through their centres.

    ``axes``: the normal axis of every mirror plane (e.g. ``(0, 1)`` for a quarter domain cut by
    the planes x = X and y = Y). The mirror image across the plane with normal ``a`` flips the
    ``a`` component of the force and, the torque being a pseudo-vector, every other component of
    the torque; the whole particle gets the sum of all images. ``force (n, dim)``,
    ``torque (n, 3)``; returns new arrays.
    """
    F, T = np.array(force, dtype=float), np.array(torque, dtype=float)
    for a in axes:
        flip_f = np.ones(F.shape[1])
        flip_f[a] = -1.0
        flip_t = -np.ones(3)
        flip_t[a] = 1.0
        F, T = F + F * flip_f, T + T * flip_t
    return F, T


def steady_test_function_forces(space: FlowSpace, owner: np.ndarray, centres: np.ndarray, shapes: list,
                                u: np.ndarray, p: np.ndarray, mu: float, rho: float,
                                fixed: np.ndarray | None = None, n_1d: int = 8):
    """Force (n, dim) and torque (n, 3) on bodies at rest in a steady flow,

        F_i = -int_fluid [rho ((u . grad) u) psi_i + sigma grad psi_i] dx,
        T_i = -int_fluid (x - X_i) x [rho ((u . grad) u) psi_i + sigma grad psi_i] dx,

    the momentum balance tested with ``psi_i e`` (exact for the continuous flow whenever
    ``psi_i`` is one on body ``i``'s surface and zero on every other wall; Schaefer & Turek's
    volume integral). ``psi_i`` is the Q2 function that is one on the nodes of every cell with a
    node of body ``i`` and zero elsewhere and on the ``fixed`` nodes (walls, ``(k,)`` int64) that
    ``i`` does not own, so its gradient lies in the fluid cells around the cut cells, where the
    flow is resolved, rather than in the cut cells themselves (with the sharp boundary the
    cut-cell volume force converges to first order only). The fluid part of the cells is found
    with the shapes' inside test on a Gauss rule of ``n_1d`` points per axis (axis-aligned
    cells of a tensor-product mesh). Bodies at rest, unrotated; ``u (dim n_v,)``, ``p (n_p,)``.
    """
    V, mesh, d = space.V, space.mesh, space.dim
    n_v, cd = V.n_dofs, V.cell_dofs
    xi, w = gauss_tensor(d, n_1d)
    phi, dphi = V.element.tabulate(xi)
    uu = u.reshape(d, n_v)
    force, torque = np.zeros((len(shapes), d)), np.zeros((len(shapes), 3))
    for i, shape in enumerate(shapes):
        psi_nodes = np.zeros(n_v)
        psi_nodes[np.unique(cd[(owner[cd] == i).any(axis=1)])] = 1.0
        if fixed is not None:
            psi_nodes[fixed[owner[fixed] != i]] = 0.0
        pc = psi_nodes[cd]
        cells = np.flatnonzero(pc.max(axis=1) > 0)
        corners = mesh.vertices[mesh.cell_vertices[cells]]
        lo, h = corners.min(axis=1), corners.max(axis=1) - corners.min(axis=1)
        x = lo[:, None, :] + 0.5 * (xi[None, :, :] + 1.0) * h[:, None, :]       # (n_c, nq, d)
        rel = x - centres[i]
        fluid = ~shape.inside(rel.reshape(-1, d)).reshape(rel.shape[:2])
        grad_phi = dphi[None, :, :, :] * (2.0 / h)[:, None, None, :]            # (n_c, nq, nl, d)
        ul = uu[:, cd[cells]]                                                     # (d, n_c, nl)
        uq = np.einsum("jca,qa->cqj", ul, phi)
        gu = np.einsum("jca,cqak->cqjk", ul, grad_phi)                            # d u_j / d x_k
        psi_q = np.einsum("ca,qa->cq", pc[cells], phi)
        gpsi = np.einsum("ca,cqak->cqk", pc[cells], grad_phi)
        pl = p.reshape(-1, d + 1)[cells]
        pq = pl[:, None, 0] + np.einsum("cl,ql->cq", pl[:, 1:], xi)               # P1disc, axis-aligned
        sigma = mu * (gu + np.swapaxes(gu, 2, 3))
        sigma[..., np.arange(d), np.arange(d)] -= pq[..., None]
        f = rho * np.einsum("cqjk,cqk->cqj", gu, uq) * psi_q[..., None] + np.einsum("cqjk,cqk->cqj", sigma, gpsi)
        weight = fluid * w[None, :] * np.prod(0.5 * h, axis=1)[:, None]
        force[i] = -np.einsum("cqj,cq->j", f, weight)
        if d == 2:
            torque[i, 2] = -np.sum(weight * (rel[..., 0] * f[..., 1] - rel[..., 1] * f[..., 0]))
        else:
            torque[i] = -np.einsum("cqj,cq->j", np.cross(rel, f), weight)
    return force, torque
