"""Lubrication correction: the force of the thin fluid film between surfaces closer than the mesh
resolves.

For a gap ``g`` below the resolved range ``delta`` the film's normal force on a pair approaching
at relative normal velocity ``u`` is ``F = -c(g) u`` with, for spheres (3D; Brenner's leading
term, the resolved part at ``delta`` subtracted so that the flow solver and the correction do not
count the film twice),

    c(g) = 6 pi mu R*^2 (1/g - 1/delta),          R* = R_i R_j / (R_i + R_j)  (R_j = inf: a wall),

and for disks (2D, per unit length; the film between two cylinders)

    c(g) = 3 pi / (2 sqrt 2) mu ((R*/g)^(3/2) - (R*/delta)^(3/2)).

``g`` is clipped below at ``min_gap`` (surface roughness; the film force is finite at contact).
The force is stiff (``c -> inf`` as ``g -> 0``), so :class:`~fbmflow.contact.ContactSet` applies
it implicitly in each contact sub-step (backward Euler of the pair's damped approach), before the
contact impulses. Shapes other than balls use their bounding radii.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Lubrication:
    """Lubrication correction with dynamic viscosity ``viscosity`` [Pa s] for gaps below
    ``range_`` [m], saturating at ``min_gap`` [m]."""

    viscosity: float
    range_: float
    min_gap: float

    def __post_init__(self):
        if not (self.viscosity > 0 and self.range_ > 0 and 0 < self.min_gap < self.range_):
            raise ValueError("lubrication needs viscosity > 0, range > 0 and 0 < min_gap < range; got "
                             f"{self.viscosity}, {self.range_}, {self.min_gap}")

    def coefficient(self, gap: np.ndarray, R_i: np.ndarray, R_j: np.ndarray, dim: int) -> np.ndarray:
        """Damping coefficients ``c`` (m,) [N s/m] (2D: per unit length) for surface gaps ``gap``
        and radii ``R_i``, ``R_j`` (``inf`` for a wall); zero at and beyond the range."""
        R = np.where(np.isinf(R_j), R_i, R_i * R_j / (R_i + np.where(np.isinf(R_j), 0.0, R_j)))
        g = np.maximum(gap, self.min_gap)
        if dim == 3:
            c = 6.0 * np.pi * self.viscosity * R**2 * (1.0 / g - 1.0 / self.range_)
        else:
            c = 3.0 * np.pi / (2.0 * np.sqrt(2.0)) * self.viscosity * ((R / g)**1.5 - (R / self.range_)**1.5)
        return np.where(gap < self.range_, np.maximum(c, 0.0), 0.0)
