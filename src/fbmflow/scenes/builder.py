"""The one scene builder: how a scene's parameters become a simulation or a flow problem.

A particle scene (:class:`ParticleScene`) only places things: its :meth:`~ParticleScene.layout`
gives the mesh, the particles, the fluid, the boundary conditions and the mirror planes of a
level. The builder adds everything else the same way for every scene, from the parameter
sections every particle scene has (``time``, ``solver``, ``coupling``, ``fbm``, ``repulsion`` and,
where the scene has it, ``contact``): the linear solver (``solver.linear = "auto"``:
:func:`~fbmflow.solvers.choice.choose_linear_solver`), the coupling scheme and the force estimator
(by name from their registries), the step count (:attr:`~fbmflow.params.TimeParams.n_steps`), the
memory check (:func:`~fbmflow.solvers.choice.check_memory`) and the warning about a contact skin too
coarse for the particles. The steady scenes build their flow problem with :func:`flow_problem`.
"""
from __future__ import annotations

import dataclasses
import logging
import math
import sys
from dataclasses import dataclass

from ..config import ParamError, Section, param, tree
from ..contact.settings import SKIN_FRACTION, ContactParams, ContactRepulsionParams, RepulsionParams
from ..coupling.settings import CouplingParams, FictitiousBoundaryParams, NodalBoundaryParams
from ..fem import FlowSpace
from ..flow import NavierStokesProblem
from ..flow.blocks import BlockNavierStokesProblem
from ..parallel import world
from ..params import FluidParams, TimeParams
from ..simulation import Simulation
from ..solvers.choice import check_memory
from ..solvers.settings import SolverParams
from .base import SceneResult, Setup, SimulationScene

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class CgsFluid(FluidParams):
    """Fluid and gravity (CGS units)."""

    density: float = param(1.0, "fluid density", "g/cm^3", positive=True)
    viscosity: float = param(0.1, "dynamic viscosity", "g/(cm s)", positive=True)
    gravity: float = param(980.0, "gravitational acceleration (downwards)", "cm/s^2", nonnegative=True)


@dataclass(frozen=True)
class DomainParams(Section):
    """Mesh of a single particle's fall."""

    mesh: str = param("graded", "graded: uniform cells along the particle's path, growing towards the "
                      "side walls and the lid; uniform: the same cells everywhere",
                      choices=("graded", "uniform"))


@dataclass(frozen=True)
class MeshTime(TimeParams):
    """Time stepping that follows the mesh: with ``dt = 0`` (the default) the time step is
    ``dt = courant h / U``, with h the cell that holds the particle and U the scene's velocity scale
    (:meth:`ParticleScene.velocity_scale`: the terminal velocity of its particle by a drag
    correlation, :mod:`fbmflow.particles.drag`), so that each level halves it; an explicit ``dt``
    wins. The run reports the time step and the Courant number it met (``time_step``,
    ``courant_number`` in ``summary.json``)."""

    dt: float = param(0.0, "time step (0: courant * h / U, halving with each level)", "s", nonnegative=True)
    courant: float = param(0.25, "Courant number U dt / h of the time step when dt = 0 (U: the scene's "
                           "velocity scale, h: the cell that holds the particle)", positive=True,
                           maximum=10.0)


#: the sections every particle scene has, after its own, with their default classes (``contact``:
#: only where the scene passes one)
STANDARD_SECTIONS = {"time": TimeParams, "coupling": CouplingParams, "fbm": FictitiousBoundaryParams,
                     "contact": None, "repulsion": RepulsionParams, "solver": SolverParams}
#: the sections of the scenes with many particles in hard contact: the nodal boundary, contact on,
#: repulsion off
CONTACT_SECTIONS = {"fbm": NodalBoundaryParams, "contact": ContactParams, "repulsion": ContactRepulsionParams}


