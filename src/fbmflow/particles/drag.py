"""Drag correlations of a single sphere or circular cylinder in unbounded fluid, and the terminal
velocity they give: a velocity *scale* fixed before a run (the time step that follows the mesh,
:class:`~fbmflow.scenes.builder.MeshTime`), never a result.

Sphere (``dim = 3``), Schiller & Naumann (1933), ``Re < 800``:

.. math:: C_D = \\frac{24}{Re}\\,(1 + 0.15\\,Re^{0.687}).

Circular cylinder per unit length (``dim = 2``), White (1991, eq. 3-225), ``1e-4 < Re < 2e5``:

.. math:: C_D = 1.18 + 6.8\\,Re^{-0.89} + 1.96\\,Re^{-1/2} - \\frac{0.0004\\,Re}{1 + 3.64\\cdot10^{-7} Re^2}.

``Re = rho_f U d / mu``; the drag is ``C_D rho_f U^2 A / 2`` with ``A = pi d^2 / 4`` (sphere) or
``d`` (cylinder, per unit length). The terminal velocity balances it with the net weight
``|rho_s - rho_f| g V``. Walls slow a particle: in Glowinski's 2 cm channel the disk's
correlation velocity (6.59 cm/s) is 18 % above the computed peak (5.6 cm/s); ten Cate's sphere
reads 0.0409 / 0.0635 / 0.0939 / 0.1290 m/s for E1-E4 against the unbounded terminal
velocities ten Cate et al. give, 0.038 / 0.060 / 0.091 / 0.128 m/s (tests/particles/test_drag.py).
"""
from __future__ import annotations

import math

from scipy.optimize import brentq


def drag_coefficient(reynolds: float, dim: int) -> float:
    """``C_D(Re)`` of a sphere (``dim = 3``) or a cylinder per unit length (``dim = 2``)."""
    if reynolds <= 0:
        raise ValueError(f"drag_coefficient: Re must be positive, got {reynolds}")
    if dim == 3:
        return 24.0 / reynolds * (1.0 + 0.15 * reynolds**0.687)
    if dim == 2:
        return (1.18 + 6.8 * reynolds**-0.89 + 1.96 / math.sqrt(reynolds)
                - 0.0004 * reynolds / (1.0 + 3.64e-7 * reynolds**2))
    raise ValueError(f"drag_coefficient: dim must be 2 or 3, got {dim}")


def terminal_velocity(diameter: float, density: float, fluid_density: float, viscosity: float,
                      gravity: float, dim: int) -> float:
    """Speed [velocity units] at which the correlation's drag balances the net weight of a sphere
    (``dim = 3``) or a disk, a cylinder per unit length (``dim = 2``), of ``diameter`` and
    ``density`` in a fluid of ``fluid_density`` and dynamic ``viscosity``; 0 for a neutrally
    buoyant particle or no gravity."""
    weight = abs(density - fluid_density) * gravity * (
        math.pi * diameter**3 / 6 if dim == 3 else math.pi * diameter**2 / 4)
    if weight == 0:
        return 0.0
    area = math.pi * diameter**2 / 4 if dim == 3 else diameter

    def excess(u: float) -> float:
        re = fluid_density * u * diameter / viscosity
        return 0.5 * drag_coefficient(re, dim) * fluid_density * u**2 * area - weight

    # Stokes' velocity bounds the sphere's from above; the cylinder's drag exceeds 1.18 of the
    # dynamic pressure, which bounds its velocity too
    stokes = weight / (3 * math.pi * viscosity * diameter)
    upper = stokes if dim == 3 else math.sqrt(2 * weight / (1.18 * fluid_density * area))
    lower = upper * 1e-12
    while excess(lower) > 0:  # (the cylinder's correlation at tiny Re)
        lower *= 1e-3
    return brentq(excess, lower, upper * (1 + 1e-9), xtol=1e-14 * upper, rtol=1e-12)
