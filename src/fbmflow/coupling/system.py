"""The coupled system: the flow, the particles, the force estimator, contact and repulsion, and
the state they advance together (the flow ``x``, the time, the particles, the last step's forces).

A :class:`CoupledSystem` is what the coupling schemes (:mod:`fbmflow.coupling.schemes`) drive,
through the members of :class:`~fbmflow.coupling.schemes.CoupledProblem`: a flow solve with the
particles as fictitious boundaries and its forces (:meth:`CoupledSystem.flow_and_forces`), the
particles' integration under given forces (:meth:`~CoupledSystem.integrate`), and the linear
responses of the flow and its forces to the particles' rigid motions
(:meth:`~CoupledSystem.rigid_responses`, :meth:`~CoupledSystem.own_stiffness`). A scheme's
:class:`~fbmflow.coupling.schemes.CoupledFlow` is then committed (:meth:`~CoupledSystem.commit`):
the particles move, the state advances. The :class:`~fbmflow.simulation.Simulation` above owns a
system and a scheme and asks nothing of the system that a scheme could not.

What one particle configuration is on the mesh (the node owner on every multigrid level, the
sharp boundary, the force estimator's rule) is a :class:`ParticleGeometry`, made once per
configuration: the positions do not change during a step's flow solves and coupling iterations.
"""
from __future__ import annotations

import dataclasses
import logging

import numpy as np
import scipy.sparse as sp

from ..contact import ContactReport, Planes, deepest_overlap
from ..contact.settings import SKIN_FRACTION, ContactParams, RepulsionParams
from ..fem.constraints import DirichletConstraints
from ..fem.functions import mean_velocity, node_integrals
from ..flow import NavierStokesProblem
from ..flow.blocks import BlockNavierStokesProblem
from ..flow.time_schemes import advance, pressure_lag
from ..parallel import SerialComm, max_over, sum_replicated
from ..params import FluidParams
from ..particles import Particles, accelerations, integrate, velocity_gain
from ..solvers import ConvergenceError, NewtonSettings
from ..solvers.base import LinearSolver
from ..solvers.multigrid import MultigridSolver
from ..solvers.reports import LinearWork
from .estimators import auto_force, make_force_estimator
from .forces import mirror_images
from .indicator import node_owner, rigid_body_constraints, rigid_liftings
from .placement import check_placement, check_symmetry, periodic_drive, too_small, walls, wrap
from .schemes import CoupledFlow
from .settings import FictitiousBoundaryParams
from .sharp import reach_layers, sharp_boundary, supports_sharp_boundary

log = logging.getLogger(__name__)

#: how deep a particle may reach into a wall or another particle, as a fraction of its bounding
#: radius (of the smaller one for a pair), before the run stops: a particle that deep has passed
#: what kept it out (or nothing did), and the flow around it no longer means anything
MAX_OVERLAP = 0.5
#: cells this many times the finest, where a particle sits, mean it left a graded mesh's fine zone
COARSE_FACTOR = 1.5


@dataclasses.dataclass
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
    # (a fully periodic suspension; None otherwise)



