"""The particulate-flow time loop (docs/design.md, "One time step"): particles -> mesh, flow,
forces, particles, contact.

A :class:`Simulation` is made from a mesh, the particles and typed parameter sections
(:mod:`fbmflow.params`): the fluid, the time stepping, the solvers, the coupling scheme
(:data:`fbmflow.coupling.COUPLINGS`), the fictitious boundary with its force estimator
(:data:`fbmflow.coupling.FORCE_ESTIMATORS`), hard contact and repulsion. Before anything is
assembled it checks the set-up (placement of the particles, mirror planes) and estimates the
memory of the linear solver (:func:`estimate_memory`), refusing a run that cannot fit.
"""
from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from .contact import ContactReport
from .coupling import (
    ImplicitCoupling,
    make_coupling,
    make_force_estimator,
    mirror_images,
    node_owner,
    rigid_body_constraints,
    rigid_liftings,
    sharp_boundary,
    supports_sharp_boundary,
)
from .fem import FlowSpace
from .fem.functions import mean_velocity, sample_pressure, sample_velocity
from .flow import NavierStokesProblem, NoSlip
from .flow.time_schemes import advance, pressure_lag
from .params import (
    ContactParams,
    CouplingParams,
    FictitiousBoundaryParams,
    FluidParams,
    ParamError,
    RepulsionParams,
    SolverParams,
    TimeParams,
)
from .particles import Particles, accelerations, integrate, velocity_gain
from .solvers import ConvergenceError
from .solvers.choice import cheapest_solver
from .solvers.direct import auto_backend, pardiso_available
from .solvers.reports import LinearWork

log = logging.getLogger(__name__)


@dataclass
class StepReport:
    """What one time step did.

    force : (n, dim) float64 and torque : (n, 3) float64, the hydrodynamic force and torque on
    every particle at the step's end; position, velocity : (n, dim) float64, the particles' new
    centres and velocities; newton_iterations : over all flow solves of the step.
    """

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
    flux_correction: np.ndarray | None = None  # (dim,) the mean volume flux removed at the step's end
    # (a fully periodic suspension, :attr:`Simulation.zero_flux`; None otherwise)


