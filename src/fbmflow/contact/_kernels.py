"""Numba kernels of the contact solver (3D vectors throughout; 2D problems padded with z = 0).

Each contact ``c`` between particles ``i`` and ``j`` (``j < 0``: a static plane) has three
constraint rows ``q`` (0: the normal, 1 and 2: the tangents) with direction ``d = D[c, q]`` and
precomputed angular parts ``a_i = r_i x d``, ``a_j = r_j x d`` (arms ``r = p - X``) and
``b = I^{-1} a`` (world axes). The relative velocity along the row is

    u = d . (v_i - v_j) + a_i . w_i - a_j . w_j,

and an impulse ``lambda`` (``+lambda d`` on i at its contact point, ``-lambda d`` on j) changes it
by ``k lambda`` with the effective inverse mass ``k = 1/m_i + a_i · b_i + 1/m_j + a_j · b_j``.
"""
from __future__ import annotations

import numpy as np

from .._jit import njit


@njit
def _velocity(v, w, i, j, d, ai, aj):
    u = 0.0
    for a in range(3):
        u += d[a] * v[i, a] + ai[a] * w[i, a]
    if j >= 0:
        for a in range(3):
            u -= d[a] * v[j, a] + aj[a] * w[j, a]
    return u


@njit
def _apply(v, w, inv_m, i, j, d, bi, bj, lam):
    for a in range(3):
        v[i, a] += inv_m[i] * lam * d[a]
        w[i, a] += lam * bi[a]
    if j >= 0:
        for a in range(3):
            v[j, a] -= inv_m[j] * lam * d[a]
            w[j, a] -= lam * bj[a]


@njit
def row_masses(ci, cj, D, ri, rj, inv_m, inv_I):
    """Angular parts and effective inverse masses of every row: ``A = r x d`` (m, 3, 3) for
    either side, ``B = I^{-1} A`` (m, 3, 3) with the inverse world inertia ``inv_I (n, 3, 3)``
    and ``K = 1/m_i |d|^2 + a_i · b_i + 1/m_j |d|^2 + a_j · b_j`` (m, 3), from the row
    directions ``D (m, 3, 3)`` and the arms ``ri, rj (m, 3)``; a plane (``j < 0``) adds nothing
    (its ``A`` and ``B`` are zero). Returns Ai, Aj, Bi, Bj, K."""
    m = ci.shape[0]
    Ai = np.zeros((m, 3, 3))
    Aj = np.zeros((m, 3, 3))
    Bi = np.zeros((m, 3, 3))
    Bj = np.zeros((m, 3, 3))
    K = np.zeros((m, 3))
    for c in range(m):
        i, j = ci[c], cj[c]
        for q in range(3):
            d = D[c, q]
            dd = d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
            k = inv_m[i] * dd + _angular(ri[c], d, inv_I[i], Ai[c, q], Bi[c, q])
            if j >= 0:
                k += inv_m[j] * dd + _angular(rj[c], d, inv_I[j], Aj[c, q], Bj[c, q])
            K[c, q] = k
    return Ai, Aj, Bi, Bj, K


@njit
def _angular(r, d, inv_I, A, B):
    """``A = r x d`` and ``B = inv_I A`` written into ``A``, ``B`` (3,); returns ``A · B``."""
    _cross(r, d, A)
    k = 0.0
    for a in range(3):
        b = 0.0
        for e in range(3):
            b += inv_I[a, e] * A[e]
        B[a] = b
        k += A[a] * b
    return k


@njit
def _cross(r, d, out):
    out[0] = r[1] * d[2] - r[2] * d[1]
    out[1] = r[2] * d[0] - r[0] * d[2]
    out[2] = r[0] * d[1] - r[1] * d[0]


@njit
def row_velocities(ci, cj, D, Ai, Aj, v, w, q):
    """Relative velocities (m,) of every contact along its row ``q``."""
    m = ci.shape[0]
    u = np.empty(m)
    for c in range(m):
        u[c] = _velocity(v, w, ci[c], cj[c], D[c, q], Ai[c, q], Aj[c, q])
    return u


@njit
def warm_start(ci, cj, D, Bi, Bj, inv_m, lam, v, w):
    """Apply the accumulated impulses ``lam (m, 3)`` to ``v, w`` in place."""
    for c in range(ci.shape[0]):
        for q in range(3):
            if lam[c, q] != 0.0:
                _apply(v, w, inv_m, ci[c], cj[c], D[c, q], Bi[c, q], Bj[c, q], lam[c, q])


@njit
def natural_residual(ci, cj, D, Ai, Aj, K, target, lam, v, w):
    """``max_c |min(lambda_c, (u_c - target_c) / k_c)|`` over the normal rows: zero exactly at a
    solution of the LCP ``lambda >= 0, u - target >= 0, lambda (u - target) = 0`` [impulse]."""
    r = 0.0
    for c in range(ci.shape[0]):
        slack = (_velocity(v, w, ci[c], cj[c], D[c, 0], Ai[c, 0], Aj[c, 0]) - target[c]) / K[c, 0]
        r = max(r, abs(min(lam[c, 0], slack)))
    return r


