"""Lubrication correction: the part of the thin fluid film's force between close surfaces that
the mesh does not resolve.

The film's normal force on a pair at surface gap ``g`` approaching at relative normal velocity
``u`` is ``F = -c(g) u``. For spheres (3D) the exact Stokes resistance near contact is (Cox &
Brenner 1967; Jeffrey & Onishi 1984)

    C(g) = 6 pi mu [R*^2 / g + l ln(1 / g)] + smooth,      R* = R_i R_j / (R_i + R_j),
    l = R_i beta (1 + 7 beta + beta^2) / (5 (1 + beta)^3),  beta = R_j / R_i,

(a wall: ``R_j = inf``, ``R* = R_i``, ``l = R_i / 5``); for disks (2D, per unit length) the
film between two cylinders gives ``C(g) = 3 pi / (2 sqrt 2) mu (R* / g)^(3/2)``. A fictitious
boundary on a mesh of spacing ``h`` resolves the film only down to gaps of about a cell: the
flow's film force behaves as ``C`` at the effective gap ``g_e = (g^p + s^p)^(1/p)``, with ``s``
(``resolved_gap``) a fraction of a cell and ``p`` = :data:`BLEND_EXPONENT`: both fitted to
Brenner's exact drag at 6 cells per diameter, of a sphere approaching a wall and of two spheres
approaching each other, whose resolved film moves by up to 20 % with where their midplane falls
between mesh planes (benchmarks/studies/lubrication.py; ``s`` 0.37 cells, the default of
``contact.lubrication_resolved_cells``). The correction adds what is missing,

    c(g) = [C(g) - C(g_e(g))] - [C(delta) - C(g_e(delta))]   for g < delta (the range), else 0,

continuous at ``delta`` and vanishing like ``s^2 / g^3`` far from contact, so that the flow
solver and the correction do not count the film twice. ``g`` is clipped below at ``min_gap``
(surface roughness; the film force is finite at contact). The force is stiff (``c -> inf`` as
``g -> 0``), so :class:`~fbmflow.contact.contact_set.ContactSet` applies it implicitly in each contact
sub-step (backward Euler of the pair's damped approach), before the contact impulses. Shapes
other than balls use their bounding radii.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: exponent ``p`` of the effective gap ``(g^p + s^p)^(1/p)`` that the resolved flow's film sees
#: (fitted with ``s`` to Brenner's drag at 6 cells per diameter: docs/validation/lubrication.md,
#: "Lubrication")
BLEND_EXPONENT = 1.75


@dataclass(frozen=True)
class Lubrication:
    """Lubrication correction with dynamic viscosity ``viscosity`` [Pa s] for gaps below
    ``range_`` [m], saturating at ``min_gap`` [m], for a flow that resolves the film down to
    gaps of about ``resolved_gap`` [m] (0: the pure near-contact law less its value at the range,
    ``C(g) - C(delta)``)."""

    viscosity: float
    range_: float
    min_gap: float
    resolved_gap: float = 0.0

    def __post_init__(self):
        if not (self.viscosity > 0 and self.range_ > 0 and 0 < self.min_gap < self.range_
                and self.resolved_gap >= 0):
            raise ValueError("lubrication needs viscosity > 0, range > 0, 0 < min_gap < range and "
                             f"resolved_gap >= 0; got {self.viscosity}, {self.range_}, {self.min_gap}, "
                             f"{self.resolved_gap}")

    def _unresolved(self, g: np.ndarray, R: np.ndarray, log_arm: np.ndarray, dim: int) -> np.ndarray:
        """``C(g) - C(g_e)`` [N s/m], ``g_e = (g^p + s^p)^(1/p)``: the film force per unit approach
        speed at gap ``g`` that the flow does not carry (``g_e = delta`` where ``s`` is 0)."""
        s, p = self.resolved_gap, BLEND_EXPONENT
        g_e = (g**p + s**p) ** (1.0 / p) if s > 0 else np.full_like(g, self.range_)
        if dim == 3:
            return 6.0 * np.pi * self.viscosity * (R**2 * (1.0 / g - 1.0 / g_e) + log_arm * np.log(g_e / g))
        return 3.0 * np.pi / (2.0 * np.sqrt(2.0)) * self.viscosity * ((R / g)**1.5 - (R / g_e)**1.5)

    def coefficient(self, gap: np.ndarray, R_i: np.ndarray, R_j: np.ndarray, dim: int) -> np.ndarray:
        """Damping coefficients ``c`` (m,) [N s/m] (2D: per unit length) for surface gaps ``gap``
        and radii ``R_i``, ``R_j`` (``inf`` for a wall); zero at and beyond the range."""
        wall = np.isinf(R_j)
        beta = np.where(wall, 1.0, R_j / R_i)
        R = np.where(wall, R_i, R_i * beta / (1.0 + beta))
        log_arm = np.where(wall, R_i / 5.0, R_i * beta * (1 + 7 * beta + beta**2) / (5 * (1 + beta)**3))
        g = np.maximum(gap, self.min_gap)
        at_range = self._unresolved(np.full_like(g, self.range_), R, log_arm, dim)
        c = self._unresolved(g, R, log_arm, dim) - at_range
        return np.where(gap < self.range_, np.maximum(c, 0.0), 0.0)