class Simulation:
    """Rigid particles in an incompressible flow on a structured mesh.

    Parameters
    ----------
    mesh : StructuredMesh
    particles : Particles
        The particles' shapes and initial state; the simulation advances its own copy.
    fluid : FluidParams
        Density, viscosity and gravity (along the last axis, downwards); particles feel gravity
        and buoyancy ``(M_i - rho_f V_i) g``. Where gravity points along a periodic axis (a
        periodic suspension), a mean pressure gradient carries the particles' weight
        (:func:`periodic_drive`, :attr:`drive`), so that the suspension as a whole does not
        accelerate; in a box periodic along every axis the step also removes the mixture's mean
        volume flux (:attr:`zero_flux`, a Galilean change of frame that stops the drift the force
        estimator's error would cause). Particles cross periodic sides (their centres wrap into
        the box); forces, constraints, repulsion and hard contact take the nearest image.
    boundary : dict tag -> condition, optional
        One of :mod:`fbmflow.flow.boundary`'s conditions for every non-periodic face of the mesh;
        default: no-slip walls all round.
    time : TimeParams
        The time scheme; ``dt`` and ``t_end`` are what :meth:`run` and :meth:`step` without a
        time step use.
    solver : SolverParams
        Newton and linear solver settings. ``linear = "auto"`` takes the cheaper of the direct
        solver and multigrid by measured cost (:func:`choose_linear_solver`).
    coupling : CouplingParams
        The coupling scheme (:data:`~fbmflow.coupling.COUPLINGS`: ``explicit`` or ``implicit``)
        and the particle integrator (``trapezoidal`` with ``crank-nicolson`` is second order in
        time).
    fbm : FictitiousBoundaryParams
        ``boundary``: ``nodes`` (every node inside a particle moves rigidly; first order in the
        mesh size) or ``sharp`` (the no-slip condition on the true surface,
        :mod:`fbmflow.coupling.sharp`; shapes with ``project``); ``force``: the estimator
        (:data:`~fbmflow.coupling.FORCE_ESTIMATORS`: ``volume``, ``test-function`` or
        ``surface``).
    contact : ContactParams or None
        Hard contact (off when None or not ``enabled``): the particles then advance over a fluid
        step in ``contact.substeps`` contact sub-steps with the hydrodynamic force of the step
        held constant (semi-implicit Euler with contact impulses, see
        :mod:`fbmflow.contact.contact_set`), so that contact resolution does not depend on the
        fluid time step. With the implicit coupling, contact acts once the coupling iteration has
        converged (a collision's velocity change reaches the flow in the next step).
    repulsion : RepulsionParams or None
        Short-range repulsive forces that keep particles off the walls and each other (the flow
        cannot resolve the last gap); off when None or not ``enabled``.
    symmetry : tuple of int
        Normal axes of mirror planes that cut the domain through every particle centre (the
        domain's faces there carry :class:`~fbmflow.flow.Slip`); forces and torques are those
        of the whole particles (:func:`~fbmflow.coupling.mirror_images`), the particles' motion
        stays on the planes, and the planes are no walls for contact and repulsion. Gravity must
        lie in the planes.
    frozen : bool
        Hold the particles' positions and orientations: their velocities and the flow still
        evolve, about a fixed configuration. Steps then tend to the configuration's quasi-steady
        mobility problem (the settling velocities of one frozen configuration, as in
        hindered-settling ensembles, Ladd 1990); contact and the repulsion act with the fixed
        positions.

    Raises
    ------
    ValueError
        A set-up that cannot run (placement, symmetry, a boundary or force the shapes do not
        support, contact with the trapezoidal integrator), or :class:`InsufficientMemory`; the
        message says what to change.
    """

    def __init__(self, mesh, particles: Particles, fluid: FluidParams, *, boundary: dict | None = None,
                 time: TimeParams = TimeParams(), solver: SolverParams = SolverParams(),
                 coupling: CouplingParams = CouplingParams(),
                 fbm: FictitiousBoundaryParams = FictitiousBoundaryParams(),
                 contact: ContactParams | None = None, repulsion: RepulsionParams | None = None,
                 symmetry: tuple = (), frozen: bool = False):
        for name, value, cls in (("particles", particles, Particles), ("fluid", fluid, FluidParams),
                                 ("time", time, TimeParams), ("solver", solver, SolverParams),
                                 ("coupling", coupling, CouplingParams),
                                 ("fbm", fbm, FictitiousBoundaryParams),
                                 ("contact", contact, (ContactParams, type(None))),
                                 ("repulsion", repulsion, (RepulsionParams, type(None)))):
            if not isinstance(value, cls):
                expected = cls.__name__ if isinstance(cls, type) else f"{cls[0].__name__} or None"
                raise TypeError(f"Simulation: {name} must be a {expected}, got {type(value).__name__}; "
                                f"make it with {expected.split()[0]}(...) or fbmflow.params.from_dict")
        contact = contact if contact is not None and contact.enabled else None
        if contact is not None and coupling.integrator != "semi-implicit-euler":
            raise ValueError("hard contact advances the particles by semi-implicit Euler; integrator "
                             f"{coupling.integrator!r} cannot be combined with it: set coupling.integrator = "
                             "'semi-implicit-euler' or turn contact off")
        sharp = fbm.boundary == "sharp"
        if sharp and not supports_sharp_boundary(particles.shapes):
            raise ValueError("the sharp fictitious boundary needs shapes with a closest-point projection "
                             "(Ball, Box, Cylinder); use fbm.boundary = 'nodes' for the others")
        self.estimator = make_force_estimator(fbm.force)
        self.estimator.check(particles.shapes, sharp)
        self.fluid, self.time, self.fbm = fluid, time, fbm
        self.symmetry = tuple(symmetry)
        self.frozen = bool(frozen)
        self.gravity = np.asarray(fluid.gravity_vector(mesh.dim), dtype=float)
        _check_symmetry(mesh, particles, self.gravity, self.symmetry)
        _check_placement(mesh, particles, self.symmetry)
        self.drive = periodic_drive(mesh, particles, self.gravity, fluid.density, self.symmetry)
        self.zero_flux = bool(np.any(self.drive)) and all(mesh.periodic) and not particles.fixed.any()
        walls = _walls(mesh, particles, self.symmetry)
        self.contact = None if contact is None else contact.make(mesh, fluid.viscosity, walls)
        self.contact_substeps = 1 if contact is None else contact.substeps
        self.repulsion = None if repulsion is None else repulsion.make(mesh, walls)
        if coupling.scheme == "auto":
            coupling = dataclasses.replace(
                coupling, scheme=auto_coupling(FlowSpace.estimate_dofs(mesh), particles, self.symmetry))
        self.coupling = make_coupling(coupling, solver.newton_rtol)
        self.integrator = coupling.integrator
        self.scheme = time.scheme
        self._pressure_lag = pressure_lag(time.scheme)
        linear = choose_linear_solver(solver, mesh)
        check_memory(FlowSpace.estimate_dofs(mesh), mesh.dim, linear,
                     self.coupling.stored_responses(particles, self.symmetry))
        self._contact_report = None
        self._estimator_of = None  # the force rule for the current particle state
        self._constraint_state: Particles | None = None
        self._owner_of: np.ndarray | None = None  # positions and orientations of _owner_cache
        self._owner_cache: dict = {}  # id of the DOF map (fine or multigrid level) -> owner
        self._sharp_of = None  # the sharp boundary of the current state
        self._behind = None  # (centres, force rule) where the pressure's force is taken
        self._walls_of = None  # velocity nodes held by the walls (the test-function force's)
        self.particles = particles.copy()
        self.particles.position = _wrap(mesh, self.particles.position)
        boundary = {t: NoSlip() for t in mesh.tags} if boundary is None else boundary
        drive = None if not np.any(self.drive) else (lambda x, t: np.broadcast_to(self.drive, x.shape))
        self.flow = NavierStokesProblem(mesh, fluid.viscosity, boundary, density=fluid.density,
                                        body_force=drive, linear_solver=linear,
                                        newton=solver.newton_settings(), extra_constraints=self._constraints)
        self.x = self.flow.zero_state()
        self.t = 0.0
        self.step_count = 0
        # hydrodynamic force (n, dim) and torque (n, 3) at the end of the last step (None before
        # the first: unknown, the fluid's reaction to the first acceleration is not zero)
        self._last_force: np.ndarray | None = None
        self._last_torque: np.ndarray | None = None
        self.last_increment: np.ndarray | None = None  # CoupledFlow.increment of the last step
        self._warned_fast = 0.0  # the largest move in cells per step warned about (_warn_if_fast)

    # -- the run ------------------------------------------------------------------------------
    @property
    def n_steps(self) -> int:
        """Steps of a whole run, from ``t = 0`` to ``time.t_end`` (:attr:`TimeParams.n_steps`)."""
        return self.time.n_steps

    @property
    def dt(self) -> float:
        """The time step of :meth:`run` [s]: ``time.t_end / n_steps`` (``time.dt`` shortened
        evenly so that the last step lands on ``t_end``)."""
        return self.time.t_end / self.n_steps

    def run(self, callback=None) -> list[StepReport]:
        """Step from the current step to ``time.t_end`` in steps of :attr:`dt`; ``callback(report)``
        after every step. Returns the steps' reports; ConvergenceError names a failing step."""
        reports = []
        for _ in range(self.step_count, self.n_steps):
            reports.append(self.step(self.dt))
            if callback is not None:
                callback(reports[-1])
        return reports

    # -- reading the state ----------------------------------------------------------------------
    @property
    def force(self) -> np.ndarray:
        """Hydrodynamic force on every particle at the end of the last step, (n, dim) float64
        (zeros before the first step)."""
        return np.zeros_like(self.particles.position) if self._last_force is None else self._last_force.copy()

    @property
    def torque(self) -> np.ndarray:
        """Hydrodynamic torque on every particle at the end of the last step, (n, 3) float64
        (zeros before the first step)."""
        return np.zeros((self.particles.n, 3)) if self._last_torque is None else self._last_torque.copy()

    def velocity_at(self, points) -> np.ndarray:
        """Fluid velocity at ``points (m, dim)``, (m, dim) float64 (inside a particle: its rigid
        motion, as the constraints hold it)."""
        return sample_velocity(self.flow.space, self.x[:self.flow.space.n_u], np.atleast_2d(points))

    def pressure_at(self, points) -> np.ndarray:
        """Pressure at ``points (m, dim)``, (m,) float64 (P1disc: the value of the cell each point
        lies in)."""
        return sample_pressure(self.flow.space, self.x[self.flow.space.n_u:], np.atleast_2d(points))

    def write_fields(self, out, step: int | None = None, fmt: str = "vtu") -> Path:
        """Write the flow (velocity, pressure, vorticity, owner) and the particles for ParaView
        into the directory ``out`` (:class:`~fbmflow.io.FieldWriter`), as output number ``step``
        (default: the step count); returns the directory."""
        from .io import FieldWriter

        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        step = self.step_count if step is None else step
        writer = FieldWriter(out, self.flow.space, start_step=step, fmt=fmt)
        writer.write(step, self.t, self.x, self.owner(), self.particles, self.force)
        return out

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
        if self.fbm.boundary != "sharp" or V is not self.flow.space.V:
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
        at the end of a step of length ``dt`` from ``self.x``, by the force estimator; with
        ``about`` (a flow), ``x`` is a change of that flow and the result the force's change
        (linear in ``x``). ``owner``: the node owner of the current state (:meth:`owner`).

        Estimators that allow it (``lags_pressure``) take the pressure's part where the pressure
        belongs: on the particles moved back by ``lag dt U`` (``lag``:
        :func:`~fbmflow.flow.time_schemes.pressure_lag`, one half with Crank–Nicolson; ``U`` the
        velocities at the step's start: ``dt U`` is the last step's displacement to first order;
        docs/method.md, "The pressure's time level"). Rotation is left out of the lag (none for
        balls).
        """
        n_u = self.flow.space.n_u
        u, p = x[:n_u], x[n_u:]
        u_old, linear = (self.x[:n_u], None) if about is None else (None, about[:n_u])
        est, mu, rho = self.estimator, self.flow.mu, self.flow.rho
        here = self._rule_here(owner)
        behind = self._rule_lagged(dt)
        if behind is None:
            force, torque = est.evaluate(here, u, p, mu, rho, u_old=u_old, dt=dt, about=linear)
        else:
            force, torque = est.evaluate(here, u, None, mu, rho, u_old=u_old, dt=dt, about=linear)
            force_p, torque_p = est.evaluate(behind, None, p, mu, rho, u_old=u_old, dt=dt, about=linear)
            force, torque = force + force_p, torque + torque_p
        return mirror_images(force, torque, self.symmetry) if self.symmetry else (force, torque)

    def _response_forces(self, owner: np.ndarray, dX: np.ndarray, dt: float, about: np.ndarray):
        """:meth:`_forces` of the ``k`` flow responses ``dX (k, n_dofs)`` about the flow ``about``:
        force (k, n, dim) and torque (k, n, 3), all responses and particles in one evaluation
        (``evaluate_many`` of the estimator)."""
        n_u, pt = self.flow.space.n_u, self.particles
        if len(dX) == 0:
            return np.zeros((0, pt.n, pt.dim)), np.zeros((0, pt.n, 3))
        U, P = dX[:, :n_u], dX[:, n_u:]
        est, mu, rho = self.estimator, self.flow.mu, self.flow.rho
        here = self._rule_here(owner)
        behind = self._rule_lagged(dt)
        if behind is None:
            force, torque = est.evaluate_many(here, U, P, mu, rho, dt=dt, about=about[:n_u])
        else:
            force, torque = est.evaluate_many(here, U, None, mu, rho, dt=dt, about=about[:n_u])
            force_p, torque_p = est.evaluate_many(behind, None, P, mu, rho, dt=dt, about=about[:n_u])
            force, torque = force + force_p, torque + torque_p
        return mirror_images(force, torque, self.symmetry) if self.symmetry else (force, torque)

    def _rule_lagged(self, dt: float):
        """The estimator's rule where the pressure of a step of length ``dt`` belongs; None where
        that is where the particles are (an estimator that does not lag the pressure, a time
        scheme without lag, particles at rest). See :meth:`_forces`."""
        p = self.particles
        if not self.estimator.lags_pressure or self._pressure_lag == 0.0 or not np.any(p.velocity):
            return None
        return self._rule_behind(p.position - self._pressure_lag * dt * p.velocity)

    def _rule_here(self, owner: np.ndarray):
        """The estimator's rule for the current particle state (computed once per state)."""
        if self._estimator_of is None:
            p = self.particles
            self._estimator_of = self.estimator.prepare(self.flow.space, p.position, p.shapes, p.rotations(),
                                                        owner=owner, walls=self._wall_nodes())
        return self._estimator_of

    def _rule_behind(self, centres: np.ndarray):
        """The estimator's rule for the particles moved to ``centres``, built once per centres."""
        if self._behind is None or not np.array_equal(self._behind[0], centres):
            p = self.particles
            rule = self.estimator.prepare(self.flow.space, centres, p.shapes, p.rotations(),
                                          walls=self._wall_nodes())
            self._behind = (centres.copy(), rule)
        return self._behind[1]

    def _wall_nodes(self) -> np.ndarray:
        """Velocity nodes whose every component the boundary conditions hold, (k,) int64."""
        if self._walls_of is None:
            space = self.flow.space
            fixed = self.flow.fine.boundary_constraints.dofs
            self._walls_of = np.flatnonzero(np.bincount(fixed % space.n_v, minlength=space.n_v) == space.dim)
        return self._walls_of

    # -- what the coupling schemes use (fbmflow.coupling.schemes) ----------------------------------
    def flow_and_forces(self, dt: float, velocities: Particles | None = None, guess: np.ndarray | None = None,
                        rtol: float | None = None, linear_rtol: float | None = None):
        """Solve the flow over the step ``dt`` from the current state, the particles at their
        current positions moving with the velocities of ``velocities`` (default: their own), from
        the initial guess ``guess`` (n_dofs,) with Newton's residual reduction ``rtol`` (default:
        the solver settings') and linear steps no tighter than ``linear_rtol`` (default: the
        solver settings'). Returns ``(x (n_dofs,), Newton reports, force (n, dim), torque
        (n, 3))``; the state itself is not changed."""
        self._constraint_state = velocities
        try:
            x, reports = advance(self.flow, self.x, self.t, dt, self.scheme, guess, rtol, linear_rtol)
        finally:
            self._constraint_state = None
        force, torque = self._forces(self._owner(self.flow.space.V), x, dt)
        return x, reports, force, torque

    def integrate(self, force: np.ndarray, torque: np.ndarray, dt: float, contact: bool = True) -> Particles:
        """New particle state under the hydrodynamic ``force (n, dim)`` and ``torque (n, 3)``, the
        push of the periodic drive's pressure gradient on their volume (:attr:`drive`), the
        repulsive forces (at the positions of the start of the step) and, with hard contact
        (unless ``contact`` is False), the contact impulses; the state itself is not changed."""
        previous = None  # the trapezoidal rule's forces at the start of the step (None: no history)
        if self._last_force is not None:
            previous = self._last_force, self._last_torque
        extra = np.zeros_like(force)
        if np.any(self.drive):  # the mean pressure gradient's push on the particles' volume
            extra += np.where(self.particles.fixed[:, None], 0.0, self.particles.volume[:, None] * self.drive)
        if self.repulsion is not None:
            extra += self.repulsion.forces(self.particles, self.gravity, self.flow.rho)
        if np.any(extra):
            force = force + extra
            if previous is not None:
                previous = (previous[0] + extra, previous[1])
        if self.contact is None or not contact:
            return integrate(self.particles, force, torque, self.gravity, self.flow.rho, dt, self.integrator,
                             previous)
        lin, ang = accelerations(self.particles, force, torque, self.gravity, self.flow.rho)
        new, self._contact_report = self.contact.advance(self.particles, lin, ang, dt, self.contact_substeps)
        return new

    def repulsion_stiffness(self) -> sp.csr_matrix | None:
        """The repulsive forces' change with the positions at the start of the step,
        ``(n dim, n dim)`` (:meth:`~fbmflow.contact.Repulsion.stiffness`); None when the repulsion
        is off or the particles are frozen (their positions do not change)."""
        if self.repulsion is None or self.frozen:
            return None
        return self.repulsion.stiffness(self.particles, self.gravity, self.flow.rho)

    def velocity_gain(self, dt: float) -> np.ndarray:
        """``d v_new / d f`` of :meth:`integrate` over ``dt`` (:func:`~fbmflow.particles.velocity_gain`),
        (n, r, r) float64."""
        return velocity_gain(self.particles, dt, self.integrator, history=self._last_force is not None)

    def rigid_responses(self, x: np.ndarray, free: np.ndarray, dt: float, motions: np.ndarray | None = None,
                        rtol: float | None = None):
        """The flow's linear response to a unit rigid motion of every free component and its
        force: ``free (n, r)`` bool selects the ``k`` generalised velocity components; returns
        ``dX (k, n_dofs)``, ``dF (k, n, dim)`` and ``dT (k, n, 3)`` about the flow ``x`` solved
        last (:meth:`~fbmflow.flow.NavierStokesProblem.lifting_response`). With ``motions
        (m, k)``, the responses to those ``m`` combinations of the unit motions instead (one
        linear solve each, to ``rtol`` where the linear solver takes one): ``dX (m, n_dofs)``,
        ``dF (m, n, dim)``, ``dT (m, n, 3)``."""
        p, space = self.particles, self.flow.space
        owner = self._owner(space.V)
        sharp = self._sharp(space.V)
        W = rigid_liftings(space.V, owner, p.position, free)
        row_liftings = None if sharp is None else sharp.ghosts.liftings(free)
        if motions is not None:
            W = sp.csc_matrix(W @ motions.T)
            row_liftings = None if row_liftings is None else sp.csc_matrix(row_liftings @ motions.T)
        dX = self.flow.lifting_response(x, W, row_liftings, rtol)
        dF, dT = self._response_forces(owner, dX, dt, about=x)
        return dX, dF, dT

    def own_stiffness(self, x: np.ndarray, free: np.ndarray, dt: float, added_mass: float) -> np.ndarray:
        """Each particle's generalised force on its own generalised velocity, estimated locally
        about the flow ``x``: ``S (n, r, r)``, ``S[i, a, b] ~ d f_ia / d v_ib`` for the True entries
        of ``free (n, r)`` (zero elsewhere).

        Two parts, neither needing a flow solve: the force of the particle's own unit rigid
        motions on its nodes with the rest of the flow held at zero (the viscous stress across
        its cut cells: :meth:`~fbmflow.coupling.forces.ForceFunctional.own_response`, one sparse
        product for all particles), and ``added_mass`` times the potential-flow added mass of a
        ball, ``-C rho_f V_i / dt`` on the translations with ``C = 1`` for a disk and ``1/2``
        for a sphere (the ball's value for every shape), which the held flow (no pressure) leaves
        out (how close the sum comes to the exact blocks: docs/validation.md, "Many particles")."""
        p, space = self.particles, self.flow.space
        owner = self._owner(space.V)
        W = rigid_liftings(space.V, owner, p.position, free)
        S = self.estimator.own_response(self._rule_here(owner), W, free, self.flow.mu, self.flow.rho, dt=dt,
                                        about=x[:space.n_u])
        if self.symmetry:  # whole particles on mirror planes: the images' forces, column by column
            d = p.dim
            rows = S[:, d:, :].transpose(2, 0, 1)  # (r, n, 1) in 2D (z), (r, n, 3) in 3D
            torque = np.zeros(rows.shape[:2] + (3,))
            torque[..., 3 - rows.shape[-1]:] = rows
            force, torque = mirror_images(S[:, :d, :].transpose(2, 0, 1), torque, self.symmetry)
            S = np.concatenate([force, torque[..., 2:] if d == 2 else torque], axis=2).transpose(1, 2, 0)
        idx = np.arange(p.dim)
        potential = 1.0 if p.dim == 2 else 0.5
        S[:, idx, idx] -= added_mass * potential * self.flow.rho * p.volume[:, None] / dt
        return np.where(free[:, :, None] & free[:, None, :], S, 0.0)

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
        if self.last_increment is not None:  # the stabilised coupling's last step
            out["coupling_increment"] = self.last_increment.copy()
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
        increment = state.get("coupling_increment")
        self.last_increment = None if increment is None else np.array(increment, dtype=float)
        if self.contact is not None:
            self.contact.set_state({k[len("contact_"):]: v for k, v in state.items()
                                    if k.startswith("contact_")})
        self._owner_of = None
        self.flow.forget_linearisation()

    def step(self, dt: float | None = None) -> StepReport:
        """Advance flow and particles over ``dt`` [s] (default :attr:`dt`) by the coupling
        scheme, then contact; ConvergenceError names the step and time."""
        dt = self.dt if dt is None else float(dt)
        if not dt > 0.0:
            raise ValueError(f"the time step must be positive, got {dt}")
        where = f"step {self.step_count + 1} (t = {self.t:.6g} -> {self.t + dt:.6g})"
        self._contact_report = None
        work = dataclasses.replace(self.flow.linear_work)
        try:
            solved = self.coupling.advance(self, dt)
            new = self.integrate(solved.force, solved.torque, dt)
        except ConvergenceError as err:
            raise ConvergenceError(f"{where}: {err}") from None
        x, reports, force, torque = solved.x, solved.reports, solved.force, solved.torque
        if not (np.all(np.isfinite(new.position)) and np.all(np.isfinite(x))):
            raise ConvergenceError(f"{where}: non-finite state")
        if self.frozen:
            new.position, new.orientation = self.particles.position.copy(), self.particles.orientation.copy()
        sharp = self._sharp(self.flow.space.V)  # of the positions the flow was solved with
        self._warn_if_fast(new.position - self.particles.position, dt)
        new.position = _wrap(self.flow.mesh, new.position)
        self.x, self.particles = x, new
        if sharp is not None:  # uncovered ghost nodes start the next step with the solid's velocity
            dofs, values = sharp.ghosts.uncovered(self.flow.space.V, self.owner(), new.position, new.velocity,
                                                  new.angular_velocity)
            self.x[dofs] = values
        self.last_increment = solved.increment
        shift = self._remove_mean_flux() if self.zero_flux else None
        self._last_force, self._last_torque = force, torque
        self.t += dt
        self.step_count += 1
        return StepReport(self.step_count, self.t, sum(r.iterations for r in reports), force, torque,
                          self.particles.position.copy(), self.particles.velocity.copy(),
                          solved.flow_solves, self._contact_report, self.flow.linear_work.since(work), shift)

    def _remove_mean_flux(self) -> np.ndarray:
        """Subtract the mixture's mean velocity (:func:`~fbmflow.fem.functions.mean_velocity`, the
        volume flux per unit area) from the flow and the particles: a Galilean change of frame,
        exact in a fully periodic box. Returns the velocity removed, (dim,) float64.

        The drive carries the particles' weight exactly, so the flux would stay zero, but the
        particles move under the estimated hydrodynamic force, whose error the fluid does not
        feel: momentum leaks at that rate, and without this the mixture would drift without
        bound (docs/validation.md, "Periodic suspensions")."""
        space = self.flow.space
        shift = mean_velocity(space, self.x[:space.n_u])
        self.x[:space.n_u] -= np.repeat(shift, space.n_v)
        self.particles.velocity = self.particles.velocity - shift
        return shift

    def _warn_if_fast(self, moved: np.ndarray, dt: float) -> None:
        """Warn when a step moves a particle more than a finest cell (the fictitious boundary
        jumps over velocity nodes, and forces and contact lose accuracy), and again each time
        the largest such move doubles."""
        if moved.size == 0:
            return
        cells = np.linalg.norm(moved, axis=1) / float(np.min(self.flow.mesh.finest_spacing))
        k = int(np.argmax(cells))
        if cells[k] > max(1.0, 2.0 * self._warned_fast):
            self._warned_fast = float(cells[k])
            log.warning("step %d moved particle %d by %.1f cells; forces and contact lose accuracy above "
                        "about one cell per step: reduce the time step (dt = %.3g s) to %.3g s or less",
                        self.step_count + 1, k, cells[k], dt, dt / cells[k])


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
                             "are not centred on it; put their centres on the domain face or drop the "
                             "symmetry")
        if gravity[a] != 0.0:
            raise ValueError(f"symmetry plane with normal axis {a}: gravity has a component {gravity[a]} "
                             "across it; the motion would not be symmetric")


