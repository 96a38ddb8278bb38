"""Numba kernel of the hydrodynamic force and torque volume integrals (checked against NumPy in
tests/coupling/test_forces.py)."""
import numpy as np

from .._jit import njit


@njit
def fbm_force_torque(cells, owner, n_particles, centres, u, p, mu, cell_dofs, phi, dphi, detJw,
                     Jinv, psi, xq):
    """``F_i = -int sigma . grad alpha_i``, ``T_i = -int (x - X_i) x (sigma . grad alpha_i)``.

    ``alpha_i`` is the Q2 interpolant of particle ``i``'s indicator (1 on its nodes), so only cells
    with nodes of ``i`` and other nodes contribute; each is visited once. ``sigma = -p I +
    mu (grad u + grad u^T)``.

    cells (n_cut,) int64; owner (n_v,) int64; centres (n_particles, d); u (d, n_v); p (n_p,);
    phi (nq, nl); dphi (nq, nl, d); detJw (n_cells, nq); Jinv (n_cells, nq, d, d);
    psi (n_cells, nq, d+1); xq (n_cells, nq, d).
    Returns force (n_particles, d) and torque (n_particles, 3) (2D: z component only).
    """
    nq, nl, d = dphi.shape
    npl = d + 1
    force = np.zeros((n_particles, d))
    torque = np.zeros((n_particles, 3))
    grad_a = np.zeros(d)
    grad_u = np.zeros((d, d))
    t = np.zeros(d)
    for c in cells:
        for i in range(n_particles):
            count = 0
            for a in range(nl):
                if owner[cell_dofs[c, a]] == i:
                    count += 1
            if count == 0 or count == nl:
                continue
            for q in range(nq):
                grad_a[:] = 0.0
                grad_u[:, :] = 0.0
                for a in range(nl):
                    dof = cell_dofs[c, a]
                    for k in range(d):
                        g = 0.0
                        for m in range(d):
                            g += dphi[q, a, m] * Jinv[c, q, m, k]
                        if owner[dof] == i:
                            grad_a[k] += g
                        for j in range(d):
                            grad_u[j, k] += u[j, dof] * g
                pq = 0.0
                for m in range(npl):
                    pq += p[c * npl + m] * psi[c, q, m]
                for j in range(d):
                    s = -pq * grad_a[j]
                    for k in range(d):
                        s += mu * (grad_u[j, k] + grad_u[k, j]) * grad_a[k]
                    t[j] = -s * detJw[c, q]
                for j in range(d):
                    force[i, j] += t[j]
                r0 = xq[c, q, 0] - centres[i, 0]
                r1 = xq[c, q, 1] - centres[i, 1]
                if d == 2:
                    torque[i, 2] += r0 * t[1] - r1 * t[0]
                else:
                    r2 = xq[c, q, 2] - centres[i, 2]
                    torque[i, 0] += r1 * t[2] - r2 * t[1]
                    torque[i, 1] += r2 * t[0] - r0 * t[2]
                    torque[i, 2] += r0 * t[1] - r1 * t[0]
    return force, torque
