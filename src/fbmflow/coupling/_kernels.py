"""Numba kernels of the hydrodynamic force and torque: the cut-cell volume integrals as linear
functionals of the flow, and their application to many flows at once (checked against NumPy in
tests/coupling/test_fbm.py)."""
import numpy as np

from .._jit import njit, prange


@njit(parallel=True)
def volume_force_rows(cells, particles, owner, centres, cell_dofs, dphi, detJw, Jinv, psi, xq, periods):
    """``F_i = -int sigma · grad alpha_i`` and ``T_i = -int (x - X_i) x (sigma · grad alpha_i)`` as
    linear functionals of the flow, one (cut cell, particle) pair at a time.

    ``alpha_i`` is the Q2 interpolant of particle ``i``'s indicator (1 on its nodes); ``sigma =
    -p I + mu (grad u + grad u^T)``. Pair ``e`` is the cell ``cells[e]`` with nodes of particle
    ``particles[e]`` and other nodes; each pair is visited once, whatever the particle count.

    cells, particles (m,) int64; owner (n_v,) int64; centres (n_particles, d); cell_dofs
    (n_cells, nl) int64; dphi (nq, nl, d); detJw (n_cells, nq); Jinv (n_cells, nq, d, d); psi
    (n_cells, nq, d+1); xq (n_cells, nq, d); periods (d,) float64, the period of every periodic axis
    (0 elsewhere): the torque arm ``x - X_i`` takes the minimum image there.
    Returns ``wu (m, r, d, nl)``, the coefficient of ``mu u_j`` at the cell's node ``a`` (component
    ``j``), and ``wp (m, r, d+1)``, that of the cell's pressure modes, in the ``r`` rows force
    ``0..d-1`` then torque (2D: ``r = 3``, the z component; 3D: ``r = 6``).
    """
    m = cells.shape[0]
    nq, nl, d = dphi.shape
    npl = d + 1
    r = 3 if d == 2 else 6
    wu = np.zeros((m, r, d, nl))
    wp = np.zeros((m, r, npl))
    for e in prange(m):  # pairs are independent: each writes its own rows
        g = np.empty((nl, d))
        ga = np.empty(d)
        gdot = np.empty(nl)
        cu = np.empty((d, d, nl))
        cp = np.empty((d, npl))
        rel = np.zeros(3)
        c, i = cells[e], particles[e]
        for q in range(nq):
            w = detJw[c, q]
            ga[:] = 0.0
            for a in range(nl):
                for k in range(d):
                    s = 0.0
                    for n in range(d):
                        s += dphi[q, a, n] * Jinv[c, q, n, k]
                    g[a, k] = s
                if owner[cell_dofs[c, a]] == i:
                    for k in range(d):
                        ga[k] += g[a, k]
            for a in range(nl):
                s = 0.0
                for k in range(d):
                    s += g[a, k] * ga[k]
                gdot[a] = s
            # t_j = -w (-p ga_j + mu sum_k (d_k u_j + d_j u_k) ga_k)
            for j in range(d):
                for n in range(d):
                    for a in range(nl):
                        v = g[a, j] * ga[n]
                        if n == j:
                            v += gdot[a]
                        cu[j, n, a] = -w * v
                for n in range(npl):
                    cp[j, n] = w * psi[c, q, n] * ga[j]
            for k in range(d):
                rel[k] = xq[c, q, k] - centres[i, k]
                if periods[k] > 0.0:
                    rel[k] -= periods[k] * np.round(rel[k] / periods[k])
            for j in range(d):
                for n in range(d):
                    for a in range(nl):
                        wu[e, j, n, a] += cu[j, n, a]
                for n in range(npl):
                    wp[e, j, n] += cp[j, n]
            for n in range(d):
                for a in range(nl):
                    if d == 2:
                        wu[e, 2, n, a] += rel[0] * cu[1, n, a] - rel[1] * cu[0, n, a]
                    else:
                        wu[e, 3, n, a] += rel[1] * cu[2, n, a] - rel[2] * cu[1, n, a]
                        wu[e, 4, n, a] += rel[2] * cu[0, n, a] - rel[0] * cu[2, n, a]
                        wu[e, 5, n, a] += rel[0] * cu[1, n, a] - rel[1] * cu[0, n, a]
            for n in range(npl):
                if d == 2:
                    wp[e, 2, n] += rel[0] * cp[1, n] - rel[1] * cp[0, n]
                else:
                    wp[e, 3, n] += rel[1] * cp[2, n] - rel[2] * cp[1, n]
                    wp[e, 4, n] += rel[2] * cp[0, n] - rel[0] * cp[2, n]
                    wp[e, 5, n] += rel[0] * cp[1, n] - rel[1] * cp[0, n]
    return wu, wp


@njit
def csr_apply_rows(indptr, indices, data, X, scale, out):
    """``out += scale X G^T`` for the CSR matrix ``G`` (indptr, indices, data) of ``n_rows``
    functionals and the flows ``X (k, n_cols)``: every functional of every flow in one pass,
    ``out (k, n_rows)``. ``X`` may be a strided view (rows of a larger array, or the transpose of
    an ``(n_cols, k)`` array, whose flows are then read side by side)."""
    k_flows = X.shape[0]
    if X.strides[0] < X.strides[1]:  # the flows are the fast axis: all of them per entry
        acc = np.empty(k_flows)
        for row in range(indptr.shape[0] - 1):
            acc[:] = 0.0
            for e in range(indptr[row], indptr[row + 1]):
                v, col = data[e], indices[e]
                for k in range(k_flows):
                    acc[k] += v * X[k, col]
            for k in range(k_flows):
                out[k, row] += scale * acc[k]
    else:
        for k in range(k_flows):
            for row in range(indptr.shape[0] - 1):
                s = 0.0
                for e in range(indptr[row], indptr[row + 1]):
                    s += data[e] * X[k, indices[e]]
                out[k, row] += scale * s
