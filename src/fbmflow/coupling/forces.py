"""Hydrodynamic forces and torques on fictitious-boundary particles: the volume integral over the
cells cut by each particle, the momentum balance tested with a function that is one on the
particle and falls to zero within the next layer of cells, and the traction integrated over the
true surface of balls (with the sharp boundary)."""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..fem.functions import locate
from ..fem.quadrature import gauss_tensor
from ..fem.space import FlowSpace
from ..particles import Ball
from . import _kernels
from .indicator import periodic_offset


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


class TestFunctionForces:
    """Force and torque on particles from the momentum balance tested with ``psi_i e``:

        F_i = -int_fluid [rho (du/dt + (u . grad) u) psi_i + sigma grad psi_i] dx,
        T_i = -int_fluid (x - X_i) x [rho (du/dt + (u . grad) u) psi_i + sigma grad psi_i] dx,

    ``sigma = -p I + mu (grad u + grad u^T)``. For the continuous flow this is exactly the surface
    force whenever ``psi_i`` is one on particle ``i``'s surface and zero on the walls and the other
    particles (Schaefer & Turek's volume integral; the body force is absent, gravity acting on
    the particles as buoyancy). ``psi_i`` is the Q2 function that is one on the nodes of every
    cell with a node of particle ``i`` and zero elsewhere, on the ``walls`` and on the other
    particles' nodes, so its gradient lies in the fluid cells around the cut cells, where the flow
    is resolved, rather than in the cut cells themselves (with the sharp boundary the cut-cell
    volume force converges to first order only). The fluid part of the cells is found with the
    shapes' inside test on a Gauss rule of ``n_1d`` points per axis (tensor-product meshes).

    ``du/dt`` is ``(u - u_old) / dt`` (the step's mean acceleration; omitted for a steady flow).
    Built once per particle state, all particles together: (cell, particle) pairs, one
    vectorised inside test per distinct shape object.

    Parameters
    ----------
    space : FlowSpace
    owner : (n_v,) int64, the particle of every velocity node (-1: fluid)
    centres : (n, dim) float64
    shapes : list of n shapes with ``inside``
    rotations : (n, dim, dim) float64, body-to-world (identity if None)
    walls : (k,) int64, velocity nodes held by the domain's walls (zero in every ``psi_i``)
    n_1d : Gauss points per axis of the fluid-part rule
    """

    def __init__(self, space: FlowSpace, owner: np.ndarray, centres: np.ndarray, shapes: list,
                 rotations: np.ndarray | None = None, walls: np.ndarray | None = None, n_1d: int = 8):
        V = space.V
        cd, n_v, n_b = V.cell_dofs, V.n_dofs, len(shapes)
        n_cells, nl = cd.shape
        cell_node = sp.csr_matrix((np.ones(cd.size), cd.ravel(), np.arange(0, cd.size + 1, nl)),
                                  shape=(n_cells, n_v))
        own = owner[cd]
        c, a = np.nonzero(own >= 0)
        core = sp.csr_matrix((np.ones(c.size), (c, own[c, a])), shape=(n_cells, n_b))
        psi = (cell_node.T @ core).tocoo()                       # nodes of the particles' cells
        blocked = np.zeros(n_v, dtype=bool)
        if walls is not None:
            blocked[walls] = True
        keep = (owner[psi.row] == psi.col) | (~blocked[psi.row] & (owner[psi.row] < 0))
        psi_nodes = sp.csr_matrix((np.ones(keep.sum()), (psi.row[keep], psi.col[keep])), shape=(n_v, n_b))
        pairs = (cell_node @ psi_nodes).tocoo()                  # cells where psi_i is not zero
        cells, body = pairs.row.astype(np.int64), pairs.col.astype(np.int64)
        self._quadrature(space, cells, body, centres, shapes, rotations, n_1d)
        pc = np.asarray(psi_nodes[self.nodes.ravel(), np.repeat(body, nl)]).reshape(self.nodes.shape)
        self.psi_q = pc @ self.phi.T                                            # (m, nq)
        self.grad_psi = np.einsum("ca,cqak->cqk", pc, self.grad_phi)

    def _quadrature(self, space: FlowSpace, cells: np.ndarray, body: np.ndarray, centres: np.ndarray,
                    shapes: list, rotations: np.ndarray | None, n_1d: int) -> None:
        """The fluid-part Gauss rule of ``n_1d`` points per axis on the (cell, particle) pairs
        ``cells, body (m,)``: points ``x`` (m, nq, dim) as offsets ``rel`` from the particle's
        centre, weights (zero inside any tested shape), Q2 basis values and gradients, P1disc
        basis values. The test function itself (``psi_q``, ``grad_psi``) is the caller's."""
        V, mesh, d = space.V, space.mesh, space.dim
        self.cells, self.body = cells, body
        self.nodes = V.cell_dofs[cells]
        xi, w = gauss_tensor(d, n_1d)
        self.phi, dphi = V.element.tabulate(xi)
        corners = mesh.vertices[mesh.cell_vertices[cells]]
        lo, h = corners.min(axis=1), corners.max(axis=1) - corners.min(axis=1)
        x = lo[:, None, :] + 0.5 * (xi[None, :, :] + 1.0) * h[:, None, :]       # (m, nq, d)
        rel = periodic_offset(V, x.reshape(-1, d), np.repeat(centres[body], len(w), axis=0))
        body_rel = rel if rotations is None else \
            np.einsum("kd,kde->ke", rel, np.repeat(rotations[body], len(w), axis=0))  # world -> body
        self.rel = rel.reshape(x.shape)                                          # (m, nq, d)
        fluid = np.ones(body_rel.shape[0], dtype=bool)
        group = np.unique(np.array([id(s) for s in shapes], dtype=np.int64), return_inverse=True)[1]
        point_group = np.repeat(group[body], len(w))
        for g, k in enumerate(np.unique(group, return_index=True)[1]):
            rows = np.flatnonzero(point_group == g)
            fluid[rows] = ~shapes[k].inside(body_rel[rows])
        self.weight = fluid.reshape(x.shape[:2]) * w[None, :] * np.prod(0.5 * h, axis=1)[:, None]
        self.grad_phi = dphi[None, :, :, :] * (2.0 / h)[:, None, None, :]       # (m, nq, nl, d)
        Q = space.Q
        self.pressure_basis = Q.element.tabulate(x, Q.centre[cells][:, None, :], Q.scale[cells][:, None, :])
        self.n_particles, self.dim, self.n_v = len(shapes), d, V.n_dofs

    def _velocity(self, u: np.ndarray):
        """Values (m, nq, d) and gradients (m, nq, d, d) (``d u_j / d x_k``) of ``u (dim n_v,)``."""
        ul = u.reshape(self.dim, self.n_v)[:, self.nodes]                         # (d, m, nl)
        return np.einsum("jca,qa->cqj", ul, self.phi), np.einsum("jca,cqak->cqjk", ul, self.grad_phi)

    def __call__(self, u: np.ndarray, p: np.ndarray, mu: float, rho: float, u_old: np.ndarray | None = None,
                 dt: float | None = None, about: np.ndarray | None = None):
        """Force (n, dim) [N] and torque (n, 3) [N m] of the flow ``u (dim n_v,)``, ``p (n_p,)``.

        ``u_old`` and ``dt``: the step's start velocity and length (du/dt = (u - u_old) / dt).
        ``about``: the velocity of a flow to linearise about; ``u, p`` are then a change of it
        (``du, dp``) and the result the change of the force, with ``du / dt`` for the time
        derivative and ``(about . grad) du + (du . grad) about`` for the convection.
        """
        uq, gu = self._velocity(u)
        if about is None:
            accel = np.einsum("cqjk,cqk->cqj", gu, uq)
            if u_old is not None:
                accel += (uq - self._velocity(u_old)[0]) / dt
        else:
            aq, ga = self._velocity(about)
            accel = np.einsum("cqjk,cqk->cqj", gu, aq) + np.einsum("cqjk,cqk->cqj", ga, uq)
            if dt is not None:
                accel += uq / dt
        d = self.dim
        pq = np.einsum("cqm,cm->cq", self.pressure_basis, p.reshape(-1, d + 1)[self.cells])
        sigma = mu * (gu + np.swapaxes(gu, 2, 3))
        sigma[..., np.arange(d), np.arange(d)] -= pq[..., None]
        f = -(rho * accel * self.psi_q[..., None] + np.einsum("cqjk,cqk->cqj", sigma, self.grad_psi))
        f *= self.weight[..., None]
        force = np.zeros((self.n_particles, d))
        np.add.at(force, self.body, f.sum(axis=1))
        r = self.rel
        if d == 2:
            t = np.zeros((len(self.cells), 3))
            t[:, 2] = np.sum(r[..., 0] * f[..., 1] - r[..., 1] * f[..., 0], axis=1)
        else:
            t = np.cross(r, f).sum(axis=1)
        torque = np.zeros((self.n_particles, 3))
        np.add.at(torque, self.body, t)
        return force, torque


