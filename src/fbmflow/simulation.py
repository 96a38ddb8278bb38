"""The particulate-flow time loop (docs/design.md, "One time step"): particles -> mesh, flow,
forces, particles, contact.

A :class:`Simulation` is made from a mesh, the particles and typed parameter sections: the fluid,
the time stepping, the solvers, the coupling scheme (:data:`fbmflow.coupling.schemes.COUPLINGS`), the
fictitious boundary with its force estimator (:data:`fbmflow.coupling.estimators.FORCE_ESTIMATORS`), hard
contact and repulsion. It is a thin orchestrator: the state and the physics live in its
:class:`~fbmflow.coupling.system.CoupledSystem` (:attr:`Simulation.system`), a coupling scheme
advances that system by one step, and the simulation resolves the ``auto`` choices, checks the
memory (:func:`~fbmflow.solvers.choice.check_memory`) before anything is assembled, and reports.
"""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from . import __version__
from .adaptive import StepControl
from .config import check_types
from .contact.settings import ContactParams, RepulsionParams
from .coupling import make_coupling
from .coupling.indicator import node_owner
from .coupling.schemes import auto_coupling
from .coupling.settings import CouplingParams, FictitiousBoundaryParams
from .coupling.system import CoupledSystem, StepReport
from .fem import FlowSpace
from .fem.functions import sample_pressure, sample_velocity
from .flow import NoSlip
from .io import load_checkpoint
from .parallel import on_first, world
from .params import FluidParams, TimeParams
from .particles import Particles
from .run import Progress, RunFiles, claim_once, output_folder, run_loop
from .solvers import ConvergenceError
from .solvers.choice import check_memory
from .solvers.settings import SolverParams


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
        (:func:`~fbmflow.coupling.placement.periodic_drive`), so that the suspension as a whole does not
        accelerate; in a box periodic along every axis the step also removes the mixture's mean
        volume flux (a Galilean change of frame that stops the drift the force
        estimator's error would cause). Particles cross periodic sides (their centres wrap into
        the box); forces, constraints, repulsion and hard contact take the nearest image.
    boundary : dict tag -> condition, optional
        One of :mod:`fbmflow.flow.boundary`'s conditions for every non-periodic face of the mesh;
        default: no-slip walls all round.
    time : TimeParams
        The time scheme; ``dt`` and ``t_end`` are what :meth:`run` and :meth:`step` without a
        time step use; with ``adaptive`` each step's size comes from a local error estimate of
        the particles' velocities (:class:`~fbmflow.adaptive.StepControl`, :attr:`control`).
    solver : SolverParams
        Newton and linear solver settings. ``linear = "auto"`` takes the cheaper of the direct
        solver and multigrid by measured cost
        (:func:`~fbmflow.solvers.choice.choose_linear_solver`).
    coupling : CouplingParams
        The coupling scheme (:data:`~fbmflow.coupling.schemes.COUPLINGS`)
        and the particle integrator (``trapezoidal`` with ``crank-nicolson`` is second order in
        time).
    fbm : FictitiousBoundaryParams
        ``boundary``: ``nodes`` (every node inside a particle moves rigidly; first order in the
        mesh size) or ``sharp`` (the no-slip condition on the true surface,
        :mod:`fbmflow.coupling.sharp`; shapes with ``project``); ``force``: the estimator
        (:data:`~fbmflow.coupling.estimators.FORCE_ESTIMATORS`: ``volume``, ``test-function`` or
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
        domain's faces there carry :class:`~fbmflow.flow.boundary.Slip`); forces and torques are those
        of the whole particles (:func:`~fbmflow.coupling.forces.mirror_images`), the particles' motion
        stays on the planes, and the planes are no walls for contact and repulsion. Gravity must
        lie in the planes.
    comm : communicator or None
        The processes that run the simulation together (mpi4py's; default: every process an
        MPI launcher started, :func:`~fbmflow.parallel.comm.world`, or this one alone). On
        several, each holds a slab of the mesh along its last axis and :attr:`x` is its part of
        the flow; the particles are the same on every process
        (:class:`~fbmflow.coupling.system.CoupledSystem`); the linear solver is multigrid
        (``solver.linear = "auto"`` takes it).
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
        support, contact with the trapezoidal or adaptive stepping), or
        :class:`~fbmflow.solvers.choice.InsufficientMemory`; the message says what to change.
    """

    def __init__(self, mesh, particles: Particles, fluid: FluidParams, *, boundary: dict | None = None,
                 time: TimeParams = TimeParams(), solver: SolverParams = SolverParams(),
                 coupling: CouplingParams = CouplingParams(),
                 fbm: FictitiousBoundaryParams = FictitiousBoundaryParams(),
                 contact: ContactParams | None = None, repulsion: RepulsionParams | None = None,
                 symmetry: tuple = (), frozen: bool = False, comm=None):
        check_types("Simulation", particles=(particles, Particles), fluid=(fluid, FluidParams),
                    time=(time, TimeParams), solver=(solver, SolverParams),
                    coupling=(coupling, CouplingParams), fbm=(fbm, FictitiousBoundaryParams),
                    contact=(contact, ContactParams, None), repulsion=(repulsion, RepulsionParams, None))
        #: the arguments this simulation was made with (:func:`fbmflow.scenes.registry.resume` makes it
        #: again from them)
        self._setup = dict(mesh=mesh, particles=particles.copy(), fluid=fluid, boundary=boundary, time=time,
                           solver=solver, coupling=coupling, fbm=fbm, contact=contact, repulsion=repulsion,
                           symmetry=tuple(symmetry), frozen=frozen)
        contact = contact if contact is not None and contact.enabled else None
        if contact is not None and coupling.integrator != "semi-implicit-euler":
            raise ValueError("hard contact advances the particles by semi-implicit Euler; integrator "
                             f"{coupling.integrator!r} cannot be combined with it: set coupling.integrator = "
                             "'semi-implicit-euler' or turn contact off")
        self.time = time
        #: the adaptive step's controller (None: steps of :attr:`dt`)
        self.control = StepControl(time, particles, bool(contact)) if time.adaptive else None
        #: the processes that run this simulation together
        self.comm = world() if comm is None else comm
        solver = solver.on_processes(self.comm.size)
        n_unknowns = FlowSpace.estimate_dofs(mesh)
        if coupling.scheme == "auto":
            coupling = dataclasses.replace(coupling, scheme=auto_coupling(n_unknowns, particles, symmetry))
        #: the coupling scheme that advances :attr:`system` by a step
        self.coupling = make_coupling(coupling, solver.newton_rtol)
        responses = self.coupling.stored_responses(particles, tuple(symmetry))
        linear = solver.linear_solver(mesh.dim, n_unknowns, responses)
        check_memory(n_unknowns // self.comm.size, mesh.dim, linear, responses, transient=True)
        if solver.device == "gpu":
            from .gpu import gpu_solver  # the gpu extra, imported where asked for

            linear = gpu_solver(linear, mesh.dim, n_unknowns)
        boundary = {t: NoSlip() for t in mesh.tags} if boundary is None else boundary
        #: the coupled flow and particles and their state
        self.system = CoupledSystem(mesh, particles, fluid, boundary=boundary, time_scheme=time.scheme,
                                    integrator=coupling.integrator, fbm=fbm, contact=contact,
                                    repulsion=repulsion, symmetry=symmetry, frozen=frozen,
                                    linear_solver=linear, newton=solver.newton_settings(),
                                    varying_steps=time.adaptive, comm=self.comm,
                                    process_grid=solver.grid(self.comm.size, mesh.dim))

    # -- the state ------------------------------------------------------------------------------
    @property
    def flow(self):
        """The :class:`~fbmflow.flow.navier_stokes.NavierStokesProblem` (mesh, space, solvers)."""
        return self.system.flow

    @property
    def mesh(self):
        """The whole mesh (:attr:`flow`'s is this process's slab of it on several processes)."""
        return self.system.mesh

    @property
    def n_dofs(self) -> int:
        """The whole mesh's unknowns (:attr:`x` holds this process's part on several)."""
        return FlowSpace.estimate_dofs(self.mesh)

    def whole(self, x: np.ndarray) -> np.ndarray | None:
        """The whole mesh's flow vector ``(n_dofs,)`` from every process's part ``x`` (such as
        :attr:`x`): on the first process, None on the others (every process calls it); ``x``
        itself on one process."""
        if self.comm.size == 1:
            return x
        return self.flow.partition.gather(x, self.n_dofs)

    @property
    def particles(self) -> Particles:
        """The particles' current state."""
        return self.system.particles

    def mixture_velocity(self) -> np.ndarray:
        """The mean velocity of fluid and particles over the whole mesh (their volume flux per
        unit area), (dim,) float64 [m/s]; every process calls it on several."""
        return self.system.mixture_velocity()

    @property
    def x(self) -> np.ndarray:
        """The flow's current state, (n_dofs,) float64: velocity (component-blocked), pressure."""
        return self.system.x

    @property
    def t(self) -> float:
        """The current time [s]."""
        return self.system.t

    @property
    def step_count(self) -> int:
        """Steps taken since ``t = 0``."""
        return self.system.step_count

    @property
    def contact(self):
        """The :class:`~fbmflow.contact.contact_set.ContactSet` (None without hard contact)."""
        return self.system.contact

    @property
    def n_steps(self) -> int:
        """Steps of a whole run to ``time.t_end`` (:attr:`~fbmflow.params.TimeParams.n_steps`)."""
        return self.time.n_steps

    @property
    def dt(self) -> float:
        """The time step of :meth:`run` [s]: ``time.t_end / n_steps`` (``time.dt`` shortened
        evenly so that the last step lands on ``t_end``)."""
        return self.time.t_end / self.n_steps

    @property
    def force(self) -> np.ndarray:
        """Hydrodynamic force on every particle at the end of the last step, (n, dim) float64
        (zeros before the first step)."""
        f = self.system.last_force
        return np.zeros_like(self.particles.position) if f is None else f.copy()

    @property
    def torque(self) -> np.ndarray:
        """Hydrodynamic torque on every particle at the end of the last step, (n, 3) float64
        (zeros before the first step)."""
        m = self.system.last_torque
        return np.zeros((self.particles.n, 3)) if m is None else m.copy()

    def owner(self) -> np.ndarray:
        """Particle owning every Q2 velocity node at the current state (-1: fluid), (n_v,) int64
        (the nodes of this process's slab on several)."""
        return self.system.owner()

    def velocity_at(self, points) -> np.ndarray:
        """Fluid velocity at ``points (m, dim)``, (m, dim) float64 (inside a particle: its rigid
        motion, as the constraints hold it). On several processes every process calls it and gets
        the answer (the whole flow gathered and broadcast: for a few looks, not every step)."""
        space, x = self._whole_flow()
        return sample_velocity(space, x[:space.n_u], np.atleast_2d(points))

    def pressure_at(self, points) -> np.ndarray:
        """Pressure at ``points (m, dim)``, (m,) float64 (P1disc: the value of the cell each point
        lies in); on several processes as :meth:`velocity_at`."""
        space, x = self._whole_flow()
        return sample_pressure(space, x[space.n_u:], np.atleast_2d(points))

    def _whole_flow(self) -> tuple[FlowSpace, np.ndarray]:
        """The whole mesh's space and flow on every process (one gather and one broadcast on
        several)."""
        return self.flow.whole_flow(self.x)

    def field_space(self) -> FlowSpace:
        """The whole mesh's FlowSpace (:attr:`flow`'s on one process; on several made once, on a
        process that asks: the first, which writes the fields)."""
        return self.flow.whole_space

    def field_data(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The whole mesh's flow ``x (n_dofs,)`` and node owner ``(n_v,)`` for output: on the
        first process, None on the others (every process calls it)."""
        x = self.whole(self.x)
        if self.comm.size == 1:
            return x, self.owner()
        if x is None:
            return None
        p = self.particles
        return x, node_owner(self.field_space().V, p.position, p.shapes, p.rotations())

    def write_fields(self, out, step: int | None = None, fmt: str = "vtu") -> Path:
        """Write the flow (velocity, pressure, vorticity, owner) and the particles for ParaView
        into the directory ``out`` (:class:`~fbmflow.io.fields.FieldWriter`), as output number ``step``
        (default: the step count); returns the directory."""
        from .io import FieldWriter

        out = Path(out)
        step = self.step_count if step is None else step
        x_owner = self.field_data()  # every process's part, gathered on the first

        def write():
            out.mkdir(parents=True, exist_ok=True)
            writer = FieldWriter(out, self.field_space(), start_step=step, fmt=fmt)
            writer.write(step, self.t, *x_owner, self.particles, self.force)

        on_first(write, self.comm)
        return out

    def state(self) -> dict:
        """Everything a restart needs, as arrays and numbers (the system's
        :meth:`~fbmflow.coupling.system.CoupledSystem.state`, the coupling scheme's, the step control's)."""
        control = self.control.state() if self.control else {}
        return {**self.system.state(), **self.coupling.state(), **control}

    def set_state(self, state: dict) -> None:
        """Restore :meth:`state`; ValueError when it does not fit this simulation. On several
        processes the flow may be this process's part or the whole mesh's (a checkpoint's,
        written on any number of processes: this process takes its part)."""
        x = np.asarray(state["x"])
        if self.comm.size > 1 and x.shape == (self.n_dofs,):
            state = {**state, "x": self.flow.partition.local(x)}
        self.system.set_state(state)
        self.coupling.set_state(state)
        if self.control is not None:
            self.control.set_state(state)

    # -- stepping -------------------------------------------------------------------------------
    def run(self, out=None, *, checkpoint_every: int = 0, fields_every: int = 0, fields_format: str = "xdmf",
            resume: bool = False, overwrite: bool = False, progress: bool = False,
            callback=None) -> list[StepReport]:
        """Step from the current step to ``time.t_end`` in steps of :attr:`dt` (adaptive ones with
        ``time.adaptive``); returns the steps' reports (ConvergenceError names a failing step).

        With an output folder ``out`` the run writes ``run.h5`` (a row per step), a checkpoint
        every ``checkpoint_every`` steps (and on a failed step or a signal), ParaView output
        every ``fields_every`` steps, and its set-up, so that ``fbmflow.resume``
        (:func:`~fbmflow.scenes.registry.resume`) continues it bit-exactly
        (:func:`fbmflow.run.run_loop`); it owns the folder while it writes, and a
        folder holding another run's results is refused unless ``overwrite``
        (:func:`fbmflow.run.claim`). ``resume``: continue from ``out``'s checkpoint instead (this
        simulation made as the run's was). ``progress``: show progress on stderr;
        ``callback(report)`` after every step.
        """
        dt = None if self.control else self.dt
        progress = Progress() if progress and self.comm.rank == 0 else None  # printed once
        if out is None:
            return run_loop(self, self.n_steps, dt, None, callback=callback, progress=progress).reports
        folder = on_first(lambda: output_folder(out), self.comm) or Path(out)
        files = RunFiles(folder, checkpoint_every, resume, fields_every, fields_format,
                         {"kind": "simulation", "fbmflow_version": __version__}, setup=self._setup)
        with claim_once(files.out, resume, overwrite, self.comm):
            resumed = None
            if resume:
                state, _, resumed = load_checkpoint(files.out / "checkpoint.h5", expect=files.meta)
                self.set_state(state)
            return run_loop(self, self.n_steps, dt, files, callback=callback, resumed=resumed,
                            progress=progress).reports

    def step(self, dt: float | None = None) -> StepReport:
        """Advance flow and particles over ``dt`` [s] (default :attr:`dt`, or an adaptive step that
        :attr:`control` accepts) by the coupling scheme, then contact; ConvergenceError names the
        step and time."""
        if dt is None and self.control is not None:
            return self.control.step(self)
        if not (dt := self.dt if dt is None else float(dt)) > 0.0:
            raise ValueError(f"the time step must be positive, got {dt}")
        system = self.system
        where = f"step {system.step_count + 1} (t = {system.t:.6g} -> {system.t + dt:.6g})"
        system.contact_report = None
        work = dataclasses.replace(self.flow.linear_work)
        try:
            solved = self.coupling.advance(system, dt)
            shift = system.commit(solved, system.integrate(solved.force, solved.torque, dt, x=solved.x), dt)
        except ConvergenceError as err:
            raise err.with_remedy(self._remedy(), f"{where}: ") from None
        self.coupling.accept(solved)
        newton = sum(r.iterations for r in solved.reports)
        return StepReport(system.step_count, system.t, newton, solved.force, solved.torque,
                          system.particles.position.copy(), system.particles.velocity.copy(),
                          solved.flow_solves, system.contact_report, self.flow.linear_work.since(work), shift)

    def _remedy(self) -> str:
        """What to change when a step fails for a cause that did not name its own remedy."""
        if self.coupling.name == "explicit":
            return ("use coupling.scheme = implicit or stabilised (the explicit coupling is unstable where "
                    "the fluid's added mass is comparable to the particles' mass), or reduce time.dt")
        return "reduce time.dt, refine the mesh (--level), or relax solver.newton_rtol"
