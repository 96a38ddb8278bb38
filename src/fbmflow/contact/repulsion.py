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
        X = p.position
        n, dim = X.shape
        R = p.bounding_radius
        weight = np.abs(p.mass - fluid_density * p.volume) * float(np.linalg.norm(gravity))
        weight = np.where(weight > 0, weight, p.mass * max(float(np.linalg.norm(gravity)), 1.0))
        F = np.zeros((n, dim))
        walls = self.walls if self.walls is not None else [(a, s) for a in range(dim) for s in (0, 1)]
        for axis, side in walls:
            plane = (self.lower, self.upper)[side][axis]
            gap = np.abs(X[:, axis] - plane) - R
            push = np.maximum(self.range_ - gap, 0.0) / self.range_
            F[:, axis] += (1.0 if side == 0 else -1.0) * self.strength * weight * push**2
        if n > 1:
            diff = X[:, None, :] - X[None, :, :]
            if self.periods is not None:
                L = np.asarray(self.periods, dtype=float)
                diff -= L * np.round(diff / np.where(L > 0, L, 1.0))
            dist = np.linalg.norm(diff, axis=2)
            np.fill_diagonal(dist, np.inf)
            push = np.maximum(self.range_ - (dist - R[:, None] - R[None, :]), 0.0) / self.range_
            w = np.minimum(weight[:, None], weight[None, :])
            F += np.einsum("ij,ijk->ik", self.strength * w * push**2 / dist, diff)
        F[p.fixed] = 0.0
        return F