@njit
def pgs(ci, cj, D, Ai, Aj, Bi, Bj, K, target, mu, inv_m, lam, v, w, iterations, tol, history):
    """Projected Gauss–Seidel sweeps with accumulated-impulse clamping (Box2D's sequential
    impulses): per contact, friction first (``|lambda_t| <= mu lambda_n``, the two tangential
    impulses clamped to a disk), then the normal row (``lambda_n >= 0``, ``u_n >= target``).
    Updates ``lam``, ``v``, ``w`` in place; ``history[s]`` is the natural residual after sweep
    ``s``. Returns the number of sweeps done (it stops once the residual is at most ``tol``)."""
    m = ci.shape[0]
    for s in range(iterations):
        for c in range(m):
            i, j = ci[c], cj[c]
            if mu > 0.0:
                t1 = 0.0
                t2 = 0.0
                if K[c, 1] > 0.0:
                    t1 = lam[c, 1] - _velocity(v, w, i, j, D[c, 1], Ai[c, 1], Aj[c, 1]) / K[c, 1]
                if K[c, 2] > 0.0:
                    t2 = lam[c, 2] - _velocity(v, w, i, j, D[c, 2], Ai[c, 2], Aj[c, 2]) / K[c, 2]
                limit = mu * lam[c, 0]
                norm = np.sqrt(t1 * t1 + t2 * t2)
                if norm > limit:
                    t1 *= limit / norm
                    t2 *= limit / norm
                _apply(v, w, inv_m, i, j, D[c, 1], Bi[c, 1], Bj[c, 1], t1 - lam[c, 1])
                _apply(v, w, inv_m, i, j, D[c, 2], Bi[c, 2], Bj[c, 2], t2 - lam[c, 2])
                lam[c, 1] = t1
                lam[c, 2] = t2
            u = _velocity(v, w, i, j, D[c, 0], Ai[c, 0], Aj[c, 0])
            new_n = max(lam[c, 0] + (target[c] - u) / K[c, 0], 0.0)
            _apply(v, w, inv_m, i, j, D[c, 0], Bi[c, 0], Bj[c, 0], new_n - lam[c, 0])
            lam[c, 0] = new_n
        history[s] = natural_residual(ci, cj, D, Ai, Aj, K, target, lam, v, w)
        if history[s] <= tol:
            return s + 1
    return iterations


@njit
def project_positions(ci, cj, n, gap, goal, inv_m, X, sweeps, slop):
    """Gauss–Seidel projection of the positions (velocities untouched, so no energy is added).

    A contact's current gap is ``gap_c + n_c · (X_i - X_j)`` (``X (N, 3)`` the displacements
    since ``gap`` was measured). Where ``goal_c`` is NaN the gap must not fall below ``-slop``;
    elsewhere (collisions of this sub-step) it is set to ``goal_c``. Each correction moves i and j
    along ``n_c`` in proportion to their inverse masses. Updates ``X`` in place; returns the
    largest overlap left."""
    m = ci.shape[0]
    worst = 0.0
    for s in range(sweeps):
        worst = 0.0
        change = 0.0
        for c in range(m):
            i, j = ci[c], cj[c]
            g = gap[c]
            for a in range(3):
                g += n[c, a] * X[i, a]
                if j >= 0:
                    g -= n[c, a] * X[j, a]
            k = inv_m[i] + (inv_m[j] if j >= 0 else 0.0)
            want = g
            if not np.isnan(goal[c]):
                want = goal[c]
            elif g < -slop:
                want = -slop
            if want != g and k > 0:
                lam = (want - g) / k
                for a in range(3):
                    X[i, a] += inv_m[i] * lam * n[c, a]
                    if j >= 0:
                        X[j, a] -= inv_m[j] * lam * n[c, a]
                change = max(change, abs(want - g))
                g = want
            worst = max(worst, -g)
        if change <= 1e-15 * (1.0 + worst):
            break
    return worst


@njit
def lubricate(ci, cj, D, Ai, Aj, Bi, Bj, K, c, h, inv_m, v, w):
    """Implicit lubrication damping, one Gauss–Seidel sweep: per contact with coefficient
    ``c > 0`` [N s/m] the normal impulse ``lambda = -c h u / (1 + c h k)`` (backward Euler of
    ``m* du/dt = -c u`` for the pair's relative normal velocity ``u``). Updates ``v, w``."""
    for k in range(ci.shape[0]):
        if c[k] <= 0.0:
            continue
        i, j = ci[k], cj[k]
        u = _velocity(v, w, i, j, D[k, 0], Ai[k, 0], Aj[k, 0])
        lam = -c[k] * h * u / (1.0 + c[k] * h * K[k, 0])
        _apply(v, w, inv_m, i, j, D[k, 0], Bi[k, 0], Bj[k, 0], lam)
