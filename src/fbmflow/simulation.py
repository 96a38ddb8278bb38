"""The particulate-flow time loop (docs/design.md, "One time step"): particles -> mesh, flow, forces,
particles.

Couplings (a registry):

* ``explicit`` (staggered): each step solves the flow with the particles' current rigid velocities
  as fictitious-boundary constraints, evaluates the hydrodynamic forces of the new flow and
  advances the particles with them. Cheap; stable only while the added mass stays below the
  particle mass (see :mod:`fbmflow.particles.dynamics`); at rho_s / rho_f = 1.25 a disk already
  shows a damped step-to-step wobble.
* ``implicit``: the same step iterated to a fixed point, the flow constrained by the particles'
  *new* velocities, by Newton's method on the particle velocities with the discrete added-mass
  and drag matrix from the flow's linear response to unit rigid motions; removes the added-mass
  instability at the price of one linear response per rigid degree of freedom (3 per disk, 6 per
  sphere, back-substitutions with the last factorisation) and two to three flow solves per step.
"""
from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .contact import ContactReport
from .coupling import (SurfaceForces, TestFunctionForces, hydrodynamic_forces, mirror_images, node_owner,
                       rigid_body_constraints, rigid_liftings, sharp_boundary, supports_sharp_boundary,
                       supports_surface_force)
from .flow import NavierStokesProblem
from .flow.time_schemes import advance, pressure_lag
from .particles import (Particles, accelerations, integrate, pack_velocities, symmetric_motion,
                        unpack_velocities, velocity_gain)
from .solvers import ConvergenceError
from .solvers.linear import LinearWork

log = logging.getLogger(__name__)


@dataclass
class StepReport:
    """What one time step did."""

    step: int
    t: float
    newton_iterations: int
    force: np.ndarray
    torque: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    flow_solves: int = 1  # flow solves of the coupling iteration (1 for the explicit coupling)
    contact: ContactReport | None = None  # what the contact solver did (None without contact)
    linear: LinearWork = dataclasses.field(default_factory=LinearWork)  # the step's linear solves
    # (Newton steps and the coupling's lifting responses)