def periodic_drive(mesh, particles: Particles, gravity: np.ndarray, fluid_density: float,
                   symmetry: tuple = ()) -> np.ndarray:
    """Force per unit volume on the fluid [N/m^3], (dim,) float64, that carries the free particles'
    weight in the fluid along the periodic axes of ``mesh``: the mean pressure gradient of a
    periodic suspension, zero where gravity has no periodic component.

        f = - sum_i (M_i - rho_f V_i) g_per / |Omega|,

    ``g_per`` the components of ``gravity`` along periodic axes and ``|Omega|`` the box's volume
    (the particles counted by their share of the box, ``2^-k`` with ``k`` mirror planes through
    their centres). The fluid feels ``f`` and every free particle ``f V_i``, so the net force on
    fluid and particles together vanishes: without it a periodic suspension would accelerate
    without end. Its mean volume flux stays what it started with (zero from rest).
    """
    g = np.where(mesh.periodic, np.asarray(gravity, dtype=float), 0.0)
    if not np.any(g) or particles.n == 0:
        return np.zeros(mesh.dim)
    free = ~particles.fixed
    excess = float(np.sum(particles.mass[free] - fluid_density * particles.volume[free]))
    box = float(np.prod(np.array(mesh.upper) - np.array(mesh.lower)))
    return -excess * 0.5 ** len(symmetry) / box * g


