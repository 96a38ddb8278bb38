"""The sections every scene and :class:`~fbmflow.simulation.Simulation` shares that belong to no
package: the fluid (:class:`~fbmflow.params.FluidParams`) and the time stepping
(:class:`~fbmflow.params.TimeParams`). The
parameter machinery is :mod:`fbmflow.config`; the solver, coupling and contact sections live in
their packages (``solvers.settings``, ``coupling.settings``, ``contact.settings``)."""
from __future__ import annotations

import dataclasses
import math

from .config import ParamError, Section, param


# -- sections shared by scenes and the Simulation ------------------------------------------------
@dataclasses.dataclass(frozen=True)
class FluidParams(Section):
    """A Newtonian fluid and gravity, in any consistent units (SI shown; the CGS scenes use g, cm, s)."""

    density: float = param(1000.0, "fluid density rho_f", "kg/m^3", positive=True)
    viscosity: float = param(1e-3, "dynamic viscosity mu", "Pa s", positive=True)
    gravity: float = param(9.81, "gravitational acceleration, pointing along the last axis downwards",
                           "m/s^2", nonnegative=True)

    def validate(self):
        """Values whose products overflow (or vanish) in double precision: no fluid is that."""
        for name in ("density", "viscosity", "gravity"):
            value = getattr(self, name)
            if value and not 1e-100 <= value <= 1e100:
                raise ParamError(f"fluid.{name} = {value!r} is outside 1e-100 to 1e100, where the flow's "
                                 "matrices overflow or vanish; use consistent units of a real fluid")

    def gravity_vector(self, dim: int):
        """Gravity as a vector, ``(dim,)`` float: ``(0, ..., 0, -gravity)``."""
        g = [0.0] * dim
        g[-1] = -self.gravity
        return g


#: the most time steps a run may take (a larger count is a typo: it would not end, and its step count
#: overflows what a run stores)
MAX_STEPS = 10**8
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
    adaptive: bool = param(False, "choose each step by a local error estimate of the particles' paths "
                           "(fbmflow.adaptive; dt: the first step)")
    tolerance: float = param(1e-3, "adaptive: the largest local error of a particle's path in a step, a "
                             "fraction of the cell that holds it", positive=True, maximum=1.0)
    max_courant: float = param(0.5, "adaptive: the largest U dt / h of a step (U: the fastest particle's "
                               "speed, h: the cell that holds it)", positive=True, maximum=10.0)

    def validate(self):
        if self.dt > 0 and self.t_end / self.dt > MAX_STEPS:  # (a scene may leave dt 0 to its set-up)
            raise ParamError(f"time.t_end / time.dt = {self.t_end / self.dt:.3g} steps, more than "
                             f"{MAX_STEPS:.0e}: use a larger time.dt or a shorter time.t_end")

    @property
    def n_steps(self) -> int:
        """Steps to reach ``t_end`` (the last one lands on it: ``dt`` is shortened evenly)."""
        return max(1, math.ceil(self.t_end / self.dt - 1e-9))
