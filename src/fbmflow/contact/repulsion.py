"""Short-range repulsive forces (Glowinski et al. 1999, 2001): the soft alternative to contact.

For particles with bounding radii ``R_i`` at centres ``X_i``, a force range ``rho`` and the
surface gaps ``s_ij = |X_i - X_j| - R_i - R_j`` (particle pairs) and ``s_iw = dist(X_i, wall) - R_i``
(walls):

    F_ij = S W_ij (max(rho - s_ij, 0) / rho)^2 n_ij,      F_iw = S W_i (max(rho - s_iw, 0) / rho)^2 n_iw,

with ``n`` the unit normal pushing the particle away, ``W_i = |m_i - rho_f V_i| |g|`` the weight
in the fluid (``W_ij = min(W_i, W_j)``; for a neutrally buoyant particle, or without gravity,
``m_i max(|g|, 1 m/s^2)`` instead, so that the force does not vanish) and ``S = strength``: at
contact the force is ``S`` times the weight, and it starts when the gap falls below ``rho``. This
is Glowinski et al.'s quadratic law written with the gap (their wall law, via the mirror image,
acts over half the range).
Spheres/disks by their bounding radius; other shapes are treated as their bounding balls. Pairs
are found by brute force (O(N^2)): a broadphase comes with the contact solver.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..particles import Particles


@dataclass(frozen=True)
class Repulsion:
    """Repulsive forces with range ``range_`` [m] between particles and from the walls of the box
    ``[lower, upper]`` (walls on every face; pass ``walls`` to keep only some axis-faces, as
    ``(axis, side)`` pairs with side 0 = lower, 1 = upper). ``periods``: the period of every axis
    (0: not periodic); pairs across a periodic axis act through the nearest image."""

    range_: float
    lower: tuple
    upper: tuple
    strength: float = 10.0
    walls: tuple | None = None
    periods: tuple | None = None

    def __post_init__(self):
        if not self.range_ > 0 or not self.strength > 0:
            raise ValueError("repulsion range and strength must be positive")

    def forces(self, p: Particles, gravity: np.ndarray, fluid_density: float) -> np.ndarray:
        """Repulsive forces (n, dim) [N] on the particles at their current positions."""
        n, dim = p.position.shape
        F = np.zeros((n, dim))
        for axis, side, gap, weight in self._walls(p, gravity, fluid_density):
            push = np.maximum(self.range_ - gap, 0.0) / self.range_
            F[:, axis] += (1.0 if side == 0 else -1.0) * self.strength * weight * push**2
        if n > 1:
            diff, dist, w = self._pairs(p, gravity, fluid_density)
            np.fill_diagonal(dist, np.inf)
            push = np.maximum(self.range_ - (dist - p.bounding_radius[:, None] - p.bounding_radius[None, :]),
                              0.0) / self.range_
            F += np.einsum("ij,ijk->ik", self.strength * w * push**2 / dist, diff)
        F[p.fixed] = 0.0
        return F

    def stiffness(self, p: Particles, gravity: np.ndarray, fluid_density: float) -> sp.csr_matrix:
        """The forces' change with the positions along the lines of action, ``K (n dim, n dim)``
        [N/m], row-major by particle: for a pair in range with unit normal ``n_ij`` and
        ``k = dF/ds = -2 S W_ij (rho - s_ij) / rho^2``, the blocks ``K_ii = K_jj = k n n^T`` and
        ``K_ij = K_ji = -k n n^T``; a wall adds ``k`` on its axis. The turn of the normal
        (``F / dist`` across it) is left out, so ``K`` is symmetric and negative semi-definite:
        what a time step needs to take the repulsion implicitly, ``F(X + dt v) ~ F(X) + dt K v``.
        Rows and columns of fixed particles are zero."""
        n, dim = p.position.shape
        rows, cols, vals = [], [], []
        for axis, _, gap, weight in self._walls(p, gravity, fluid_density):
            k = -2.0 * self.strength * weight * np.maximum(self.range_ - gap, 0.0) / self.range_**2
            on = np.flatnonzero(k)
            rows.append(on * dim + axis)
            cols.append(on * dim + axis)
            vals.append(k[on])
        if n > 1:
            diff, dist, w = self._pairs(p, gravity, fluid_density)
            i, j = np.nonzero(np.triu(dist - p.bounding_radius[:, None] - p.bounding_radius[None, :]
                                      < self.range_, 1))
            s = dist[i, j] - p.bounding_radius[i] - p.bounding_radius[j]
            k = -2.0 * self.strength * w[i, j] * (self.range_ - s) / self.range_**2
            normal = diff[i, j] / dist[i, j, None]
            block = k[:, None, None] * normal[:, :, None] * normal[:, None, :]     # (m, dim, dim)
            a, b = np.meshgrid(np.arange(dim), np.arange(dim), indexing="ij")
            for first, second, sign in ((i, i, 1.0), (j, j, 1.0), (i, j, -1.0), (j, i, -1.0)):
                rows.append((first[:, None, None] * dim + a).ravel())
                cols.append((second[:, None, None] * dim + b).ravel())
                vals.append(sign * block.ravel())
        K = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                          shape=(n * dim, n * dim)) if rows else sp.csr_matrix((n * dim, n * dim))
        keep = sp.diags(np.repeat((~p.fixed).astype(float), dim))
        return (keep @ K @ keep).tocsr()

    def _weights(self, p: Particles, gravity: np.ndarray, fluid_density: float) -> np.ndarray:
        """``W_i`` (n,): the weight in the fluid, or ``m_i max(|g|, 1 m/s^2)`` where it vanishes."""
        g = float(np.linalg.norm(gravity))
        weight = np.abs(p.mass - fluid_density * p.volume) * g
        return np.where(weight > 0, weight, p.mass * max(g, 1.0))

    def _walls(self, p: Particles, gravity: np.ndarray, fluid_density: float):
        """``(axis, side, gap (n,), W (n,))`` for every wall."""
        X, R = p.position, p.bounding_radius
        weight = self._weights(p, gravity, fluid_density)
        walls = self.walls if self.walls is not None else [(a, s) for a in range(X.shape[1]) for s in (0, 1)]
        for axis, side in walls:
            plane = (self.lower, self.upper)[side][axis]
            yield axis, side, np.abs(X[:, axis] - plane) - R, weight

    def _pairs(self, p: Particles, gravity: np.ndarray, fluid_density: float):
        """``X_i - X_j`` (n, n, dim) by the nearest image, its length (n, n) and ``W_ij`` (n, n)."""
        X = p.position
        diff = X[:, None, :] - X[None, :, :]
        if self.periods is not None:
            L = np.asarray(self.periods, dtype=float)
            diff -= L * np.round(diff / np.where(L > 0, L, 1.0))
        weight = self._weights(p, gravity, fluid_density)
        return diff, np.linalg.norm(diff, axis=2), np.minimum(weight[:, None], weight[None, :])
