"""The particulate-flow time loop (DESIGN.md section 1): particles -> mesh, flow, forces, particles.

The coupling is explicit (staggered): each step solves the flow with the particles' current rigid
velocities as fictitious-boundary constraints, evaluates the hydrodynamic forces of the new flow,
and advances the particles with them. See :mod:`fbmflow.particles.dynamics` for when this is
stable.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from .coupling import hydrodynamic_forces, node_owner, rigid_body_constraints
from .flow import NavierStokesProblem
from .flow.time_schemes import advance
from .particles import Particles, integrate
from .solvers import ConvergenceError

log = logging.getLogger(__name__)


@dataclass
class StepReport:
    """What one time step did."""

    step: int
    t: float
    newton_iterations: int
    linear_iterations: int
    force: np.ndarray
    torque: np.ndarray
    position: np.ndarray
    velocity: np.ndarray


class Simulation:
    """Rigid particles in an incompressible flow on a structured mesh.

    Parameters
    ----------
    mesh, viscosity, boundary, density : as for :class:`~fbmflow.flow.NavierStokesProblem`
    particles : Particles
    gravity : (dim,) float64 [m/s^2]
    scheme : time scheme name; integrator : particle integrator name
    linear_solver, newton : passed to the flow problem
    """

    def __init__(self, mesh, viscosity: float, boundary: dict, particles: Particles, gravity,
                 density: float = 1.0, scheme: str = "backward-euler",
                 integrator: str = "semi-implicit-euler", linear_solver="direct", newton=None):
        self.particles = particles
        self.gravity = np.asarray(gravity, dtype=float)
        self.scheme = scheme
        self.integrator = integrator
        kwargs = {} if newton is None else {"newton": newton}
        self.flow = NavierStokesProblem(mesh, viscosity, boundary, density=density,
                                        linear_solver=linear_solver,
                                        extra_constraints=self._constraints, **kwargs)
        self.x = self.flow.zero_state()
        self.t = 0.0
        self.step_count = 0

    def _owner(self, V):
        return node_owner(V, self.particles.position, self.particles.shapes, self.particles.rotations())

    def _constraints(self, V, t):
        p = self.particles
        return rigid_body_constraints(V, self._owner(V), p.position, p.velocity, p.angular_velocity)

    def step(self, dt: float) -> StepReport:
        """Advance flow and particles over ``dt``; ConvergenceError names the step and time."""
        try:
            self.x, reports = advance(self.flow, self.x, self.t, dt, self.scheme)
        except ConvergenceError as err:
            raise ConvergenceError(f"step {self.step_count + 1} (t = {self.t:.6g} -> {self.t + dt:.6g}): {err}") from None
        space = self.flow.space
        u, p = self.x[:space.n_u], self.x[space.n_u:]
        owner = self._owner(space.V)
        force, torque = hydrodynamic_forces(space, owner, self.particles.position, u, p, self.flow.mu)
        self.particles = integrate(self.particles, force, torque, self.gravity, self.flow.rho, dt,
                                   self.integrator)
        if not (np.all(np.isfinite(self.particles.position)) and np.all(np.isfinite(self.x))):
            raise ConvergenceError(f"step {self.step_count + 1} (t = {self.t + dt:.6g}): non-finite state")
        self.t += dt
        self.step_count += 1
        return StepReport(self.step_count, self.t, sum(r.iterations for r in reports),
                          sum(r.linear_iterations for r in reports), force, torque,
                          self.particles.position.copy(), self.particles.velocity.copy())
