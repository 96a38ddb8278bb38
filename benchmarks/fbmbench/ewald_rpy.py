"""Mean settling velocity of a periodic configuration of equal spheres in Stokes flow at the
Rotne–Prager–Yamakawa level, by Ewald summation (Beenakker 1986, J. Chem. Phys. 85, 1581): an
independent far-field reference for the hindered-settling ensembles.

Every sphere (radius ``a``) carries the same force along the last axis; the velocities are
``U_i = sum_j M_ij F``, relative to the mixture (the Ewald sum leaves out the mean flow), with the
RPY mobility of every pair and all its periodic images. Exact for one sphere per box to the first
three terms of Hasimoto's series, ``1 - 1.7601 phi^(1/3) + phi``; no near-field (lubrication, higher
multipoles), so at phi = 0.2 its level is that of a far-field model, while its dependence on the
box and the particle count is that of Stokes flow.
"""
from __future__ import annotations

import itertools
import math

import numpy as np
from scipy.special import erfc


def mean_settling(X: np.ndarray, box: float, a: float, xi: float | None = None, tol: float = 1e-12) -> float:
    """Mean settling velocity of the spheres at ``X (n, 3)`` in the periodic cube of side ``box``,
    over the Stokes velocity of one sphere, ``F / (6 pi mu a)``.

    ``xi``: Ewald's splitting parameter (default: the real-space sum cut at half the box, the
    nearest images only); the result does not depend on it beyond ``tol`` (the sums are cut where
    their terms fall below ``tol``)."""
    X = np.asarray(X, dtype=float)
    n = len(X)
    xi = 2.0 * math.sqrt(-math.log(tol)) / box if xi is None else xi
    cut = math.sqrt(-math.log(tol)) / xi  # real space: erfc(xi r) < tol beyond
    kcut = 2.0 * xi * math.sqrt(-math.log(tol))  # reciprocal space: exp(-k^2 / 4 xi^2) < tol beyond
    sq = math.sqrt(math.pi)
    # self term (Beenakker's)
    total = n * (1.0 - 6.0 * xi * a / sq + 40.0 * xi**3 * a**3 / (3.0 * sq))
    # real space: every pair (i, j) and image n, except i = j at n = 0
    m = int(math.ceil(cut / box))
    diff = (X[:, None, :] - X[None, :, :]).reshape(-1, 3)
    same = np.eye(n, dtype=bool).ravel()
    for shift in itertools.product(range(-m, m + 1), repeat=3):
        r_vec = diff + box * np.array(shift, dtype=float)
        r = np.linalg.norm(r_vec, axis=1)
        keep = (r < cut) & ~(same & (r == 0.0))
        r_vec, r = r_vec[keep], r[keep]
        if r.size == 0:
            continue
        e, g = erfc(xi * r), np.exp(-(xi * r) ** 2) / sq
        iso = e * (0.75 * a / r + 0.5 * a**3 / r**3) + g * (
            4 * xi**7 * a**3 * r**4 + 3 * xi**3 * a * r**2 - 20 * xi**5 * a**3 * r**2 - 4.5 * xi * a
            + 14 * xi**3 * a**3 + xi * a**3 / r**2)
        aniso = e * (0.75 * a / r - 1.5 * a**3 / r**3) + g * (
            -4 * xi**7 * a**3 * r**4 - 3 * xi**3 * a * r**2 + 16 * xi**5 * a**3 * r**2 + 1.5 * xi * a
            - 2 * xi**3 * a**3 - 3 * xi * a**3 / r**2)
        total += float(np.sum(iso + aniso * (r_vec[:, 2] / r) ** 2))
    # reciprocal space: sum_k f(k) (1 - k_z^2 / k^2) |sum_j exp(i k X_j)|^2, k != 0
    q = int(math.ceil(kcut * box / (2.0 * math.pi)))
    ints = np.array([s for s in itertools.product(range(-q, q + 1), repeat=3) if any(s)], dtype=float)
    k = 2.0 * math.pi / box * ints
    k2 = np.einsum("ij,ij->i", k, k)
    k = k[k2 <= kcut**2]
    k2 = k2[k2 <= kcut**2]
    f = ((a - a**3 * k2 / 3.0) * (1.0 + k2 / (4 * xi**2) + k2**2 / (8 * xi**4)) * 6.0 * math.pi / k2
         * np.exp(-k2 / (4 * xi**2)) / box**3)
    for s in range(0, len(k), 2048):  # |sum_j exp(i k X_j)|^2 for a block of wave vectors
        block = slice(s, s + 2048)
        rho = np.exp(1j * X @ k[block].T).sum(axis=0)
        total += float(np.sum(f[block] * (1.0 - k[block, 2] ** 2 / k2[block]) * np.abs(rho) ** 2))
    return total / n
