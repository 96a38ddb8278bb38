"""Rigid particle shapes, in body coordinates, knowing nothing of meshes.

Every shape gives a vectorised inside test on points ``(n, dim)`` relative to its centre of mass
in body axes, its volume (area in 2D), and its inertia tensor per unit density in body axes
(``dim = 2``: the scalar polar moment ``int (x^2 + y^2) dV`` as a 1 x 1 array).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Ball:
    """Disk (``dim = 2``) or sphere (``dim = 3``) of the given radius [m]."""

    radius: float
    dim: int = 2

    def __post_init__(self):
        if not self.radius > 0:
            raise ValueError(f"radius must be positive, got {self.radius}")
        if self.dim not in (2, 3):
            raise ValueError(f"dim must be 2 or 3, got {self.dim}")

    def inside(self, x: np.ndarray) -> np.ndarray:
        """Points ``x (n, dim)`` (body frame) inside or on the surface -> (n,) bool."""
        return np.einsum("ij,ij->i", x, x) <= self.radius**2

    @property
    def bounding_radius(self) -> float:
        return self.radius

    @property
    def volume(self) -> float:
        r = self.radius
        return np.pi * r**2 if self.dim == 2 else 4.0 / 3.0 * np.pi * r**3

    @property
    def inertia(self) -> np.ndarray:
        """Inertia per unit density: ``pi r^4 / 2`` (disk, 1 x 1) or ``8 pi r^5 / 15 I`` (sphere)."""
        r = self.radius
        if self.dim == 2:
            return np.array([[np.pi * r**4 / 2.0]])
        return np.eye(3) * (8.0 * np.pi * r**5 / 15.0)
