"""Brenner (1961): the exact Stokes drag of a sphere moving slowly towards a plane.

H. Brenner, "The slow motion of a sphere through a viscous fluid towards a plane surface",
Chem. Eng. Sci. 16 (1961) 242-251, eqs. (2.19) and (3.13). A sphere of radius ``a`` whose centre
is ``a + h`` from the plane moves towards it at speed ``U`` in fluid of viscosity ``mu``; the
fluid resists with ``F = 6 pi mu a U lambda(h / a)``, with ``alpha = arccosh(1 + h / a)`` and::

    rigid wall (no slip):
    lambda = 4/3 sinh(alpha) sum_n n(n+1)/((2n-1)(2n+3))
             [(2 sinh((2n+1) alpha) + (2n+1) sinh(2 alpha))
              / (4 sinh^2((n+1/2) alpha) - (2n+1)^2 sinh^2(alpha)) - 1],

    free surface (zero normal velocity and shear stress):
    lambda = 4/3 sinh(alpha) sum_n n(n+1)/((2n-1)(2n+3))
             [(4 cosh^2((n+1/2) alpha) + (2n+1)^2 sinh^2(alpha))
              / (2 sinh((2n+1) alpha) - (2n+1) sinh(2 alpha)) - 1].

The free surface is the mirror plane of two equal spheres approaching each other, each at speed
``U`` with surface gap ``2 h`` (Maude 1961; Stimson & Jeffery's bispherical set-up): the same
``lambda`` gives the force on each. Near contact ``lambda ~ a / h`` (wall) and ``a / (4 h)``
(free surface, i.e. ``a / (2 g)`` for the spheres' gap ``g``); far away
``lambda ~ 1 + 9/8 a / (a + h)`` and ``1 + 3/4 a / (a + h)``.
"""
from __future__ import annotations

import numpy as np


def drag_factor(h_over_a, wall: str = "rigid") -> np.ndarray:
    """``lambda = F / (6 pi mu a U)`` for gaps ``h / a`` (array, > 0) between the sphere's surface
    and a ``"rigid"`` (no-slip) or ``"free"`` (slip) plane; the series summed until its terms
    fall below double precision."""
    if wall not in ("rigid", "free"):
        raise ValueError(f"wall must be 'rigid' or 'free', got {wall!r}")
    gaps = np.asarray(h_over_a, dtype=float)
    if not np.all(gaps > 0):
        raise ValueError("the gaps h / a must be positive")
    out = np.empty(gaps.shape)
    for i, g in np.ndenumerate(gaps):
        alpha = np.arccosh(1.0 + g)
        n = np.arange(1, max(int(350.0 / alpha), 2))  # (2n+1) alpha < 700: no overflow
        m = 2 * n + 1
        s = np.sinh(alpha)
        if wall == "rigid":
            ratio = (2 * np.sinh(m * alpha) + m * np.sinh(2 * alpha)) / (
                4 * np.sinh(m * alpha / 2) ** 2 - m**2 * s**2)
        else:
            ratio = (4 * np.cosh(m * alpha / 2) ** 2 + m**2 * s**2) / (
                2 * np.sinh(m * alpha) - m * np.sinh(2 * alpha))
        out[i] = 4.0 / 3.0 * s * np.sum(n * (n + 1) / ((2 * n - 1) * (2 * n + 3)) * (ratio - 1.0))
    return out