class Simulation:
    """Rigid particles in an incompressible flow on a structured mesh.

    Parameters
    ----------
    mesh, viscosity, boundary, density : as for :class:`~fbmflow.flow.NavierStokesProblem`
    particles : Particles
    gravity : (dim,) float64 [m/s^2]
    scheme : time scheme name; integrator : particle integrator name
        (:data:`~fbmflow.particles.dynamics.INTEGRATORS`; ``trapezoidal`` with ``crank-nicolson``
        is second order in time)
    linear_solver, newton : passed to the flow problem
    coupling : ``explicit`` or ``implicit`` (see the module docstring)
    first_solve_rtol : float or None
        Implicit coupling: Newton's residual reduction in each step's first flow solve, which
        only seeds the coupling iteration (its forces give the first velocity update, its
        linearisation the responses); the later solves, whose flow is kept, use the Newton
        settings' ``rtol``, and the step always ends on one of them. None: the same for all.
        (Measured effect: docs/validation.md, "Multigrid with fictitious boundaries".)
    symmetry : normal axes of mirror planes that cut the domain through every particle centre
        (the domain's faces there carry :class:`~fbmflow.flow.Slip`); forces and torques are those
        of the whole particles (:func:`~fbmflow.coupling.mirror_images`), the particles' motion
        stays on the planes. Gravity must lie in the planes.
    repulsion : :class:`~fbmflow.contact.Repulsion` or None, short-range repulsive forces that
        keep particles off the walls and each other (the flow cannot resolve the last gap).
    contact : :class:`~fbmflow.contact.ContactSet` or None, hard contact: the particles then
        advance over a fluid step in ``contact_substeps`` contact sub-steps with the hydrodynamic
        force of the step held constant (semi-implicit Euler with contact impulses, see
        :mod:`fbmflow.contact.contact_set`), so that contact resolution does not depend on the
        fluid time step. With the implicit coupling, contact acts once the coupling iteration has
        converged (a collision's velocity change reaches the flow in the next step).
    fbm : ``nodes`` (every node inside a particle moves rigidly; first order in the mesh size) or
        ``sharp`` (the no-slip condition on the true surface, :mod:`fbmflow.coupling.sharp`;
        shapes with ``project``, the direct linear solver)
    force : ``volume`` (``-int sigma . grad alpha`` over the cut cells,
        :func:`~fbmflow.coupling.hydrodynamic_forces`) or ``test-function`` (the momentum balance
        tested with a function that is one on the particle, :class:`~fbmflow.coupling.TestFunctionForces`;
        ``du/dt`` is the step's mean acceleration ``(u - u_old) / dt``) or ``surface`` (the
        traction integrated over the true surface, :class:`~fbmflow.coupling.SurfaceForces`;
        balls with the sharp boundary)
    """

    def __init__(self, mesh, viscosity: float, boundary: dict, particles: Particles, gravity,
                 density: float = 1.0, scheme: str = "backward-euler",
                 integrator: str = "semi-implicit-euler", linear_solver="direct", newton=None,
                 coupling: str = "explicit", coupling_tol: float = 1e-6, max_subiterations: int = 20,
                 symmetry: tuple = (), repulsion=None, contact=None, contact_substeps: int = 1,
                 fbm: str = "nodes", force: str = "volume", first_solve_rtol: float | None = None):
        if coupling not in COUPLINGS:
            raise ValueError(f"unknown coupling {coupling!r}; choose one of {COUPLINGS}")
        if contact is not None and integrator != "semi-implicit-euler":
            raise ValueError("hard contact advances the particles by semi-implicit Euler; "
                             f"integrator {integrator!r} cannot be combined with it")
        if contact_substeps < 1:
            raise ValueError(f"contact_substeps must be >= 1, got {contact_substeps}")
        if fbm not in FBM_BOUNDARIES:
            raise ValueError(f"unknown fictitious boundary {fbm!r}; choose one of {FBM_BOUNDARIES}")
        if force not in FORCES:
            raise ValueError(f"unknown hydrodynamic force {force!r}; choose one of {FORCES}")
        if fbm == "sharp" and not supports_sharp_boundary(particles.shapes):
            raise ValueError("the sharp fictitious boundary needs shapes with a closest-point projection "
                             "(Ball, Box, Cylinder); use fbm='nodes' for the others")
        if force == "surface" and not (fbm == "sharp" and supports_surface_force(particles.shapes)):
            raise ValueError("force='surface' integrates the traction over the true surface of balls with the "
                             "sharp boundary (the nodal boundary's cut cells carry no flow up to the surface); "
                             "use fbm='sharp' with balls, or force='volume'")
        self.fbm = fbm
        self.force = force
        self._estimator_of = None  # the force's test functions or surface rule for the current state
        self.contact = contact
        self.contact_substeps = int(contact_substeps)
        self._contact_report = None
        self.symmetry = tuple(symmetry)
        self.repulsion = repulsion
        _check_symmetry(mesh, particles, np.asarray(gravity, dtype=float), self.symmetry)
        _check_placement(mesh, particles, self.symmetry)
        self.coupling = coupling
        self.coupling_tol = coupling_tol
        if first_solve_rtol is not None and not 0.0 < first_solve_rtol < 1.0:
            raise ValueError(f"first_solve_rtol must lie in (0, 1), got {first_solve_rtol}")
        self.first_solve_rtol = first_solve_rtol
        self.max_subiterations = max_subiterations
        self._constraint_state: Particles | None = None
        self._owner_of: np.ndarray | None = None  # positions and orientations of _owner_cache
        self._owner_cache: dict = {}  # id of the DOF map (fine or multigrid level) -> owner
        self._sharp_of = None  # the sharp boundary of the current state
        self._behind = None  # (centres, owner or SurfaceForces) where the pressure's force is taken
        self.particles = particles
        self.gravity = np.asarray(gravity, dtype=float)
        self.scheme = scheme
        self._pressure_lag = pressure_lag(scheme)
        self.integrator = integrator
        kwargs = {} if newton is None else {"newton": newton}
        self.flow = NavierStokesProblem(mesh, viscosity, boundary, density=density,
                                        linear_solver=linear_solver,
                                        extra_constraints=self._constraints, **kwargs)
        self.x = self.flow.zero_state()
        self.t = 0.0
        self.step_count = 0
        # hydrodynamic force (n, dim) and torque (n, 3) at the end of the last step (None before
        # the first: unknown, the fluid's reaction to the first acceleration is not zero)
        self._last_force: np.ndarray | None = None
        self._last_torque: np.ndarray | None = None
        self._warned_fast = False  # the warning about particles crossing cells in a step is given once

    def owner(self) -> np.ndarray:
        """Particle owning every Q2 velocity node at the current state (-1: fluid), (n_v,) int64."""
        return self._owner(self.flow.space.V)

    def _owner(self, V):
        """Owner of every node for the current particle state; computed once per state (the
        positions do not change during a step's flow solves and coupling iterations)."""
        p = self.particles
        key = np.concatenate([p.position.ravel(), np.ravel(p.orientation)])
        if self._owner_of is None or not np.array_equal(self._owner_of, key):
            self._owner_cache, self._sharp_of, self._estimator_of, self._owner_of = {}, None, None, key
        if id(V) not in self._owner_cache:
            self._owner_cache[id(V)] = node_owner(V, p.position, p.shapes, p.rotations())
        return self._owner_cache[id(V)]

    def _sharp(self, V):
        """The sharp boundary on the fine DOF map ``V`` for the current particle state (None for
        the nodal boundary and on coarser multigrid levels); computed once per state."""
        if self.fbm != "sharp" or V is not self.flow.space.V:
            return None
        owner = self._owner(V)  # resets the caches when the particles moved
        if self._sharp_of is None:
            p = self.particles
            self._sharp_of = sharp_boundary(self.flow.space, owner, p.position, p.shapes, p.rotations())
        return self._sharp_of

    def _constraints(self, V, t):
        """Fictitious-boundary constraints at the current positions with the velocities of the
        particle state being iterated (the current one for the explicit coupling): rigid motion
        on the particles' nodes, with the sharp boundary's changes on the fine level."""
        p = self.particles
        v = self._constraint_state or p
        rigid = rigid_body_constraints(V, self._owner(V), p.position, v.velocity, v.angular_velocity)
        sharp = self._sharp(V)
        return rigid if sharp is None else sharp.constraints(rigid, v.velocity, v.angular_velocity)

    def _forces(self, owner: np.ndarray, x: np.ndarray, dt: float, about: np.ndarray | None = None):
        """Hydrodynamic force (n, dim) and torque (n, 3) of the whole particles for the flow ``x``
        at the end of a step of length ``dt`` from ``self.x``; with ``about`` (a flow), ``x`` is a
        change of that flow and the result the force's change (linear in ``x``).

        The volume and surface forces take the pressure's part where the pressure belongs: on
        the particles moved back by ``lag dt U`` (``lag``:
        :func:`~fbmflow.flow.time_schemes.pressure_lag`, one half with Crank–Nicolson; ``U`` the
        velocities at the step's start: ``dt U`` is the last step's displacement to first order).
        Measured (glowinski-free-fall, 4 cells/D, dt 4 / 2 / 1 ms): the settling velocity's
        plateau moves -0.80 / -0.34 % (volume force) and -0.50 / -0.16 % (surface force) between
        the time steps with it, +0.78 / +0.53 % (surface, order 0.5) without. Rotation is left
        out of the lag (none for balls).
        """
        space = self.flow.space
        n_u = space.n_u
        u, p = x[:n_u], x[n_u:]
        if self.force == "test-function":
            u_old, linear = (self.x[:n_u], None) if about is None else (None, about[:n_u])
            force, torque = self._estimator(owner)(u, p, self.flow.mu, self.flow.rho,
                                                   u_old=u_old, dt=dt, about=linear)
        else:
            here = owner if self.force == "volume" else self._estimator(owner)
            if self._pressure_lag == 0.0 or not np.any(self.particles.velocity):
                force, torque = self._stress(here, self.particles.position, u, p)
            else:
                force, torque = self._stress(here, self.particles.position, u, np.zeros_like(p))
                behind = self.particles.position - self._pressure_lag * dt * self.particles.velocity
                force_p, torque_p = self._stress(self._rule_behind(behind), behind, np.zeros_like(u), p)
                force, torque = force + force_p, torque + torque_p
        return mirror_images(force, torque, self.symmetry) if self.symmetry else (force, torque)

    def _stress(self, rule, centres: np.ndarray, u: np.ndarray, p: np.ndarray):
        """Force and torque of the stress of ``(u, p)`` on the particles at ``centres``: by the
        volume rule with ``rule`` their node owner, or by ``rule`` a SurfaceForces."""
        if self.force == "volume":
            return hydrodynamic_forces(self.flow.space, rule, centres, u, p, self.flow.mu)
        return rule(u, p, self.flow.mu)

    def _rule_behind(self, centres: np.ndarray):
        """Node owner (volume force) or SurfaceForces of the particles moved to ``centres``,
        built once per centres."""
        if self._behind is None or not np.array_equal(self._behind[0], centres):
            pts = self.particles
            rule = (node_owner(self.flow.space.V, centres, pts.shapes, pts.rotations()) if self.force == "volume"
                    else SurfaceForces(self.flow.space, centres, pts.shapes))
            self._behind = (centres.copy(), rule)
        return self._behind[1]

    def _estimator(self, owner: np.ndarray):
        """The force's test functions (TestFunctionForces) or surface rule (SurfaceForces) for the
        current particle state (computed once per state)."""
        if self._estimator_of is None:
            p, space = self.particles, self.flow.space
            if self.force == "surface":
                self._estimator_of = SurfaceForces(space, p.position, p.shapes)
            else:
                fixed = self.flow.fine.boundary_constraints.dofs
                walls = np.flatnonzero(np.bincount(fixed % space.n_v, minlength=space.n_v) == space.dim)
                self._estimator_of = TestFunctionForces(space, owner, p.position, p.shapes, p.rotations(), walls)
        return self._estimator_of

    def _flow_and_forces(self, dt: float, guess: np.ndarray | None = None, rtol: float | None = None):
        x, reports = advance(self.flow, self.x, self.t, dt, self.scheme, guess, rtol)
        force, torque = self._forces(self._owner(self.flow.space.V), x, dt)
        return x, reports, force, torque

    def _integrate(self, force: np.ndarray, torque: np.ndarray, dt: float, contact: bool = True) -> Particles:
        """New particle state under the hydrodynamic and the repulsive forces (the latter at the
        positions of the start of the step) and, with hard contact (unless ``contact`` is False),
        the contact impulses."""
        previous = None  # the trapezoidal rule's forces at the start of the step (None: no history)
        if self._last_force is not None:
            previous = self._last_force, self._last_torque
        if self.repulsion is not None:
            repulsion = self.repulsion.forces(self.particles, self.gravity, self.flow.rho)
            force = force + repulsion
            if previous is not None:
                previous = (previous[0] + repulsion, previous[1])
        if self.contact is None or not contact:
            return integrate(self.particles, force, torque, self.gravity, self.flow.rho, dt, self.integrator,
                             previous)
        lin, ang = accelerations(self.particles, force, torque, self.gravity, self.flow.rho)
        new, self._contact_report = self.contact.advance(self.particles, lin, ang, dt, self.contact_substeps)
        return new

    def state(self) -> dict:
        """Everything a restart needs, as arrays and numbers: flow ``x``, time, step count, the
        particles' positions, velocities, orientations, angular velocities, densities, fixed
        flags and the contact warm-start impulses. (The shapes come from the scene.)"""
        p = self.particles
        out = {"x": self.x.copy(), "t": self.t, "step_count": self.step_count,
               "position": p.position.copy(), "velocity": p.velocity.copy(),
               "orientation": p.orientation.copy(), "angular_velocity": p.angular_velocity.copy(),
               "density": p.density.copy(), "fixed": p.fixed.copy()}
        if self._last_force is not None:  # the trapezoidal rule's force history (none before step 1)
            out.update(last_force=self._last_force.copy(), last_torque=self._last_torque.copy())
        if self.contact is not None:
            out.update({f"contact_{k}": v for k, v in self.contact.state().items()})
        return out

    def set_state(self, state: dict) -> None:
        """Restore :meth:`state`; ValueError when it does not fit this simulation."""
        p = self.particles
        if np.shape(state["x"]) != self.x.shape or np.shape(state["position"]) != p.position.shape:
            raise ValueError(f"state of {np.shape(state['position'])[0]} particles and "
                             f"{np.size(state['x'])} unknowns does not fit this simulation "
                             f"({p.n} particles, {self.x.size} unknowns)")
        if (self.contact is not None) != ("contact_keys" in state):
            raise ValueError("the state and this simulation disagree on hard contact")
        self.x = np.array(state["x"], dtype=float)
        self.t, self.step_count = float(state["t"]), int(state["step_count"])
        for name in ("position", "velocity", "orientation", "angular_velocity", "density"):
            setattr(p, name, np.array(state[name], dtype=float))
        p.fixed = np.array(state["fixed"], dtype=bool)
        if "last_force" in state:
            self._last_force = np.array(state["last_force"], dtype=float)
            self._last_torque = np.array(state["last_torque"], dtype=float)
        elif self.integrator == "trapezoidal" and self.step_count > 0:
            raise ValueError("the state lacks the last step's forces, which the trapezoidal integrator needs")
        else:
            self._last_force = self._last_torque = None
        if self.contact is not None:
            self.contact.set_state({k[len("contact_"):]: v for k, v in state.items() if k.startswith("contact_")})
        self._owner_of = None
        self.flow.forget_linearisation()

    def step(self, dt: float) -> StepReport:
        """Advance flow and particles over ``dt``; ConvergenceError names the step and time."""
        where = f"step {self.step_count + 1} (t = {self.t:.6g} -> {self.t + dt:.6g})"
        flow_solves = 1
        self._contact_report = None
        work = dataclasses.replace(self.flow.linear_work)
        try:
            loose = (self.coupling == "implicit" and self.first_solve_rtol is not None
                     and not self.particles.fixed.all())
            x, reports, force, torque = self._flow_and_forces(dt, rtol=self.first_solve_rtol if loose else None)
            if self.coupling == "implicit":
                x, reports, force, torque, flow_solves = self._subiterate(dt, x, reports, force, torque,
                                                                          exact=not loose)
            new = self._integrate(force, torque, dt)
        except ConvergenceError as err:
            raise ConvergenceError(f"{where}: {err}") from None
        finally:
            self._constraint_state = None
        if not (np.all(np.isfinite(new.position)) and np.all(np.isfinite(x))):
            raise ConvergenceError(f"{where}: non-finite state")
        sharp = self._sharp(self.flow.space.V)  # of the positions the flow was solved with
        self._warn_if_fast(new.position - self.particles.position, dt)
        self.x, self.particles = x, new
        if sharp is not None:  # uncovered ghost nodes start the next step with the solid's velocity
            dofs, values = sharp.ghosts.uncovered(self.flow.space.V, self.owner(), new.position, new.velocity,
                                                  new.angular_velocity)
            self.x[dofs] = values
        self._last_force, self._last_torque = force, torque
        self.t += dt
        self.step_count += 1
        return StepReport(self.step_count, self.t, sum(r.iterations for r in reports), force, torque,
                          self.particles.position.copy(), self.particles.velocity.copy(),
                          flow_solves, self._contact_report, self.flow.linear_work.since(work))

    def _warn_if_fast(self, moved: np.ndarray, dt: float) -> None:
        """Warn once when a step moves a particle more than a finest cell: the fictitious
        boundary jumps over velocity nodes, and forces and contact lose accuracy."""
        if self._warned_fast or moved.size == 0:
            return
        cells = np.linalg.norm(moved, axis=1) / float(np.min(self.flow.mesh.finest_spacing))
        k = int(np.argmax(cells))
        if cells[k] > 1.0:
            self._warned_fast = True
            log.warning("step %d moved particle %d by %.1f cells; forces and contact lose accuracy above about "
                        "one cell per step: reduce the time step (dt = %.3g s) to %.3g s or less", self.step_count + 1,
                        k, cells[k], dt, dt / cells[k])

    def _subiterate(self, dt, x, reports, force, torque, exact: bool = True):
        """Newton iteration on the particles' new generalised velocities ``v``.

        The fixed point is ``v = Phi(v)``: integrate the particles with the forces of the flow
        constrained by ``v``. Its Jacobian ``I - G S`` is built once per step from the flow's
        response to unit rigid motions of each particle (``S = d f / d v``, the discrete added
        mass and drag, :meth:`NavierStokesProblem.lifting_response`) and the particles' gain
        ``G = d v_new / d f``; each sub-iteration then costs one flow solve, whose Newton iteration
        starts from the flow those responses predict (``x + step dX``; its stopping rule stays
        relative to the residual at the step's start). The iteration stops
        when the error left after the next Newton step on ``v`` is below ``coupling_tol`` times
        the velocity scale, estimated from the contraction ``theta = |step_k| / |step_(k-1)|`` as
        ``theta / (1 - theta) |step_k|`` (Deuflhard's estimate; ``|step_0|`` itself for the first).
        That last step is taken without a further flow solve, the flow and the forces following
        it linearly through the same responses (``x + sum_k step_k dx_k``), if the flow's error in
        doing so is below the tolerance too. The responses belong to the first flow of the step;
        how much the flow's response bent over the previous step (``drift``, the part of its
        change that they do not explain, largest over the velocity DOFs) gives that error as
        ``2 drift |step_k| / |step_(k-1)|`` (a quadratic model). Otherwise the step is solved.
        Two flow solves per time step are typical near density ratio 1 (the first from the
        explicit prediction, the second after one Newton step, which contracts about 1e-4 times),
        three at larger ratios. Broyden's rank-one
        update corrects the Jacobian from each sub-iteration's change (the forces are not exactly
        linear in ``v``). Contact is left out of the iterated map (its non-smooth response, a
        constraint switching on and off between sub-iterations, stalls the iteration): it acts
        once the coupling has converged, with the converged hydrodynamic force.
        """
        p, space = self.particles, self.flow.space
        new = self._integrate(force, torque, dt, contact=False)
        gain = velocity_gain(p, dt, self.integrator, history=self._last_force is not None)
        r = gain.shape[1]
        free = np.zeros((p.n, r), dtype=bool)  # the iterated components: movable, on the planes
        free[~p.fixed] = symmetric_motion(p.dim, self.symmetry)
        owner = self._owner(space.V)
        sharp = self._sharp(space.V)
        row_liftings = None if sharp is None else sharp.ghosts.liftings(free)
        dX = self.flow.lifting_response(x, rigid_liftings(space.V, owner, p.position, free), row_liftings)
        sens = np.zeros((p.n, r, len(dX)))  # d f_i / d v_k for every iterated component k
        dF = np.zeros((len(dX),) + force.shape)
        dT = np.zeros((len(dX),) + torque.shape)
        for k, dx in enumerate(dX):
            dF[k], dT[k] = self._forces(owner, dx, dt, about=x)
            sens[:, :, k] = np.column_stack([dF[k], dT[k][:, 2:] if p.dim == 2 else dT[k]])
        J = np.eye(len(dX)) - np.einsum("nab,nbk->nak", gain, sens)[free]
        guess = p.copy()
        v_guess = pack_velocities(p)
        # velocity scale of the convergence test: the step's velocities, at least what gravity adds
        floor = max(float(np.linalg.norm(v_guess)), float(np.linalg.norm(self.gravity)) * dt, 1e-30)
        all_reports = list(reports)
        res_old = step = size_old = x_old = drift = None
        for k in range(self.max_subiterations):
            res = (pack_velocities(new) - v_guess)[free]
            scale = max(float(np.linalg.norm(pack_velocities(new))), floor)
            if step is not None:  # Broyden's update: contact and nonlinearity bend the map
                dG = res_old - res
                if step @ step > 0.0:  # (a zero step, e.g. a particle in balance, teaches nothing)
                    J += np.outer(dG - J @ step, step) / (step @ step)
                # the flow's change over the last step that the responses do not explain
                drift = float(np.abs(x - x_old - step @ dX)[:space.n_u].max())
            step = np.linalg.solve(J, res)
            size = float(np.linalg.norm(step))
            if k == 0 or size_old == 0.0:  # no contraction measured: the step bounds both errors
                error = flow_error = size
            else:
                theta = size / size_old  # contraction of the iteration
                error = size if theta >= 1.0 else min(size, theta / (1.0 - theta) * size)
                flow_error = 2.0 * drift * size / size_old
            log.debug("coupling sub-iteration %d: relative step %.3e, error after it %.3e, of the "
                      "flow following it %.3e", k, size / scale, error / scale, flow_error / scale)
            if (k > 0 or exact) and max(error, flow_error) <= self.coupling_tol * scale:  # the last step,
                # without a solve (not from a first flow solved to a looser tolerance)
                return (x + step @ dX, all_reports, force + np.tensordot(step, dF, 1),
                        torque + np.tensordot(step, dT, 1), k + 1)
            res_old, size_old, x_old = res, size, x
            v_guess[free] += step
            unpack_velocities(guess, v_guess)
            self._constraint_state = guess
            x, reports, force, torque = self._flow_and_forces(dt, guess=x + step @ dX)
            all_reports += reports
            new = self._integrate(force, torque, dt, contact=False)
        raise ConvergenceError(f"fluid-particle coupling did not converge in {self.max_subiterations} "
                               f"sub-iterations (last step {np.linalg.norm(step) / scale:.1e})")