def particle_params(name: str, doc: str, validate=None, **sections) -> type:
    """The parameter tree of a particle scene (:func:`~fbmflow.config.tree`): its own sections
    in the order given, then those of :data:`STANDARD_SECTIONS`, each the class given here or the
    default one. The class belongs to the calling module."""
    own = {key: cls for key, cls in sections.items() if key not in STANDARD_SECTIONS}
    standard = {key: sections.get(key, cls) for key, cls in STANDARD_SECTIONS.items()}
    return tree(name, doc, validate, sys._getframe(1).f_globals["__name__"], **own,
                **{key: cls for key, cls in standard.items() if cls is not None})


@dataclass
class Layout:
    """What a particle scene places at a level: ``mesh`` (StructuredMesh), ``particles``
    (Particles), ``fluid`` (FluidParams), ``boundary`` (tag -> condition; None: no-slip walls all
    round) and ``symmetry`` (normal axes of mirror planes through the particles)."""

    mesh: object
    particles: object
    fluid: FluidParams
    boundary: dict | None = None
    symmetry: tuple = ()


class ParticleScene(SimulationScene):
    """A time-dependent scene of rigid particles in a flow, built by
    :meth:`~fbmflow.scenes.builder.ParticleScene.build`.

    Subclasses give :meth:`layout`, :meth:`~fbmflow.scenes.base.SimulationScene.observe` and
    :meth:`~fbmflow.scenes.base.SimulationScene.quantities`, :meth:`velocity_scale` when their
    time section is a :class:`MeshTime`, and override :meth:`time` when it leaves other values
    to the set-up.
    """

    def layout(self, params, level: int) -> Layout:
        raise NotImplementedError

    def velocity_scale(self, params) -> float:
        """The fastest velocity the run is expected to reach [length/s], which a time step that
        follows the mesh is made for (:class:`MeshTime`)."""
        raise NotImplementedError(f"{self.name} gives no velocity scale: its time section needs a dt")

    def time(self, params, place: Layout) -> TimeParams:
        """The time stepping of a run laid out as ``place``: ``params.time``, with ``dt = courant h
        / U`` where it leaves ``dt`` 0 (:class:`MeshTime`; h the smallest side of the cells that
        hold the particles at the start)."""
        t = params.time
        if t.dt:
            return t
        speed = self.velocity_scale(params)
        h = float(place.mesh.cell_size_at(place.particles.position).min())
        if not speed > 0:
            raise ParamError(f"{self.name}: the particles are expected not to move (velocity scale "
                             f"{speed:g}), so the time step cannot follow the mesh; set time.dt")
        dt = t.courant * h / speed
        log.info("%s: time step %.4g s = Courant %.3g x cell %.4g / velocity scale %.4g (time.dt to choose "
                 "another)", self.name, dt, t.courant, h, speed)
        return dataclasses.replace(t, dt=dt)

    def build(self, params, level: int) -> Setup:
        place = self.layout(params, level)
        frozen = getattr(getattr(params, "particles", None), "frozen", False)  # suspension scenes only
        sim = Simulation(place.mesh, place.particles, place.fluid, boundary=place.boundary,
                         time=self.time(params, place), solver=params.solver, coupling=params.coupling,
                         fbm=params.fbm, contact=getattr(params, "contact", None), repulsion=params.repulsion,
                         symmetry=place.symmetry, frozen=frozen)
        self._check_contact_skin(sim, level)
        return Setup(sim, None if sim.control else sim.dt, sim.n_steps)

    def _check_contact_skin(self, sim: Simulation, level: int) -> None:
        """Warn when hard contact keeps surfaces more than
        :data:`~fbmflow.contact.settings.SKIN_FRACTION` of the smallest radius apart (the skin is
        counted in cells: at a coarse level it can exceed a diameter, and contact times and
        distances lose their meaning), naming the level that avoids it."""
        if sim.contact is None or sim.contact.skin == 0.0:
            return
        radius = float(sim.particles.bounding_radius.min())
        ratio = sim.contact.skin / radius
        if ratio <= SKIN_FRACTION:
            return
        needed = level + math.ceil(math.log2(ratio / SKIN_FRACTION) - 1e-9)
        remedy = (f"use --level {needed} or finer" if needed <= self.max_level
                  else f"levels up to {self.max_level} do not reach it")
        cell = float(max(sim.mesh.finest_spacing))
        log.warning("%s at level %d: the contact skin (%.3g, %.3g cells of %.3g) is %.2g particle radii, so "
                    "contact stops the particles that far apart and contact times and distances lose their "
                    "meaning; %s (a skin of at most %.2g radii) or lower contact.skin_cells", self.name,
                    level, sim.contact.skin, sim.contact.skin / cell, cell, ratio, remedy, SKIN_FRACTION)