class ParticleGeometry:
    """One particle configuration (centres and rotations) on the flow's mesh, each part made on
    first use: the node owner of every DOF map asked for (the fine level's and the multigrid
    levels'), the sharp boundary on the fine level (with ``sharp``), and the force estimator's
    rule.

    Parameters
    ----------
    space : FlowSpace, the fine level's
    particles : Particles, whose positions and orientations this geometry is (copied)
    sharp : bool, the sharp fictitious boundary is on
    estimator : a force estimator (:data:`~fbmflow.coupling.estimators.FORCE_ESTIMATORS`)
    wall_nodes : (k,) int64, the velocity nodes the walls hold (for the estimator)
    cells : (n_cells,) bool or None, the cells whose part of the forces the rule takes (one
        process's owned cells; None: all)
    whole : StructuredMesh or None, the whole mesh where ``space``'s is one process's slab
    comm : the processes' communicator (with ``whole``)
    """

    def __init__(self, space, particles: Particles, sharp: bool, estimator, wall_nodes: np.ndarray,
                 cells: np.ndarray | None = None, whole=None, comm=None):
        self.space, self.sharp_on, self.estimator, self.wall_nodes = space, sharp, estimator, wall_nodes
        self.cells, self.whole, self.comm = cells, whole, comm
        #: the whole mesh's finest cell length on a slab (None: the space's own)
        self.spacing = None if whole is None else float(whole.finest_spacing.min())
        self.position = particles.position.copy()
        self.orientation = np.array(particles.orientation, copy=True)
        self.shapes = particles.shapes
        self.rotations = particles.rotations()
        self._owner: dict = {}  # id of a DOF map -> owner
        self._sharp = None
        self._rule = None

    def describes(self, particles: Particles) -> bool:
        """Whether ``particles`` are at this configuration (positions and orientations equal)."""
        return (np.array_equal(self.position, particles.position)
                and np.array_equal(self.orientation, particles.orientation))

    def owner(self, V) -> np.ndarray:
        """Particle owning every node of the DOF map ``V`` (-1: fluid), (n_v,) int64."""
        if id(V) not in self._owner:
            self._owner[id(V)] = node_owner(V, self.position, self.shapes, self.rotations)
        return self._owner[id(V)]

    def sharp(self, V):
        """The sharp boundary on the fine DOF map ``V`` (None for the nodal boundary and on the
        coarser multigrid levels). On one process's slab, ConvergenceError on every process
        where a row of an owned cell's node would reach beyond the slab's halo (every process
        builds it at the same point of a step)."""
        if not self.sharp_on or V is not self.space.V:
            return None
        if self._sharp is None:
            self._sharp = sharp_boundary(self.space, self.owner(V), self.position, self.shapes,
                                         self.rotations, self.whole)
            if self.whole is not None:
                beyond = np.isin(self._sharp.ghosts.beyond, V.cell_dofs[self.cells]).sum()
                if max_over(float(beyond), self.comm) > 0:
                    raise ConvergenceError(
                        "the sharp boundary's rows of a particle's nodes reach beyond the halo that the "
                        "processes' slabs share (cut cells coarser than the mesh's finest, next to the "
                        "boundary between two slabs)",
                        "run it on one process, on a uniform mesh, or with fbm.boundary = 'nodes'")
        return self._sharp

    def rule(self):
        """The force estimator's rule for this configuration."""
        if self._rule is None:
            self._rule = self.estimator.prepare(self.space, self.position, self.shapes, self.rotations,
                                                owner=self.owner(self.space.V), walls=self.wall_nodes,
                                                cells=self.cells, spacing=self.spacing)
        return self._rule

    def constraints(self, V, velocity: np.ndarray, angular_velocity: np.ndarray) -> DirichletConstraints:
        """Fictitious-boundary constraints on ``V`` for the particles moving with ``velocity
        (n, dim)`` and ``angular_velocity``: rigid motion on their nodes, with the sharp
        boundary's changes on the fine level."""
        rigid = rigid_body_constraints(V, self.owner(V), self.position, velocity, angular_velocity)
        sharp = self.sharp(V)
        return rigid if sharp is None else sharp.constraints(rigid, velocity, angular_velocity)


def _check_distributed(linear_solver: LinearSolver) -> None:
    """ValueError naming the setting to change where a coupled system cannot run on several
    processes."""
    if not isinstance(linear_solver, MultigridSolver):
        raise ValueError("several processes solve with multigrid: set solver.linear = 'multigrid'")


