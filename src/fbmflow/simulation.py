"""The particulate-flow time loop (DESIGN.md section 1): particles -> mesh, flow, forces, particles.

Couplings (a registry):

* ``explicit`` (staggered): each step solves the flow with the particles' current rigid velocities
  as fictitious-boundary constraints, evaluates the hydrodynamic forces of the new flow and
  advances the particles with them. Cheap; stable only while the added mass stays below the
  particle mass (see :mod:`fbmflow.particles.dynamics`); at rho_s / rho_f = 1.25 a disk already
  shows a damped step-to-step wobble.
* ``implicit``: the same step iterated to a fixed point, the flow constrained by the particles'
  *new* velocities, with Aitken relaxation of the velocity update (Küttler & Wall 2008); removes
  the added-mass instability at the price of a few flow solves per step.
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
                 integrator: str = "semi-implicit-euler", linear_solver="direct", newton=None,
                 coupling: str = "explicit", coupling_tol: float = 1e-6, max_subiterations: int = 20):
        if coupling not in COUPLINGS:
            raise ValueError(f"unknown coupling {coupling!r}; choose one of {COUPLINGS}")
        self.coupling = coupling
        self.coupling_tol = coupling_tol
        self.max_subiterations = max_subiterations
        self._constraint_state: Particles | None = None
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
        """Rigid-body constraints at the current positions with the velocities of the particle
        state being iterated (the current one for the explicit coupling)."""
        p = self.particles
        v = self._constraint_state or p
        return rigid_body_constraints(V, self._owner(V), p.position, v.velocity, v.angular_velocity)

    def _flow_and_forces(self, dt: float):
        x, reports = advance(self.flow, self.x, self.t, dt, self.scheme)
        space = self.flow.space
        force, torque = hydrodynamic_forces(space, self._owner(space.V), self.particles.position,
                                            x[:space.n_u], x[space.n_u:], self.flow.mu)
        return x, reports, force, torque

    def step(self, dt: float) -> StepReport:
        """Advance flow and particles over ``dt``; ConvergenceError names the step and time."""
        where = f"step {self.step_count + 1} (t = {self.t:.6g} -> {self.t + dt:.6g})"
        try:
            x, reports, force, torque = self._flow_and_forces(dt)
            new = integrate(self.particles, force, torque, self.gravity, self.flow.rho, dt, self.integrator)
            if self.coupling == "implicit":
                x, reports, force, torque, new = self._subiterate(dt, x, reports, new)
        except ConvergenceError as err:
            raise ConvergenceError(f"{where}: {err}") from None
        finally:
            self._constraint_state = None
        if not (np.all(np.isfinite(new.position)) and np.all(np.isfinite(x))):
            raise ConvergenceError(f"{where}: non-finite state")
        self.x, self.particles = x, new
        self.t += dt
        self.step_count += 1
        return StepReport(self.step_count, self.t, sum(r.iterations for r in reports),
                          sum(r.linear_iterations for r in reports), force, torque,
                          self.particles.position.copy(), self.particles.velocity.copy())

    def _subiterate(self, dt, x, reports, new):
        """Fixed-point iteration on the particles' new velocities with Aitken relaxation."""
        def pack(p):
            return np.concatenate([p.velocity.ravel(), np.ravel(p.angular_velocity)])

        guess = self.particles.copy()  # velocities being iterated; positions stay at t_n
        guess.velocity, guess.angular_velocity = new.velocity.copy(), new.angular_velocity.copy()
        omega, r_old = 0.5, None
        for k in range(self.max_subiterations):
            self._constraint_state = guess
            x, reports, force, torque = self._flow_and_forces(dt)
            new = integrate(self.particles, force, torque, self.gravity, self.flow.rho, dt, self.integrator)
            r = pack(new) - pack(guess)
            scale = max(float(np.linalg.norm(pack(new))), 1e-30)
            if np.linalg.norm(r) <= self.coupling_tol * scale:
                return x, reports, force, torque, new
            if r_old is not None:
                dr = r - r_old
                omega = -omega * float(r_old @ dr) / max(float(dr @ dr), 1e-300)
            r_old = r
            upd = pack(guess) + omega * r
            nv = guess.velocity.size
            guess.velocity = upd[:nv].reshape(guess.velocity.shape)
            guess.angular_velocity = upd[nv:].reshape(np.shape(guess.angular_velocity))
        raise ConvergenceError(f"fluid-particle coupling did not converge in {self.max_subiterations} "
                               f"sub-iterations (last change {np.linalg.norm(r) / scale:.1e})")


COUPLINGS = ("explicit", "implicit")