def supports_surface_force(shapes) -> bool:
    """True when every shape is a ball (disk or sphere), whose surface :class:`SurfaceForces`
    integrates over."""
    return all(isinstance(s, Ball) for s in shapes)


class SurfaceForces:
    """Force and torque on balls as the traction integrated over their true surfaces:

        F_i = int_{S_i} sigma n dS,     T_i = int_{S_i} (x - X_i) x sigma n dS,

    ``sigma = -p I + mu (grad u + grad u^T)`` of the discrete flow at points on the surface. With
    the sharp boundary (:mod:`fbmflow.coupling.sharp`) the cells the surface cuts carry the flow
    continued through it (ghost nodes) and the pressure continued from a fluid cell, so the
    stress there is the resolved flow's own, taken where the no-slip condition holds. Rule: in
    3D Gauss–Legendre in ``cos(theta)`` times the trapezoidal rule in ``phi``, in 2D the
    trapezoidal rule, with ``points_per_cell`` points per finest cell length along a great
    circle (the same unit rule for every ball, scaled by its radius; ``phi`` offset by half a
    step so that no point lies on a mirror plane through the centre). Surface points outside the
    mesh box are left out: the parts beyond mirror planes through the centre come back with
    :func:`mirror_images`; periodic axes wrap. Built once per particle state; linear in ``(u, p)``
    (tensor-product meshes).

    Measured (Stokes flow through a cubic array of spheres with exact drag,
    ``benchmarks/bench_sphere_array.py``): error +2.5 / -0.6 / +0.5 / +0.3 / -0.2 % at 4 / 6 / 8 /
    12 / 16 cells per diameter, against +6.1 / +3.2 / +3.0 / +1.9 / +1.2 % for the cut-cell
    volume force and -21 / -13 / -8.3 / -6.1 / -3.9 % for the tested momentum balance.

    Parameters
    ----------
    space : FlowSpace
    centres : (n, dim) float64, ball centres [m]
    shapes : list of n :class:`~fbmflow.particles.Ball`
    points_per_cell : int, default 4
    """

    def __init__(self, space: FlowSpace, centres: np.ndarray, shapes: list, points_per_cell: int = 4):
        if not supports_surface_force(shapes):
            raise ValueError("the surface force integrates over balls (disks, spheres) only; use the volume "
                             "force for other shapes")
        mesh, dim = space.mesh, space.dim
        centres = np.atleast_2d(np.asarray(centres, dtype=float))
        radius = np.array([s.radius for s in shapes])
        h = float(mesh.finest_spacing.min())
        per_circle = 4 * int(np.ceil(points_per_cell * 2 * np.pi * radius.max() / h / 4))
        phi = (np.arange(per_circle) + 0.5) * 2 * np.pi / per_circle
        if dim == 2:
            unit = np.column_stack([np.cos(phi), np.sin(phi)])
            w_unit = np.full(per_circle, 2 * np.pi / per_circle)
        else:
            c, wc = np.polynomial.legendre.leggauss(per_circle // 2)
            C, P = np.meshgrid(c, phi, indexing="ij")
            S = np.sqrt(1 - C**2)
            unit = np.stack([S * np.cos(P), S * np.sin(P), C], -1).reshape(-1, 3)
            w_unit = np.outer(wc, np.full(per_circle, 2 * np.pi / per_circle)).ravel()
        n_pts = len(unit)
        particle = np.repeat(np.arange(len(shapes)), n_pts)
        normal = np.tile(unit, (len(shapes), 1))
        arm = radius[particle, None] * normal
        weight = np.tile(w_unit, len(shapes)) * radius[particle] ** (dim - 1)
        x = centres[particle] + arm
        lower, upper = np.array(mesh.lower), np.array(mesh.upper)
        for d in np.flatnonzero(mesh.periodic):
            x[:, d] = lower[d] + np.mod(x[:, d] - lower[d], upper[d] - lower[d])
        keep = np.all((x >= lower) & (x <= upper), axis=1)
        x, self.particle, self.normal = x[keep], particle[keep], normal[keep]
        self.arm, self.weight = arm[keep], weight[keep]
        self.n_particles, self.space = len(shapes), space
        self.cells, xi = locate(mesh, x)
        _, dphi = space.V.element.tabulate(xi)
        half = space.Q.scale[self.cells]  # the cells' half extents (tensor-product cells)
        self.dphi = dphi / half[:, None, :]  # physical gradients (n, n_local, dim)
        self.psi = space.Q.element.tabulate(x, space.Q.centre[self.cells], space.Q.scale[self.cells])

    def __call__(self, u: np.ndarray, p: np.ndarray, mu: float) -> tuple[np.ndarray, np.ndarray]:
        """Force (n, dim) [N] and torque (n, 3) [N m] of the flow ``u (dim n_v,)``, ``p (n_p,)``."""
        space, dim = self.space, self.space.dim
        local = u.reshape(dim, space.n_v)[:, space.V.cell_dofs[self.cells]]  # (dim, n, n_local)
        grad = np.einsum("ina,nad->nid", local, self.dphi)  # du_i / dx_d
        pressure = np.einsum("nm,nm->n", p.reshape(-1, dim + 1)[self.cells], self.psi)
        strain = grad + grad.transpose(0, 2, 1)
        traction = -pressure[:, None] * self.normal + mu * np.einsum("nij,nj->ni", strain, self.normal)
        traction *= self.weight[:, None]
        if dim == 2:
            moment = np.zeros((len(traction), 3))
            moment[:, 2] = self.arm[:, 0] * traction[:, 1] - self.arm[:, 1] * traction[:, 0]
        else:
            moment = np.cross(self.arm, traction)
        force = np.stack([np.bincount(self.particle, traction[:, d], self.n_particles) for d in range(dim)],
                         -1)
        torque = np.stack([np.bincount(self.particle, moment[:, d], self.n_particles) for d in range(3)], -1)
        return force, torque