def check_mesh_size(shape, periodic, dim: int, cause: str) -> None:
    """Refuse, before the mesh is made, a mesh of ``shape`` cells whose particle time steps would
    not fit the machine even on multigrid (the solver that needs least; the time-step model,
    :func:`~fbmflow.solvers.choice.check_memory` with ``transient``): ParamError with the
    figure, naming ``cause`` (the parameter that made it that large)."""
    from ..solvers.choice import InsufficientMemory

    n = FlowSpace.count_dofs(shape, periodic)
    try:
        check_memory(n, dim, "multigrid", transient=True, warn=False)  # the run's own check warns
    except InsufficientMemory as err:
        cells = " x ".join(str(int(s)) for s in shape)
        raise ParamError(f"{cause} asks for a mesh of {cells} cells: {err}") from None


def flow_problem(mesh, viscosity: float, boundary: dict, solver: SolverParams, density: float = 1.0,
                 halo: int = 1, **kwargs) -> NavierStokesProblem:
    """The flow problem of a scene without particles, with the Newton and linear solver settings
    of ``solver`` (:meth:`~fbmflow.solvers.settings.SolverParams.linear_solver`) and its memory
    checked before the first solve (:func:`~fbmflow.solvers.choice.check_memory`); ``kwargs`` go to
    :class:`~fbmflow.flow.navier_stokes.NavierStokesProblem`. Where a launcher started several
    processes, each holds a slab of the mesh (:class:`~fbmflow.flow.blocks.BlockNavierStokesProblem`,
    multigrid, ``halo`` cell layers of halo on the finest level: the sharp boundary's
    :func:`~fbmflow.coupling.sharp.reach_layers`; ParamError for the direct solver or a mesh too
    small to divide), and the memory check takes its share."""
    comm = world()
    n_unknowns = FlowSpace.estimate_dofs(mesh)
    solver = solver.on_processes(comm.size)
    linear = solver.linear_solver(mesh.dim, n_unknowns)
    check_memory(n_unknowns // comm.size, mesh.dim, linear)
    if solver.device == "gpu":
        from ..gpu import gpu_solver  # the gpu extra, imported where asked for

        linear = gpu_solver(linear, mesh.dim, n_unknowns)
    if comm.size > 1:
        try:
            return BlockNavierStokesProblem(mesh, viscosity, boundary, comm, density=density,
                                            newton=solver.newton_settings(), multigrid=linear.settings,
                                            halo=halo, grid=solver.grid(comm.size, mesh.dim), **kwargs)
        except ValueError as err:  # a mesh too small for the processes
            raise ParamError(str(err)) from None
    return NavierStokesProblem(mesh, viscosity, boundary, density=density, linear_solver=linear,
                               newton=solver.newton_settings(), **kwargs)


def steady_result(problem: NavierStokesProblem, quantities: dict, newton_iterations: int,
                  steps: int = 0) -> SceneResult:
    """The :class:`~fbmflow.scenes.base.SceneResult` of a scene that solved ``problem`` (the whole
    mesh's cells and unknowns on several processes)."""
    space = problem.whole_space
    return SceneResult(quantities, space.mesh.n_cells, space.n_dofs, steps=steps,
                       newton_iterations=newton_iterations, linear_solver=problem.linear_solver_description)
