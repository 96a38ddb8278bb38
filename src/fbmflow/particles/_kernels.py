"""Numba kernels of the particle shapes (checked against NumPy in tests/particles/test_shapes.py)."""
import numpy as np

from .._jit import njit, prange


@njit(parallel=True)
def winding_number(x, vertices, triangles):
    """Generalised winding number ``w(p) = sum_t Omega_t(p) / (4 pi)`` of points ``x (n, 3)``
    with respect to the closed surface ``vertices (n_v, 3)``, ``triangles (n_t, 3)``.

    The solid angle of triangle ``(a, b, c)`` seen from ``p`` (Van Oosterom and Strackee, 1983)
    with ``A = a - p`` etc.: ``tan(Omega / 2) = A . (B x C) / (|A||B||C| + (A.B)|C| + (B.C)|A|
    + (C.A)|B|)``. Returns (n,) float64: 1 inside, 0 outside.
    """
    n = x.shape[0]
    out = np.empty(n)
    for i in prange(n):
        total = 0.0
        p0, p1, p2 = x[i, 0], x[i, 1], x[i, 2]
        for t in range(triangles.shape[0]):
            va, vb, vc = triangles[t, 0], triangles[t, 1], triangles[t, 2]
            a0, a1, a2 = vertices[va, 0] - p0, vertices[va, 1] - p1, vertices[va, 2] - p2
            b0, b1, b2 = vertices[vb, 0] - p0, vertices[vb, 1] - p1, vertices[vb, 2] - p2
            c0, c1, c2 = vertices[vc, 0] - p0, vertices[vc, 1] - p1, vertices[vc, 2] - p2
            la = np.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
            lb = np.sqrt(b0 * b0 + b1 * b1 + b2 * b2)
            lc = np.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
            det = a0 * (b1 * c2 - b2 * c1) - a1 * (b0 * c2 - b2 * c0) + a2 * (b0 * c1 - b1 * c0)
            ab = a0 * b0 + a1 * b1 + a2 * b2
            bc = b0 * c0 + b1 * c1 + b2 * c2
            ca = c0 * a0 + c1 * a1 + c2 * a2
            total += 2.0 * np.arctan2(det, la * lb * lc + ab * lc + bc * la + ca * lb)
        out[i] = total / (4.0 * np.pi)
    return out