def _check_symmetry(mesh, particles: Particles, gravity: np.ndarray, axes: tuple):
    """Mirror planes must be domain faces through every particle centre, parallel to gravity."""
    for a in axes:
        if not 0 <= a < mesh.dim:
            raise ValueError(f"symmetry axis {a} is not an axis of a {mesh.dim}D mesh")
        tol = 1e-9 * (mesh.upper[a] - mesh.lower[a])
        on = np.isclose(particles.position[:, a], mesh.lower[a], atol=tol) | \
            np.isclose(particles.position[:, a], mesh.upper[a], atol=tol)
        if not on.all():
            raise ValueError(f"symmetry plane with normal axis {a}: particles {np.flatnonzero(~on).tolist()} "
                             "are not centred on it; put their centres on the domain face or drop the symmetry")
        if gravity[a] != 0.0:
            raise ValueError(f"symmetry plane with normal axis {a}: gravity has a component {gravity[a]} "
                             "across it; the motion would not be symmetric")


def _check_placement(mesh, particles: Particles, symmetry: tuple):
    """Particles must lie in the domain (balls wholly, other shapes with their centre; not across
    periodic axes or symmetry planes), balls must not overlap (periodic images not checked), and
    every particle must span the velocity-node spacing (half a cell) where it sits: a smaller one
    can cover no node and feel no drag. ValueError naming the particles and the remedy."""
    X, n = particles.position, particles.n
    if n == 0:
        return
    radius = particles.ball_radius
    reach = np.zeros(n) if radius is None else radius
    for a in range(mesh.dim):
        lo, hi = float(mesh.lower[a]), float(mesh.upper[a])
        tol = 1e-9 * (hi - lo)
        if mesh.periodic[a]:
            continue
        r = np.zeros(n) if a in symmetry else reach
        out = np.flatnonzero((X[:, a] - r < lo - tol) | (X[:, a] + r > hi + tol))
        if out.size:
            k = out[0]
            raise ValueError(f"particle {k} (centre {X[k].tolist()}, radius {reach[k]:.4g}) reaches outside the "
                             f"domain along axis {a} ([{lo:.4g}, {hi:.4g}]){_more(out)}; move it inside")
    if radius is not None and n > 1:
        from scipy.spatial import cKDTree
        pairs = cKDTree(X).query_pairs(2.0 * float(radius.max()), output_type="ndarray")
        if pairs.size:
            gap = np.linalg.norm(X[pairs[:, 0]] - X[pairs[:, 1]], axis=1) - radius[pairs].sum(axis=1)
            bad = np.flatnonzero(gap < -1e-9 * radius[pairs].sum(axis=1))
            if bad.size:
                i, j = pairs[bad[0]]
                raise ValueError(f"particles {i} and {j} overlap by {-gap[bad[0]]:.4g} (centres {X[i].tolist()} "
                                 f"and {X[j].tolist()}){_more(bad)}; place them at least a diameter apart")
    axes = mesh.axis_coordinates
    if axes is not None:  # the local cell size where each particle sits
        h = np.max([np.diff(ax)[np.clip(np.searchsorted(ax, X[:, a]) - 1, 0, ax.size - 2)]
                    for a, ax in enumerate(axes)], axis=0)
        small = np.flatnonzero(2.0 * particles.bounding_radius < 0.5 * h)  # the Q2 node spacing
        if small.size:
            k = small[0]
            raise ValueError(f"particle {k} (diameter {2 * particles.bounding_radius[k]:.4g}) is smaller than "
                             f"the velocity-node spacing, half the cell it sits in (cell size {h[k]:.4g})"
                             f"{_more(small)}: it can cover no velocity node and feel no drag; refine the mesh "
                             "(cells of at most two diameters; 4 or more cells per diameter for accurate "
                             "forces) or enlarge the particles")


def _more(indices: np.ndarray) -> str:
    return f" (and {indices.size - 1} more)" if indices.size > 1 else ""


COUPLINGS = ("explicit", "implicit")
FBM_BOUNDARIES = ("nodes", "sharp")
FORCES = ("volume", "test-function", "surface")
