"""Hydrodynamic forces and torques on fictitious-boundary particles: the volume integral over the
cells cut by each particle, the momentum balance tested with a function that is one on the
particle and falls to zero within the next layer of cells, and the traction integrated over the
true surface of balls (with the sharp boundary).

The volume and surface forces are linear in the flow: they are built once per particle state, for
all particles at once, as a :class:`ForceFunctional` (sparse rows over the flow's unknowns), which
evaluates one flow or many (the implicit coupling's lifting responses) in one pass."""
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


class ForceFunctional:
    """Hydrodynamic force and torque on every particle as linear functionals of the flow:
    ``mu G_u u + G_p p``, ``G_u (n r, n_u)`` and ``G_p (n r, n_p)`` CSR, ``r`` rows per particle
    (force ``0..dim-1``, then torque: the z component in 2D, three in 3D).

    Built once per particle state from the pieces of an estimator's integral (cells cut by a
    particle, surface points), all particles at once; evaluating it costs one pass over its
    entries, whatever the particle count, and :meth:`many` evaluates any number of flows (the
    implicit coupling's lifting responses) in that one pass.

    Parameters
    ----------
    space : FlowSpace
    n_particles : int
    cells : (m,) int64, the cell of every piece
    particle : (m,) int64, the particle of every piece
    wu : (m, r, dim, nl) float64, coefficients of ``mu`` times the velocity components at the
        cell's Q2 nodes
    wp : (m, r, dim + 1) float64, coefficients of the cell's P1disc pressure modes
    """

    def __init__(self, space: FlowSpace, n_particles: int, cells: np.ndarray, particle: np.ndarray,
                 wu: np.ndarray, wp: np.ndarray):
        d, n_v, nl = space.dim, space.n_v, space.V.cell_dofs.shape[1]
        r, npl = wu.shape[1], d + 1
        self.dim, self.n_particles, self.rows_per_particle = d, int(n_particles), r
        order = np.argsort(particle, kind="stable")                                 # pieces by particle
        cells, particle = cells[order], particle[order]
        nodes = space.V.cell_dofs[cells]                                            # (m, nl)
        cols_u = np.arange(d)[None, :, None] * n_v + nodes[:, None, :]              # (m, d, nl)
        cols_p = cells[:, None] * npl + np.arange(npl)[None, :]                     # (m, npl)
        self.G_u = _rows_by_particle(particle, self.n_particles, wu[order].reshape(len(order), r, d * nl),
                                     cols_u.reshape(len(order), d * nl), space.n_u)
        self.G_p = _rows_by_particle(particle, self.n_particles, wp[order], cols_p, space.n_p)

    def _split(self, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Force (..., n, dim) and torque (..., n, 3) from the rows (..., n r)."""
        rows = rows.reshape(rows.shape[:-1] + (self.n_particles, self.rows_per_particle))
        force = rows[..., :self.dim].copy()
        if self.dim == 3:
            return force, rows[..., 3:].copy()
        torque = np.zeros(rows.shape[:-1] + (3,))
        torque[..., 2] = rows[..., 2]
        return force, torque

    def __call__(self, u: np.ndarray | None, p: np.ndarray | None,
                 mu: float) -> tuple[np.ndarray, np.ndarray]:
        """Force (n, dim) [N] and torque (n, 3) [N m] of the flow ``u (dim * n_v,)``, ``p (n_p,)``
        with dynamic viscosity ``mu`` (None: that part left out)."""
        rows = np.zeros(self.G_u.shape[0])
        if u is not None:
            rows += mu * (self.G_u @ u)
        if p is not None:
            rows += self.G_p @ p
        return self._split(rows)

    def many(self, U: np.ndarray | None, P: np.ndarray | None, mu: float) -> tuple[np.ndarray, np.ndarray]:
        """Force (k, n, dim) and torque (k, n, 3) of the ``k`` flows ``U (k, dim * n_v)``,
        ``P (k, n_p)`` (row views of a larger array are fine; None: that part left out), in one
        pass over the functionals (``csr_apply_rows``)."""
        k = (U if U is not None else P).shape[0]
        rows = np.zeros((k, self.G_u.shape[0]))
        for G, X, scale in ((self.G_u, U, mu), (self.G_p, P, 1.0)):
            if X is not None:
                _kernels.csr_apply_rows(G.indptr, G.indices, G.data, X, float(scale), rows)
        return self._split(rows)

    def own_response(self, W: sp.spmatrix, free: np.ndarray, mu: float) -> np.ndarray:
        """Each particle's force and torque on its own unit rigid motions ``W (n_u, k)`` (sparse,
        one column per True entry of ``free (n, r)``, row-major, as
        :func:`~fbmflow.coupling.indicator.rigid_liftings` makes them), the rest of the flow held at zero:
        ``S (n, r, r)`` float64 with ``S[i, :, b]`` the rows of particle ``i`` of ``mu G_u W``
        in its column ``b`` (zero where ``free`` is False). One sparse product for all
        particles; the other particles' rows of a column are dropped."""
        n, r = self.n_particles, self.rows_per_particle
        owner_of_column, component = np.nonzero(free)
        M = (self.G_u @ sp.csc_matrix(W)).tocoo()
        own = M.row // r == owner_of_column[M.col]
        S = np.zeros((n, r, r))
        np.add.at(S, (M.row[own] // r, M.row[own] % r, component[M.col[own]]), mu * M.data[own])
        return S


def _rows_by_particle(particle: np.ndarray, n: int, w: np.ndarray, cols: np.ndarray,
                      n_cols: int) -> sp.csr_matrix:
    """CSR (n r, n_cols) whose row ``i r + q`` holds the entries ``w[e, q]`` (at ``cols[e]``) of
    every piece ``e`` of particle ``i``: ``particle (m,)`` sorted, ``w (m, r, k)``, ``cols (m, k)``.
    Built in place (no COO round trip); a column may repeat within a row (cells share nodes)."""
    m, r, k = w.shape
    count = np.bincount(particle, minlength=n)                                  # pieces per particle
    indptr = np.zeros(n * r + 1, dtype=np.int64)
    np.cumsum(np.repeat(count * k, r), out=indptr[1:])
    rank = np.arange(m) - (np.cumsum(count) - count)[particle]                 # piece within its particle
    start = indptr[:-1][particle[:, None] * r + np.arange(r)] + (rank * k)[:, None]   # (m, r)
    dest = (start[:, :, None] + np.arange(k)).ravel()
    data, indices = np.empty(dest.size), np.empty(dest.size, dtype=np.int64)
    data[dest] = w.ravel()
    indices[dest] = np.broadcast_to(cols[:, None, :], w.shape).ravel()
    return sp.csr_matrix((data, indices, indptr), shape=(n * r, n_cols))


def volume_force_functional(space: FlowSpace, owner: np.ndarray, centres: np.ndarray,
                            cells: np.ndarray | None = None) -> ForceFunctional:
    """The cut-cell volume force and torque of every particle (see :func:`hydrodynamic_forces`) as a
    :class:`ForceFunctional`: the (cut cell, particle) pairs of all particles found at once, their
    coefficients in one kernel pass (``volume_force_rows``). ``cells (n_cells,)`` bool: the cut
    cells taken (None: all)."""
    centres = np.atleast_2d(np.asarray(centres, dtype=float))
    n = len(centres)
    cut = cut_cells(space, owner)
    if cells is not None:
        cut = cut[cells[cut]]
    o = owner[space.V.cell_dofs[cut]]                                   # (n_cut, nl)
    row, col = np.nonzero(o >= 0)
    pairs = np.unique(cut[row] * max(n, 1) + o[row, col])               # (cell, particle), sorted
    cells, particle = pairs // max(n, 1), pairs % max(n, 1)
    wu, wp = _kernels.volume_force_rows(cells, particle, owner, centres, space.V.cell_dofs, space.dphi,
                                        space.detJw, space.Jinv, space.psi, space.xq,
                                        space.mesh.periods)
    return ForceFunctional(space, n, cells, particle, wu, wp)


def hydrodynamic_forces(space: FlowSpace, owner: np.ndarray, centres: np.ndarray, u: np.ndarray,
                        p: np.ndarray, mu: float):
    """Force (n_particles, dim) [N] and torque (n_particles, 3) [N m] from the flow ``u (dim * n_v,)``,
    ``p (n_p,)`` with dynamic viscosity ``mu``: ``F_i = -int sigma · grad alpha_i``,
    ``T_i = -int (x - X_i) x (sigma · grad alpha_i)`` over the cells cut by particle ``i``
    (``alpha_i`` the Q2 interpolant of its indicator; the arm ``x - X_i`` takes the minimum image
    on periodic axes). For many flows of one particle state build :func:`volume_force_functional`
    once."""
    return volume_force_functional(space, owner, centres)(u, p, mu)


def mirror_images(force: np.ndarray, torque: np.ndarray, axes) -> tuple[np.ndarray, np.ndarray]:
    """Force and torque of whole particles cut by symmetry planes through their centres.

    ``axes``: the normal axis of every mirror plane (e.g. ``(0, 1)`` for a quarter domain cut by
    the planes x = X and y = Y). The mirror image across the plane with normal ``a`` flips the
    ``a`` component of the force and, the torque being a pseudo-vector, every other component of
    the torque; the whole particle gets the sum of all images. ``force (..., n, dim)``,
    ``torque (..., n, 3)`` (leading axes: several flows); returns new arrays.
    """
    F, T = np.array(force, dtype=float), np.array(torque, dtype=float)
    for a in axes:
        flip_f = np.ones(F.shape[-1])
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
    cells : (n_cells,) bool or None, the cells whose part of the integrals is taken (None: all):
        a process's owned cells on its slab (:mod:`fbmflow.parallel.blocks`), the sums over all
        processes' parts being the whole mesh's. ``psi_i`` at an owned cell's node needs the
        owners of the nodes of the cells around it, which the slab's halo holds.
    """

    def __init__(self, space: FlowSpace, owner: np.ndarray, centres: np.ndarray, shapes: list,
                 rotations: np.ndarray | None = None, walls: np.ndarray | None = None, n_1d: int = 8,
                 cells: np.ndarray | None = None):
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
        taken = slice(None) if cells is None else np.asarray(cells, dtype=bool)[pairs.row]
        self._quadrature(space, pairs.row[taken].astype(np.int64), pairs.col[taken].astype(np.int64), centres,
                         shapes, rotations, n_1d)
        pc = np.zeros(self.nodes.shape)
        if pc.size:  # (a process's cells may hold no pair)
            pc.flat[:] = np.asarray(psi_nodes[self.nodes.ravel(), np.repeat(self.body, nl)]).ravel()
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
        self.n_particles, self.dim, self.n_v, self.space = len(shapes), d, V.n_dofs, space

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
        derivative and ``(about · grad) du + (du · grad) about`` for the convection.
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

    def linearised(self, about: np.ndarray, mu: float, rho: float,
                   dt: float | None = None) -> ForceFunctional:
        """The change of the force with the flow about the velocity ``about (dim n_v,)`` (what
        ``__call__`` gives with ``about``), as a :class:`ForceFunctional` whose coefficients
        hold ``mu`` and ``rho`` (evaluate it with ``mu = 1``): one pass evaluates any number of
        responses. Built from the rule's quadrature by contractions over its Gauss points."""
        d = self.dim
        aq, ga = self._velocity(about)                               # (m, nq, d), (m, nq, d, d)
        W = self.weight
        A = W * rho * self.psi_q                                     # (m, nq)
        # per Gauss point, the coefficient of u_n at node a in f_j is
        # -(delta_jn S_a + A ga_jn phi_a + W mu dphi_aj dpsi_n), S_a = A (dphi_a . about + phi_a / dt)
        # + W mu dphi_a . dpsi
        S = A[..., None] * np.einsum("cqak,cqk->cqa", self.grad_phi, aq)
        if dt is not None:
            S += A[..., None] * self.phi[None] / dt
        S += (W * mu)[..., None] * np.einsum("cqak,cqk->cqa", self.grad_phi, self.grad_psi)
        Wmu_gpsi = (W * mu)[..., None] * self.grad_psi              # (m, nq, d)
        if d == 2:  # the moment arm as a matrix: torque_i = sum_j M_ij f_j (z only in 2D)
            M = np.stack([-self.rel[..., 1], self.rel[..., 0]], axis=-1)[:, :, None, :]
        else:
            eps = np.zeros((3, 3, 3))
            eps[0, 1, 2] = eps[1, 2, 0] = eps[2, 0, 1] = 1.0
            eps[0, 2, 1] = eps[2, 1, 0] = eps[1, 0, 2] = -1.0
            M = np.einsum("ilj,cql->cqij", eps, self.rel)
        force_u = -np.einsum("jn,ca->cjna", np.eye(d), S.sum(axis=1))
        force_u -= np.einsum("cq,cqjn,qa->cjna", A, ga, self.phi, optimize=True)
        force_u -= np.einsum("cqaj,cqn->cjna", self.grad_phi, Wmu_gpsi, optimize=True)
        torque_u = -np.einsum("cqin,cqa->cina", M, S, optimize=True)
        torque_u -= np.einsum("cqin,qa->cina", np.einsum("cqij,cq,cqjn->cqin", M, A, ga), self.phi,
                              optimize=True)
        torque_u -= np.einsum("cqij,cqaj,cqn->cina", M, self.grad_phi, Wmu_gpsi, optimize=True)
        # pressure: +W pq dpsi_j
        force_p = np.einsum("cq,cqm,cqj->cjm", W, self.pressure_basis, self.grad_psi, optimize=True)
        torque_p = np.einsum("cqij,cq,cqm,cqj->cim", M, W, self.pressure_basis, self.grad_psi, optimize=True)
        wu = np.concatenate([force_u, torque_u], axis=1)
        wp = np.concatenate([force_p, torque_p], axis=1)
        return ForceFunctional(self.space, self.n_particles, self.cells, self.body, wu, wp)


def supports_surface_force(shapes) -> bool:
    """True when every shape is a ball (disk or sphere), whose surface :class:`SurfaceForces`
    integrates over."""
    return all(isinstance(s, Ball) for s in shapes)


class SurfaceForces(ForceFunctional):
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
    :func:`mirror_images`; periodic axes wrap. Built once per particle state, all balls at once,
    as a :class:`ForceFunctional` (linear in ``(u, p)``; tensor-product meshes).

    Measured (Stokes flow through a cubic array of spheres with exact drag,
    ``benchmarks/studies/sphere_array.py``): error +2.5 / -0.6 / +0.5 / +0.3 / -0.2 % at 4 / 6 / 8 /
    12 / 16 cells per diameter, against +6.1 / +3.2 / +3.0 / +1.9 / +1.2 % for the cut-cell
    volume force and -21 / -13 / -8.3 / -6.1 / -3.9 % for the tested momentum balance.

    Parameters
    ----------
    space : FlowSpace
    centres : (n, dim) float64, ball centres [m]
    shapes : list of n :class:`~fbmflow.particles.shapes.Ball`
    points_per_cell : int, default 4
    cells : (n_cells,) bool or None, the cells whose surface points the integral takes (one
        process's owned cells: its part of a sum over processes; None: all)
    spacing : float or None, the finest cell length that sets the points' density (None:
        ``space``'s mesh's; a process's slab takes the whole mesh's)
    """

    def __init__(self, space: FlowSpace, centres: np.ndarray, shapes: list, points_per_cell: int = 4,
                 cells: np.ndarray | None = None, spacing: float | None = None):
        if not supports_surface_force(shapes):
            raise ValueError("the surface force integrates over balls (disks, spheres) only; use the volume "
                             "force for other shapes")
        mesh, dim = space.mesh, space.dim
        centres = np.atleast_2d(np.asarray(centres, dtype=float))
        radius = np.array([s.radius for s in shapes])
        h = float(mesh.finest_spacing.min()) if spacing is None else float(spacing)
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
        L, middle = mesh.periods, (lower + upper) / 2
        for d in np.flatnonzero((L > 0) & ~np.array(mesh.periodic)):  # a piece of a periodic mesh:
            x[:, d] -= L[d] * np.round((x[:, d] - middle[d]) / L[d])  # the image nearest the piece
        keep = np.all((x >= lower) & (x <= upper), axis=1)
        x, particle, normal, arm, weight = x[keep], particle[keep], normal[keep], arm[keep], weight[keep]
        cells_at, xi = locate(mesh, x)
        if cells is not None:  # (off a slab's mesh: in no owned cell either)
            own = cells[cells_at]
            x, particle, normal, arm, weight, cells_at, xi = (
                a[own] for a in (x, particle, normal, arm, weight, cells_at, xi))
        cells = cells_at
        _, dphi = space.V.element.tabulate(xi)
        dphi = dphi / space.Q.scale[cells][:, None, :]  # physical gradients (tensor-product cells)
        psi = space.Q.element.tabulate(x, space.Q.centre[cells], space.Q.scale[cells])
        # traction_j = -p n_j + mu sum_k (d_k u_j + d_j u_k) n_k, times the point's weight
        eye = np.eye(dim)
        cu = np.einsum("jm,pak,pk->pjma", eye, dphi, normal) + np.einsum("paj,pm->pjma", dphi, normal)
        cu *= weight[:, None, None, None]
        cp = -weight[:, None, None] * normal[:, :, None] * psi[:, None, :]        # (n_pts, dim, npl)
        r = 3 if dim == 2 else 6
        wu = np.zeros((len(x), r) + cu.shape[2:])
        wp = np.zeros((len(x), r, dim + 1))
        wu[:, :dim], wp[:, :dim] = cu, cp
        for w, c in ((wu, cu), (wp, cp)):  # the moment arm x traction
            arm_b = arm.reshape(arm.shape + (1,) * (c.ndim - 2))
            if dim == 2:
                w[:, 2] = arm_b[:, 0] * c[:, 1] - arm_b[:, 1] * c[:, 0]
            else:
                w[:, 3:] = np.cross(arm_b, c, axis=1)
        super().__init__(space, len(shapes), cells, particle, wu, wp)
