"""The sections every scene and :class:`~fbmflow.simulation.Simulation` shares that belong to no
package: the fluid (:class:`~fbmflow.params.FluidParams`) and the time stepping
(:class:`~fbmflow.params.TimeParams`). The
parameter machinery is :mod:`fbmflow.config`; the solver, coupling and contact sections live in
their packages (``solvers.settings``, ``coupling.settings``, ``contact.settings``)."""
from __future__ import annotations

import dataclasses
import math

from .config import Section, param


# -- sections shared by scenes and the Simulation ------------------------------------------------
@dataclasses.dataclass(frozen=True)
class FluidParams(Section):
    """A Newtonian fluid and gravity, in any consistent units (SI shown; the CGS scenes use g, cm, s)."""

    density: float = param(1000.0, "fluid density rho_f", "kg/m^3", positive=True)
    viscosity: float = param(1e-3, "dynamic viscosity mu", "Pa s", positive=True)
    gravity: float = param(9.81, "gravitational acceleration, pointing along the last axis downwards",
                           "m/s^2", nonnegative=True)

    def gravity_vector(self, dim: int):
        """Gravity as a vector, ``(dim,)`` float: ``(0, ..., 0, -gravity)``."""
        g = [0.0] * dim
        g[-1] = -self.gravity
        return g


#: the time schemes a ``scheme`` parameter may name: the names of
#: :data:`fbmflow.flow.time_schemes.TIME_SCHEMES` (a test keeps the two equal; this module sits below
#: the flow package)
SCHEMES = ("backward-euler", "crank-nicolson", "fractional-step-theta")


@dataclasses.dataclass(frozen=True)
class TimeParams(Section):
    """Time stepping."""

    dt: float = param(0.01, "time step", "s", positive=True)
    t_end: float = param(1.0, "final time", "s", positive=True)
    scheme: str = param("fractional-step-theta", "implicit time scheme", choices=SCHEMES)

    @property
    def n_steps(self) -> int:
        """Steps to reach ``t_end`` (the last one lands on it: ``dt`` is shortened evenly)."""
        return max(1, math.ceil(self.t_end / self.dt - 1e-9))