class CoupledSystem:
    """Rigid particles in an incompressible flow on a structured mesh, and their state.

    Parameters
    ----------
    mesh : StructuredMesh
    particles : Particles, the initial state (copied; centres wrapped into a periodic box)
    fluid : FluidParams
    boundary : dict tag -> condition, the flow's boundary conditions
    time_scheme : str, the flow's time scheme (:data:`~fbmflow.flow.time_schemes.TIME_SCHEMES`)
    integrator : str, the particles' (``semi-implicit-euler`` or ``trapezoidal``)
    fbm : FictitiousBoundaryParams, the boundary and the force estimator
    contact : ContactParams or None, hard contact (None: off)
    repulsion : RepulsionParams or None, short-range repulsion (None: off)
    symmetry : tuple of int, normal axes of mirror planes through every particle centre
    frozen : bool, hold the particles' positions and orientations
    linear_solver : LinearSolver, newton : NewtonSettings, the flow's solvers
    varying_steps : bool, the steps change from one to the next (adaptive steps): the
        trapezoidal integrator then takes each step's own pressure force (:attr:`midpoint_pressure`)
    comm : the processes' communicator (None: one process). On several, each holds a block of the
        mesh (:class:`~fbmflow.flow.blocks.BlockNavierStokesProblem`; the flow ``x`` is its local part),
        sums the forces of its owned cells, and the sums are added up in the same order on every
        process (:func:`~fbmflow.parallel.comm.sum_replicated`): the particles, their contact and
        the coupling's decisions are the same bits everywhere. The sharp boundary's blocks hold
        :func:`~fbmflow.coupling.sharp.reach_layers` halo layers. The multigrid solver and the
        volume or surface force only.
    process_grid : tuple of int or None, the processes along every axis of the mesh on several
        (None: chosen, :class:`~fbmflow.flow.blocks.BlockFlowLevels`)

    See :class:`~fbmflow.simulation.Simulation` for what each does; ValueError for a set-up that
    cannot run (placement, mirror planes, a boundary or force the shapes do not support).
    """

    def __init__(self, mesh, particles: Particles, fluid: FluidParams, *, boundary: dict, time_scheme: str,
                 integrator: str, fbm: FictitiousBoundaryParams, contact: ContactParams | None,
                 repulsion: RepulsionParams | None, symmetry: tuple, frozen: bool,
                 linear_solver: LinearSolver, newton: NewtonSettings, varying_steps: bool = False, comm=None,
                 process_grid=None):
        sharp = fbm.boundary == "sharp"
        self.comm = comm if comm is not None else SerialComm()
        self.mesh = mesh  # the whole mesh (the flow's is a slab of it on several processes)
        if sharp and not supports_sharp_boundary(particles.shapes):
            raise ValueError("the sharp fictitious boundary needs shapes with a closest-point projection "
                             "(Ball, Box, Cylinder); use fbm.boundary = 'nodes' for the others")
        self.estimator = make_force_estimator(auto_force(particles.shapes, sharp, mesh.dim)
                                              if fbm.force == "auto" else fbm.force)
        self.estimator.check(particles.shapes, sharp)
        if self.comm.size > 1:
            _check_distributed(linear_solver)
        self.sharp = sharp
        self.symmetry, self.frozen, self.integrator = tuple(symmetry), bool(frozen), integrator
        self.gravity = np.asarray(fluid.gravity_vector(mesh.dim), dtype=float)
        check_symmetry(mesh, particles, self.gravity, self.symmetry)
        check_placement(mesh, particles, self.symmetry)
        #: (dim,) the mean pressure gradient carrying a periodic suspension's weight [N/m^3]
        self.drive = periodic_drive(mesh, particles, self.gravity, fluid.density, self.symmetry)
        #: remove the mixture's mean volume flux after every step (a box periodic along every axis)
        self.zero_flux = bool(np.any(self.drive)) and all(mesh.periodic) and not particles.fixed.any()
        faces = walls(mesh, particles, self.symmetry)
        self._planes = Planes.box(mesh.lower, mesh.upper, faces)  # what the sanity check sees as walls
        self.contact = None if contact is None else contact.make(mesh, fluid.viscosity, faces)
        self.contact_substeps = 1 if contact is None else contact.substeps
        self.repulsion = None if repulsion is None else repulsion.make(mesh, faces)
        self.time_scheme = time_scheme
        self._pressure_lag = pressure_lag(time_scheme)
        #: the trapezoidal integrator pairs the step's own pressure force with the mean of the
        #: viscous forces at the step's start and end (the midpoint rule for the pressure, a
        #: multiplier of the whole step under Crank–Nicolson) instead of the mean of two steps'
        #: pressure forces, which stands for the step only when the two steps are equal (steps
        #: alternating 0.5 / 1.5 ms moved Glowinski's settling velocity by up to 4 % at level 2;
        #: docs/validation/converged-answers.md, "Adaptive time steps"). With varying steps
        #: only: with constant ones the two-step mean is as consistent and smoother.
        self.midpoint_pressure = varying_steps and integrator == "trapezoidal" and self._pressure_lag > 0
        if self.midpoint_pressure and not self.estimator.lags_pressure:
            self.midpoint_pressure = False
            log.warning("force %r does not separate the pressure's part: with steps that vary, %s and the "
                        "trapezoidal integrator bias the particles' velocities (up to 4 %% where steps "
                        "alternate); use fbm.force = 'volume' or 'surface', or coupling.integrator = "
                        "'semi-implicit-euler' (docs/validation/converged-answers.md)",
                        self.estimator.name, time_scheme)
        self.particles = particles.copy()
        self.particles.position = wrap(mesh, self.particles.position)
        self._geometry: ParticleGeometry | None = None
        self._behind = None  # (centres, force rule) where the pressure's force is taken
        self._wall_nodes = np.zeros(0, dtype=np.int64)  # set once the flow is made
        drive = None if not np.any(self.drive) else (lambda x, t: np.broadcast_to(self.drive, x.shape))
        if self.comm.size > 1:
            self.flow = BlockNavierStokesProblem(mesh, fluid.viscosity, boundary, self.comm,
                                                density=fluid.density, body_force=drive, newton=newton,
                                                multigrid=linear_solver.settings,
                                                extra_constraints=self._own_constraints,
                                                halo=reach_layers(mesh) if sharp else 1, grid=process_grid)
        else:
            self.flow = NavierStokesProblem(mesh, fluid.viscosity, boundary, density=fluid.density,
                                            body_force=drive, linear_solver=linear_solver, newton=newton,
                                            extra_constraints=self._own_constraints)
        #: the cells whose part of the forces this process takes (None: all, one process)
        self._cells = self.flow.partition.owned_cells if self.comm.size > 1 else None
        self.x = self.flow.zero_state()
        self.t = 0.0
        self.step_count = 0
        # hydrodynamic force (n, dim) and torque (n, 3) at the end of the last step (None before
        # the first: unknown, the fluid's reaction to the first acceleration is not zero)
        self.last_force: np.ndarray | None = None
        self.last_torque: np.ndarray | None = None
        #: (force (n, dim), torque (n, 3)): the pressure's part of them (:attr:`midpoint_pressure`)
        self.last_pressure: tuple | None = None
        self.contact_report = None  # what contact did in the last integration with it
        fixed = self.flow.fine.boundary_constraints.dofs  # velocity nodes the walls hold wholly
        space = self.flow.space
        self._wall_nodes = np.flatnonzero(np.bincount(fixed % space.n_v, minlength=space.n_v) == space.dim)
        self._geometry = None  # made with the wall nodes from now on
        self._warned_fast = 0.0  # the largest move in cells per step warned about (_warn_if_fast)
        self._warned_coarse = False  # a particle in cells too coarse for it (_warn_if_coarse)

    # -- the configuration ----------------------------------------------------------------------
    def geometry(self) -> ParticleGeometry:
        """The :class:`ParticleGeometry` of the particles' current configuration."""
        if self._geometry is None or not self._geometry.describes(self.particles):
            whole = self.mesh if self.comm.size > 1 else None
            self._geometry = ParticleGeometry(self.flow.space, self.particles, self.sharp, self.estimator,
                                              self._wall_nodes, self._cells, whole, self.comm)
        return self._geometry

    def owner(self) -> np.ndarray:
        """Particle owning every Q2 velocity node at the current state (-1: fluid), (n_v,) int64."""
        return self.geometry().owner(self.flow.space.V)

    def _own_constraints(self, V, t):
        """The flow's fictitious-boundary constraints: the particles' rigid motion with their own
        velocities (a scheme that iterates on other velocities passes its own to the solve)."""
        p = self.particles
        return self.geometry().constraints(V, p.velocity, p.angular_velocity)

    # -- what the coupling schemes use (fbmflow.coupling.schemes.CoupledProblem) -------------------
    def flow_and_forces(self, dt: float, velocities: Particles | None = None, guess: np.ndarray | None = None,
                        rtol: float | None = None, linear_rtol: float | None = None):
        """Solve the flow over the step ``dt`` from the current state, the particles at their
        current positions moving with the velocities of ``velocities`` (default: their own), from
        the initial guess ``guess`` (n_dofs,) with Newton's residual reduction ``rtol`` (default:
        the solver settings') and linear steps no tighter than ``linear_rtol`` (default: the
        solver settings'). Returns ``(x (n_dofs,), Newton reports, force (n, dim), torque
        (n, 3))``; the state itself is not changed."""
        extra = None
        if velocities is not None:
            geometry = self.geometry()

            def extra(V, t):
                return geometry.constraints(V, velocities.velocity, velocities.angular_velocity)
        x, reports = advance(self.flow, self.x, self.t, dt, self.time_scheme, guess, rtol, linear_rtol, extra)
        force, torque = self.forces(x, dt)
        return x, reports, force, torque

    def integrate(self, force: np.ndarray, torque: np.ndarray, dt: float, contact: bool = True,
                  x: np.ndarray | None = None) -> Particles:
        """New particle state under the hydrodynamic ``force (n, dim)`` and ``torque (n, 3)``, the
        push of the periodic drive's pressure gradient on their volume (:attr:`drive`), the
        repulsive forces (at the positions of the start of the step) and, with hard contact
        (unless ``contact`` is False), the contact impulses; the state itself is not changed.

        ``x``: the step's flow, whose pressure force replaces the last step's in the trapezoidal
        rule's start forces with :attr:`midpoint_pressure` (required then)::

            v^{n+1} = v^n + dt / 2 (a(F^n - F_p^n + F_p^{n+1}) + a(F^{n+1}))
                    = v^n + dt / 2 (a_visc^n + a_visc^{n+1}) + dt a_p^{n+1}
        """
        previous = None  # the trapezoidal rule's forces at the start of the step (None: no history)
        if self.last_force is not None:
            previous = self.last_force, self.last_torque
            if self.midpoint_pressure:
                if x is None:
                    raise ValueError("the midpoint rule for the pressure needs the step's flow x")
                force_p, torque_p = self.pressure_forces(x, dt)
                previous = (previous[0] - self.last_pressure[0] + force_p,
                            previous[1] - self.last_pressure[1] + torque_p)
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
        new, self.contact_report = self.contact.advance(self.particles, lin, ang, dt, self.contact_substeps)
        return new

    def repulsion_stiffness(self) -> sp.csr_matrix | None:
        """The repulsive forces' change with the positions at the start of the step,
        ``(n dim, n dim)`` (:meth:`~fbmflow.contact.repulsion.Repulsion.stiffness`); None when the repulsion
        is off or the particles are frozen (their positions do not change)."""
        if self.repulsion is None or self.frozen:
            return None
        return self.repulsion.stiffness(self.particles, self.gravity, self.flow.rho)

    def velocity_gain(self, dt: float) -> np.ndarray:
        """``d v_new / d f`` of :meth:`integrate` over ``dt``
        (:func:`~fbmflow.particles.dynamics.velocity_gain`),
        (n, r, r) float64. With :attr:`midpoint_pressure` the pressure's part of ``f`` gains twice
        this; the coupling schemes' Jacobians take this gain for the whole force (the implicit
        scheme's Broyden update corrects it)."""
        return velocity_gain(self.particles, dt, self.integrator, history=self.last_force is not None)

    def rigid_responses(self, x: np.ndarray, free: np.ndarray, dt: float, motions: np.ndarray | None = None,
                        rtol: float | None = None):
        """The flow's linear response to a unit rigid motion of every free component and its
        force: ``free (n, r)`` bool selects the ``k`` generalised velocity components; returns
        ``dX (k, n_dofs)``, ``dF (k, n, dim)`` and ``dT (k, n, 3)`` about the flow ``x`` solved
        last (:meth:`~fbmflow.flow.navier_stokes.NavierStokesProblem.lifting_response`). With ``motions
        (m, k)``, the responses to those ``m`` combinations of the unit motions instead (one
        linear solve each, to ``rtol`` where the linear solver takes one): ``dX (m, n_dofs)``,
        ``dF (m, n, dim)``, ``dT (m, n, 3)``."""
        p, space, geometry = self.particles, self.flow.space, self.geometry()
        sharp = geometry.sharp(space.V)
        W = rigid_liftings(space.V, geometry.owner(space.V), p.position, free)
        row_liftings = None if sharp is None else sharp.ghosts.liftings(free)
        if motions is not None:
            W = sp.csc_matrix(W @ motions.T)
            row_liftings = None if row_liftings is None else sp.csc_matrix(row_liftings @ motions.T)
        dX = self.flow.lifting_response(x, W, row_liftings, rtol)
        dF, dT = self._response_forces(dX, dt, about=x)
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
        out (how close the sum comes to the exact blocks: docs/validation/many-particles.md)."""
        p, space, geometry = self.particles, self.flow.space, self.geometry()
        W = rigid_liftings(space.V, geometry.owner(space.V), p.position, free)
        S = sum_replicated(self.estimator.own_response(geometry.rule(), W, free, self.flow.mu, self.flow.rho,
                                                       dt=dt, about=x[:space.n_u]), self.comm)
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

    # -- forces ---------------------------------------------------------------------------------
    def forces(self, x: np.ndarray, dt: float, about: np.ndarray | None = None):
        """Hydrodynamic force (n, dim) and torque (n, 3) of the whole particles for the flow ``x``
        at the end of a step of length ``dt`` from ``self.x``, by the force estimator; with
        ``about`` (a flow), ``x`` is a change of that flow and the result the force's change
        (linear in ``x``).

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
        here = self.geometry().rule()
        behind = self._rule_lagged(dt)
        if behind is None:
            force, torque = est.evaluate(here, u, p, mu, rho, u_old=u_old, dt=dt, about=linear)
        else:
            force, torque = est.evaluate(here, u, None, mu, rho, u_old=u_old, dt=dt, about=linear)
            force_p, torque_p = est.evaluate(behind, None, p, mu, rho, u_old=u_old, dt=dt, about=linear)
            force, torque = force + force_p, torque + torque_p
        return self._whole_particles(force, torque)

    def pressure_forces(self, x: np.ndarray, dt: float):
        """The pressure's part of :meth:`forces` ``(x, dt)``: force (n, dim) and torque (n, 3);
        estimators that separate it (``lags_pressure``) only."""
        behind = self._rule_lagged(dt)
        rule = self.geometry().rule() if behind is None else behind
        pressure = x[self.flow.space.n_u:]
        force, torque = self.estimator.evaluate(rule, None, pressure, self.flow.mu, self.flow.rho, dt=dt)
        return self._whole_particles(force, torque)

    def _response_forces(self, dX: np.ndarray, dt: float, about: np.ndarray):
        """:meth:`forces` of the ``k`` flow responses ``dX (k, n_dofs)`` about the flow ``about``:
        force (k, n, dim) and torque (k, n, 3), all responses and particles in one evaluation
        (``evaluate_many`` of the estimator)."""
        n_u, pt = self.flow.space.n_u, self.particles
        if len(dX) == 0:
            return np.zeros((0, pt.n, pt.dim)), np.zeros((0, pt.n, 3))
        U, P = dX[:, :n_u], dX[:, n_u:]
        est, mu, rho = self.estimator, self.flow.mu, self.flow.rho
        here = self.geometry().rule()
        behind = self._rule_lagged(dt)
        if behind is None:
            force, torque = est.evaluate_many(here, U, P, mu, rho, dt=dt, about=about[:n_u])
        else:
            force, torque = est.evaluate_many(here, U, None, mu, rho, dt=dt, about=about[:n_u])
            force_p, torque_p = est.evaluate_many(behind, None, P, mu, rho, dt=dt, about=about[:n_u])
            force, torque = force + force_p, torque + torque_p
        return self._whole_particles(force, torque)

    def _whole_particles(self, force: np.ndarray, torque: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The whole particles' force and torque from this process's part (summed over the
        processes, :func:`~fbmflow.parallel.comm.sum_replicated`) and their mirror images."""
        if self.comm.size > 1:
            both = sum_replicated(np.concatenate([force.ravel(), torque.ravel()]), self.comm)
            force, torque = both[:force.size].reshape(force.shape), both[force.size:].reshape(torque.shape)
        return mirror_images(force, torque, self.symmetry) if self.symmetry else (force, torque)

    def _rule_lagged(self, dt: float):
        """The estimator's rule where the pressure of a step of length ``dt`` belongs; None where
        that is where the particles are (an estimator that does not lag the pressure, a time
        scheme without lag, particles at rest). See :meth:`forces`."""
        p = self.particles
        if not self.estimator.lags_pressure or self._pressure_lag == 0.0 or not np.any(p.velocity):
            return None
        centres = p.position - self._pressure_lag * dt * p.velocity
        if self._behind is None or not np.array_equal(self._behind[0], centres):
            rule = self.estimator.prepare(self.flow.space, centres, p.shapes, p.rotations(),
                                          walls=self._wall_nodes, cells=self._cells,
                                          spacing=self.geometry().spacing)
            self._behind = (centres.copy(), rule)
        return self._behind[1]

    # -- the step's end -------------------------------------------------------------------------
    def commit(self, solved: CoupledFlow, new: Particles, dt: float) -> np.ndarray | None:
        """End the step of length ``dt``: the flow ``solved.x``, the particles ``new`` (held in
        place when frozen, wrapped into a periodic box), uncovered ghost nodes set to the solid's
        velocity (sharp boundary), the mixture's mean flux removed (:attr:`zero_flux`), the step's
        forces kept for the next (the trapezoidal rule's history), the time and step count
        advanced. ConvergenceError when the state is not finite. Returns the mean velocity
        removed, (dim,) float64, or None."""
        if not (np.all(np.isfinite(new.position)) and np.all(np.isfinite(solved.x))):
            raise ConvergenceError("non-finite state", "reduce time.dt (the step diverged)")
        if self.frozen:
            new.position, new.orientation = self.particles.position.copy(), self.particles.orientation.copy()
        sharp = self.geometry().sharp(self.flow.space.V)  # of the positions the flow was solved with
        pressure = self.pressure_forces(solved.x, dt) if self.midpoint_pressure else None
        moved = new.position - self.particles.position
        self._warn_if_fast(moved, dt)
        new.position = wrap(self.mesh, new.position)
        self._check_overlap(new, moved, dt)
        self._warn_if_coarse(new)
        self.x, self.particles = solved.x, new
        if sharp is not None:  # uncovered ghost nodes start the next step with the solid's velocity
            dofs, values = sharp.ghosts.uncovered(self.flow.space.V, self.owner(), new.position, new.velocity,
                                                  new.angular_velocity)
            self.x[dofs] = values
            self.flow.make_consistent(self.x)  # the outer halo's ghost nodes may not be this process's
        shift = self._remove_mean_flux() if self.zero_flux else None
        self.last_force, self.last_torque, self.last_pressure = solved.force, solved.torque, pressure
        self.t += dt
        self.step_count += 1
        return shift

    def _check_overlap(self, new: Particles, moved: np.ndarray, dt: float) -> None:
        """Stop (ConvergenceError with a remedy that fits) when the step's end ``new`` has a
        particle deeper than :data:`MAX_OVERLAP` of its radius in a wall or another particle
        (:func:`~fbmflow.contact.deepest_overlap`); ``moved (n, dim)`` the step's displacements."""
        mesh = self.mesh
        periods = mesh.periods if any(mesh.periodic) else None
        overlap = deepest_overlap(new, self._planes, periods, np.asarray(mesh.lower, dtype=float))
        if overlap is None or overlap.fraction <= MAX_OVERLAP:
            return
        k = overlap.particle
        cells = float(np.linalg.norm(moved[k])) / float(np.min(mesh.finest_spacing))
        if overlap.other < 0:
            axis, side = overlap.wall
            where = f"{overlap.fraction:.2f} of its radius into the wall {'xyz'[axis]} = " \
                    f"{(mesh.lower, mesh.upper)[side][axis]:g}"
            keeper = "wall contact (contact.enabled = true), which stops a particle at the wall,"
        else:
            where = f"{overlap.fraction:.2f} of the smaller radius into particle {overlap.other}"
            keeper = "hard contact (contact.enabled = true), which keeps particles apart,"
        remedy = f"reduce time.dt (this step moved it {cells:.2g} cells; the repulsion needs several steps " \
                 "within its range to stop a particle)"
        radius = float(new.bounding_radius[k] if overlap.other < 0 else
                       min(new.bounding_radius[k], new.bounding_radius[overlap.other]))
        if self.contact is None:
            remedy = f"turn on {keeper} or {remedy}"
        elif self.contact.skin > SKIN_FRACTION * radius:  # the skin, not the step, pushed it there
            remedy = (f"refine the mesh (--level) or lower contact.skin_cells: hard contact keeps surfaces "
                      f"{self.contact.skin:.3g} apart, {self.contact.skin / radius:.2g} particle radii, so "
                      f"particles that start closer are pushed apart at once (this step moved it {cells:.2g} "
                      "cells, whatever the step); or start them further apart (particles.spacing where the "
                      "scene has it)")
        raise ConvergenceError(f"particle {k} reaches {where} (depth {overlap.depth:.3g})", remedy)

    def _warn_if_coarse(self, new: Particles) -> None:
        """Warn, once per run, when a particle leaves the fine zone of a graded mesh: where it
        sits the cells are more than :data:`COARSE_FACTOR` times the finest (a light disk rising
        out of ``glowinski-free-fall``'s fine zone ran 2.3 times as fast as on a uniform mesh);
        where it spans less than a velocity-node spacing the placement check would have refused
        it at the start (:func:`~fbmflow.coupling.placement.too_small`)."""
        mesh = self.mesh
        if self._warned_coarse or mesh.axis_coordinates is None:
            return
        small, h = too_small(mesh, new.position, new.bounding_radius)
        ratio = h / float(np.min(mesh.finest_spacing))
        out = np.flatnonzero(ratio > COARSE_FACTOR)
        if out.size:
            self._warned_coarse = True
            k = int(small[0]) if small.size else int(out[np.argmax(ratio[out])])
            worse = " (it spans less than a velocity-node spacing there)" if small.size else ""
            log.warning("step %d: particle %d left the graded mesh's fine zone: cells of %.3g there, %.1f "
                        "times the finest%s; its motion loses accuracy: use a uniform mesh (domain.mesh = "
                        "uniform) or a fine zone that holds its path", self.step_count + 1, k, h[k], ratio[k],
                        worse)

    def mixture_velocity(self) -> np.ndarray:
        """The mixture's mean velocity over the whole mesh (:func:`~fbmflow.fem.functions.mean_velocity`:
        its volume flux per unit area), (dim,) float64; on several processes the owned nodes'
        parts summed in rank order, the same bits on every process."""
        space = self.flow.space
        if self.comm.size == 1:
            return mean_velocity(space, self.x[:space.n_u])
        own = self.flow.partition.owned_nodes
        w = node_integrals(space)[own]
        total = sum_replicated(np.append(self.x[:space.n_u].reshape(space.dim, -1)[:, own] @ w, w.sum()),
                               self.comm)
        return total[:-1] / total[-1]

    def _remove_mean_flux(self) -> np.ndarray:
        """Subtract the mixture's mean velocity (:func:`~fbmflow.fem.functions.mean_velocity`, the
        volume flux per unit area) from the flow and the particles: a Galilean change of frame,
        exact in a fully periodic box. Returns the velocity removed, (dim,) float64.

        The drive carries the particles' weight exactly, so the flux would stay zero, but the
        particles move under the estimated hydrodynamic force, whose error the fluid does not
        feel: momentum leaks at that rate, and without this the mixture would drift without
        bound (docs/validation/periodic-suspensions.md)."""
        space = self.flow.space
        shift = self.mixture_velocity()
        self.x[:space.n_u] -= np.repeat(shift, space.n_v)
        self.particles.velocity = self.particles.velocity - shift
        return shift

    def _warn_if_fast(self, moved: np.ndarray, dt: float) -> None:
        """Warn when a step moves a particle more than a finest cell (the fictitious boundary
        jumps over velocity nodes, and forces and contact lose accuracy), and again each time
        the largest such move doubles."""
        if moved.size == 0:
            return
        cells = np.linalg.norm(moved, axis=1) / float(np.min(self.mesh.finest_spacing))
        k = int(np.argmax(cells))
        if cells[k] > max(1.0, 2.0 * self._warned_fast):
            self._warned_fast = float(cells[k])
            log.warning("step %d moved particle %d by %.1f cells; forces and contact lose accuracy above "
                        "about one cell per step: reduce the time step (dt = %.3g s) to %.3g s or less",
                        self.step_count + 1, k, cells[k], dt, dt / cells[k])

    # -- restarts -------------------------------------------------------------------------------
    def state(self) -> dict:
        """Everything a restart of the system needs, as arrays and numbers: flow ``x``, time, step
        count, the particles' positions, velocities, orientations, angular velocities, densities,
        fixed flags, the last step's forces (and their pressure's part, :attr:`midpoint_pressure`) and
        the contact warm-start impulses. (The shapes come from the set-up.)"""
        p = self.particles
        out = {"x": self.x.copy(), "t": self.t, "step_count": self.step_count,
               "position": p.position.copy(), "velocity": p.velocity.copy(),
               "orientation": p.orientation.copy(), "angular_velocity": p.angular_velocity.copy(),
               "density": p.density.copy(), "fixed": p.fixed.copy()}
        if self.last_force is not None:  # the trapezoidal rule's force history (none before step 1)
            out.update(last_force=self.last_force.copy(), last_torque=self.last_torque.copy())
        if self.last_pressure is not None:
            out.update(last_pressure_force=self.last_pressure[0].copy(),
                       last_pressure_torque=self.last_pressure[1].copy())
        if self.contact is not None:
            out.update({f"contact_{k}": v for k, v in self.contact.state().items()})
        return out

    def set_state(self, state: dict) -> None:
        """Restore :meth:`state`; ValueError when it does not fit this system."""
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
            self.last_force = np.array(state["last_force"], dtype=float)
            self.last_torque = np.array(state["last_torque"], dtype=float)
        elif self.integrator == "trapezoidal" and self.step_count > 0:
            raise ValueError("the state lacks the last step's forces, which the trapezoidal integrator needs")
        else:
            self.last_force = self.last_torque = None
        self.last_pressure = None
        if "last_pressure_force" in state:
            self.last_pressure = (np.array(state["last_pressure_force"], dtype=float),
                                  np.array(state["last_pressure_torque"], dtype=float))
        elif self.midpoint_pressure and self.last_force is not None:
            raise ValueError("the state lacks the last step's pressure force, which the midpoint rule for "
                             "the pressure needs (a state of a run with constant steps)")
        if self.contact is not None:
            self.contact.set_state({k[len("contact_"):]: v for k, v in state.items()
                                    if k.startswith("contact_")})
        self._geometry = None
        self.flow.forget_linearisation()