def _wrap(mesh, X: np.ndarray) -> np.ndarray:
    """Centres ``X (n, dim)`` moved into ``[lower, upper)`` along the periodic axes (a new array)."""
    L = mesh.periods
    if not np.any(L):
        return X
    lower = np.array(mesh.lower, dtype=float)
    return np.where(L > 0, lower + np.mod(X - lower, np.where(L > 0, L, 1.0)), X)


def _check_placement(mesh, particles: Particles, symmetry: tuple):
    """Particles must lie in the domain (balls wholly, other shapes with their centre; along
    periodic axes anywhere; not across symmetry planes), balls must not overlap (across periodic
    sides with the nearest image), and
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
            raise ValueError(f"particle {k} (centre {X[k].tolist()}, radius {reach[k]:.4g}) reaches outside "
                             f"the domain along axis {a} ([{lo:.4g}, {hi:.4g}]){_more(out)}; move it inside")
    if radius is not None and n > 1:
        from scipy.spatial import cKDTree
        L, lower = mesh.periods, np.array(mesh.lower, dtype=float)
        reach_pairs = 2.0 * float(radius.max())
        extent = np.array(mesh.upper, dtype=float) - lower
        # periodic axes wrap (cKDTree's boxsize); the others get a box too wide to wrap within reach
        box = np.where(L > 0, L, extent + 2.0 * reach_pairs + 1.0)
        Xb = _wrap(mesh, X) - lower
        pairs = cKDTree(np.clip(Xb, 0.0, np.nextafter(box, 0.0)), boxsize=box).query_pairs(
            reach_pairs, output_type="ndarray")
        if pairs.size:
            diff = X[pairs[:, 0]] - X[pairs[:, 1]]
            diff -= L * np.round(diff / np.where(L > 0, L, 1.0))
            gap = np.linalg.norm(diff, axis=1) - radius[pairs].sum(axis=1)
            bad = np.flatnonzero(gap < -1e-9 * radius[pairs].sum(axis=1))
            if bad.size:
                i, j = pairs[bad[0]]
                raise ValueError(f"particles {i} and {j} overlap by {-gap[bad[0]]:.4g} (centres "
                                 f"{X[i].tolist()} and {X[j].tolist()}){_more(bad)}; place them at least a "
                                 "diameter apart")
    axes = mesh.axis_coordinates
    if axes is not None:  # the local cell size where each particle sits
        h = np.max([np.diff(ax)[np.clip(np.searchsorted(ax, X[:, a]) - 1, 0, ax.size - 2)]
                    for a, ax in enumerate(axes)], axis=0)
        small = np.flatnonzero(2.0 * particles.bounding_radius < 0.5 * h)  # the Q2 node spacing
        if small.size:
            k = small[0]
            raise ValueError(f"particle {k} (diameter {2 * particles.bounding_radius[k]:.4g}) is smaller "
                             "than the velocity-node spacing, half the cell it sits in (cell size "
                             f"{h[k]:.4g}){_more(small)}: it can cover no velocity node and feel no drag; "
                             "refine the mesh (cells of at most two diameters; 4 or more cells per diameter "
                             "for accurate forces) or enlarge the particles")


def _more(indices: np.ndarray) -> str:
    return f" (and {indices.size - 1} more)" if indices.size > 1 else ""


def _walls(mesh, particles: Particles, symmetry: tuple):
    """The domain faces ``(axis, side)`` that are walls for contact and repulsion: all of them
    (None) without mirror planes and periodic axes, else all but the periodic faces and those the
    particles are centred on."""
    if not symmetry and not any(mesh.periodic):
        return None
    walls = []
    for a in range(mesh.dim):
        if mesh.periodic[a]:
            continue
        for side, face in enumerate((mesh.lower[a], mesh.upper[a])):
            on_plane = a in symmetry and np.allclose(particles.position[:, a], face,
                                                     atol=1e-9 * (mesh.upper[a] - mesh.lower[a]))
            if not on_plane:
                walls.append((a, side))
    return walls


def choose_linear_solver(solver: SolverParams, mesh):
    """The linear solver of a run: ``solver.linear_solver()``, with ``"auto"`` resolved to the
    cheaper of the direct solver and multigrid by measured cost, among those whose memory
    estimate fits the machine (:func:`fbmflow.solvers.choice.cheapest_solver`,
    :func:`estimate_memory`): ``"direct"`` or the configured multigrid solver."""
    if solver.linear != "auto":
        return solver.linear_solver()
    n, have = FlowSpace.estimate_dofs(mesh), available_memory()

    def fits(name: str) -> bool:
        return have is None or estimate_memory(n, mesh.dim, name)[0] <= have

    if cheapest_solver(mesh.dim, n, solver.linear_rtol, pardiso_available(), fits) == "direct":
        return "direct"
    return dataclasses.replace(solver, linear="multigrid").linear_solver()


class InsufficientMemory(ParamError):
    """A run whose linear solver would need more memory than the machine has available."""


#: peak resident memory of a run by (dimension, solver): ``(c, n_ref, e)``, the memory per unknown
#: ``c`` [bytes] at ``n_ref`` unknowns, growing as ``(n / n_ref)^e`` (a factorisation fills more
#: than linearly: nested dissection ``O(n^(4/3))`` in 3D, ``O(n log n)`` in 2D; multigrid is
#: linear). Fitted, with a margin, to peak resident sets of whole runs measured on x86-64 Linux:
#: ten-cate 64 547 / 278 739 unknowns PARDISO 2.0 / 10.3 GB (benchmarks/results/tencate_solvers.md),
#: multigrid 278 739 / 2 012 403 unknowns 1.44 / 8.9 GB (three and two steps), channel-3d level 4
#: (486 979 unknowns, steady, Newton hierarchy) 3.4 GB (benchmarks/results/solver_table.md);
#: sedimentation-3d 32 707 unknowns PARDISO 1.22 GB, SuperLU 0.91 GB; glowinski-free-fall
#: 17 106 / 52 818 / 164 946 unknowns PARDISO or SuperLU 0.33 / 0.55 / 1.30 GB, multigrid 0.81 GB
#: at 164 946.
MEMORY_MODEL = {(2, "pardiso"): (6_500, 165_000, 0.1), (2, "superlu"): (6_500, 165_000, 0.25),
                (2, "multigrid"): (3_500, 165_000, 0.0), (3, "pardiso"): (40_000, 280_000, 0.15),
                (3, "superlu"): (30_000, 33_000, 0.5), (3, "multigrid"): (6_500, 280_000, 0.0)}
#: what the interpreter, NumPy, SciPy and the compiled kernels take before any mesh [bytes]
MEMORY_BASE = 400e6
#: peak memory per unknown of each response the implicit coupling keeps [bytes]: about ten float64
#: fields (liftings, responses and their forces' work arrays); measured, sedimentation-2d level 2
#: (141 762 unknowns), 100 disks: 5.17 GB implicit against 1.70 GB explicit
#: (benchmarks/results/particle_scaling.md), 3.47 GB over 300 responses
RESPONSE_BYTES = 80


#: the implicit coupling's responses that ``coupling.scheme = "auto"`` allows [bytes]
AUTO_RESPONSE_BYTES = 4e9


def auto_coupling(n_unknowns: int, particles: Particles, symmetry=()) -> str:
    """The scheme ``coupling.scheme = "auto"`` takes: ``"implicit"`` while the flow responses it
    keeps (:data:`RESPONSE_BYTES` per unknown each, one per free rigid-body component) fit
    :data:`AUTO_RESPONSE_BYTES`, else ``"stabilised"`` (one flow solve per step, none kept; less
    accurate in transients, and at a hard impact it needs half a cell per step: docs/validation.md,
    "Many particles"). The same for every machine."""
    responses = ImplicitCoupling.stored_responses(particles, symmetry)
    stored = RESPONSE_BYTES * n_unknowns * responses
    if stored <= AUTO_RESPONSE_BYTES:
        return "implicit"
    log.info("coupling.scheme = auto: stabilised, since the implicit scheme's %d responses would need "
             "%.1f GB for %d unknowns", responses, stored / 1e9, n_unknowns)
    return "stabilised"


def estimate_memory(n_unknowns: int, dim: int, linear_solver) -> tuple[float, str]:
    """Rough, conservative peak memory of a run: ``(bytes, the solver in words)``.

    ``linear_solver``: a solver object (``needs_hierarchy`` marks multigrid, ``backend`` the direct
    solver's ``"pardiso"``, ``"superlu"`` or ``"auto"``) or the name ``"direct"`` or
    ``"multigrid"``. The estimate is ``MEMORY_BASE + n c (n / n_ref)^e`` with ``(c, n_ref, e)``
    from :data:`MEMORY_MODEL`; it is meant to tell a run that fits from one that cannot, not to
    predict the figure to better than a few tens of per cent.
    """
    name = linear_solver if isinstance(linear_solver, str) else getattr(linear_solver, "name", "direct")
    if name == "multigrid" or getattr(linear_solver, "needs_hierarchy", False):
        kind, words = "multigrid", "multigrid"
    else:
        kind = getattr(linear_solver, "backend", "auto")
        kind = auto_backend(dim, n_unknowns) if kind == "auto" else kind
        words = f"the direct solver ({'PARDISO' if kind == 'pardiso' else 'SuperLU'})"
    c, n_ref, growth = MEMORY_MODEL[(dim, kind)]
    return MEMORY_BASE + n_unknowns * c * (n_unknowns / n_ref) ** growth, words


def available_memory(meminfo="/proc/meminfo") -> float | None:
    """Memory available to a new process [bytes]: ``MemAvailable`` of ``meminfo`` (Linux); None
    where it cannot be read (no check is made then)."""
    try:
        for line in Path(meminfo).read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return float(line.split()[1]) * 1024.0
    except (OSError, ValueError, IndexError):
        return None
    return None


def check_memory(n_unknowns: int, dim: int, linear_solver, responses: int = 0) -> float:
    """Refuse (:class:`InsufficientMemory`) a run whose :func:`estimate_memory` plus the
    ``responses`` flow fields an implicit coupling keeps (:data:`RESPONSE_BYTES` per unknown
    each) exceeds the available memory, warn when it exceeds half of it; returns the estimate
    [bytes]. Called before the first solve, so that a run too large for the machine stops with
    the figure and a remedy instead of a MemoryError, or the kernel's out-of-memory killer, in the
    factorisation or the responses."""
    need, words = estimate_memory(n_unknowns, dim, linear_solver)
    have = available_memory()
    if have is None:
        return need
    figure = f"{words} needs about {need / 1e9:.1f} GB for {n_unknowns} unknowns ({dim}D)"
    stored = RESPONSE_BYTES * n_unknowns * responses
    if stored and need <= have < need + stored:
        raise InsufficientMemory(
            f"the implicit coupling's responses to {responses} rigid-body velocity components need about "
            f"{stored / 1e9:.1f} GB for {n_unknowns} unknowns, and {words} {need / 1e9:.1f} GB: more "
            f"than the {have / 1e9:.1f} GB available; use fewer particles, a coarser mesh (a lower --level) "
            "or coupling.scheme = stabilised (one flow solve per step, no responses kept) or newton-krylov "
            "(the same, with a few linear responses per step; for dense suspensions)")
    need += stored
    if need > have:
        remedy = "a coarser mesh (a lower --level)"
        if words != "multigrid":
            mg, _ = estimate_memory(n_unknowns, dim, "multigrid")
            remedy += f" or solver.linear = multigrid (about {mg / 1e9:.1f} GB)"
        raise InsufficientMemory(f"{figure}, more than the {have / 1e9:.1f} GB available; use {remedy}")
    if need > 0.5 * have:
        log.warning("%s, more than half of the %.1f GB available", figure, have / 1e9)
    return need
