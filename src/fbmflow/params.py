"""Parameters: frozen, documented dataclasses with strict loading from TOML-like dictionaries.

Every scene's parameters are a tree of frozen dataclasses (:class:`Section` subclasses) whose
fields are declared with :func:`param` (default, unit, documentation and constraints). A section
checks its values when it is made, so ``FluidParams(viscosity=-1.0)`` fails at once;
:func:`from_dict` builds a tree from nested dictionaries and rejects unknown keys, wrong types and
values outside the constraints with a :class:`ParamError` that names the dotted key and what is
allowed. ``--set a.b=value`` overrides use :func:`set_dotted` and :func:`parse_value`.

The sections shared by scenes and by :class:`~fbmflow.simulation.Simulation` are defined here:
:class:`FluidParams`, :class:`TimeParams`, :class:`SolverParams`, :class:`CouplingParams`,
:class:`FictitiousBoundaryParams`, :class:`ContactParams` and :class:`RepulsionParams`.
"""
from __future__ import annotations

import dataclasses
import functools
import math
import sys
import tomllib
import typing
from typing import Any

from .contact import BROADPHASES
from .coupling import COUPLINGS, FORCE_ESTIMATORS
from .flow.time_schemes import TIME_SCHEMES
from .solvers.multigrid import MultigridSettings, MultigridSolver
from .solvers.newton import NewtonSettings


class ParamError(ValueError):
    """Invalid user input (scene file, parameter, command line); the message is one line."""


def param(default, doc: str, unit: str = "", *, positive: bool = False, nonnegative: bool = False,
          choices: tuple | None = None, minimum: float | None = None, maximum: float | None = None):
    """A documented dataclass field with validation metadata."""
    meta = dict(doc=doc, unit=unit, positive=positive, nonnegative=nonnegative, choices=choices,
                minimum=minimum, maximum=maximum)
    if dataclasses.is_dataclass(default):
        return dataclasses.field(default_factory=lambda: default, metadata=meta)
    return dataclasses.field(default=default, metadata=meta)


def section(cls, doc: str = ""):
    """A nested parameter section with its default instance."""
    return dataclasses.field(default_factory=cls, metadata=dict(doc=doc or (cls.__doc__ or "").strip()))


def _check_value(key: str, value: Any, ftype, meta) -> Any:
    if ftype is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ParamError(f"{key}: expected a number, got {value!r}")
        value = float(value)
        if not math.isfinite(value):
            raise ParamError(f"{key}: must be finite, got {value!r}")
    elif ftype is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ParamError(f"{key}: expected an integer, got {value!r}")
    elif ftype is bool:
        if not isinstance(value, bool):
            raise ParamError(f"{key}: expected true or false, got {value!r}")
    elif ftype is str:
        if not isinstance(value, str):
            raise ParamError(f"{key}: expected a string, got {value!r}")
    if meta.get("choices") is not None and value not in meta["choices"]:
        allowed = ", ".join(repr(c) for c in meta["choices"])
        raise ParamError(f"{key}: {value!r} is not allowed; choose one of {allowed}")
    if meta.get("positive") and not value > 0:
        raise ParamError(f"{key}: must be positive, got {value!r}")
    if meta.get("nonnegative") and not value >= 0:
        raise ParamError(f"{key}: must be zero or positive, got {value!r}")
    if meta.get("minimum") is not None and value < meta["minimum"]:
        raise ParamError(f"{key}: must be at least {meta['minimum']}, got {value!r}")
    if meta.get("maximum") is not None and value > meta["maximum"]:
        raise ParamError(f"{key}: must be at most {meta['maximum']}, got {value!r}")
    return value


@functools.cache
def _hints(cls) -> dict:
    return typing.get_type_hints(cls)


class Section:
    """Base of the parameter dataclasses: a section checks its values when it is made.

    Every field declared with :func:`param` is checked against its type (an integer is accepted
    for a float and stored as one) and its constraints, nested sections against their class,
    and then ``validate()``, when the section has one, checks what spans several keys; a
    violation raises :class:`ParamError` naming ``Class.field`` and what is allowed.
    """

    def __post_init__(self):
        hints = _hints(type(self))
        for f in dataclasses.fields(self):
            value, ftype = getattr(self, f.name), hints[f.name]
            if dataclasses.is_dataclass(ftype):
                if not isinstance(value, ftype):
                    raise ParamError(f"{type(self).__name__}.{f.name}: expected a {ftype.__name__}, "
                                     f"got {value!r}")
                continue
            object.__setattr__(self, f.name, _check_value(f"{type(self).__name__}.{f.name}", value, ftype,
                                                          f.metadata))
        validate = getattr(self, "validate", None)
        if validate is not None:
            validate()


def derive(base: type, name: str, doc: str, **changes) -> type:
    """A frozen subclass ``name`` of the section ``base`` with other defaults.

    Each change names a field of ``base``: a plain value replaces its default (its doc, unit and
    bounds stay), a :func:`param` replaces the whole field. The class belongs to the calling
    module. ValueError when ``base`` has no such field. For example
    ``derive(TimeParams, "SlowTime", "Time stepping.", dt=0.1)``."""
    fields, hints = {f.name: f for f in dataclasses.fields(base)}, _hints(base)
    unknown = sorted(set(changes) - set(fields))
    if unknown:
        raise ValueError(f"derive: {base.__name__} has no field {unknown[0]!r}; its fields: "
                         f"{', '.join(fields)}")
    new = [(key, hints[key], change if isinstance(change, dataclasses.Field)
            else dataclasses.field(default=change, metadata=fields[key].metadata))
           for key, change in changes.items()]
    module = sys._getframe(1).f_globals["__name__"]
    return dataclasses.make_dataclass(name, new, bases=(base,), frozen=True,
                                      namespace={"__doc__": doc, "__module__": module})


def tree(name: str, doc: str, validate=None, module: str | None = None, **sections) -> type:
    """A frozen :class:`Section` ``name`` whose fields are the given sections (``key=Class``), in
    that order, each defaulting to its class's defaults; ``validate(self)``, when given, checks
    what spans several sections. The class belongs to ``module`` (default: the calling one)."""
    namespace = {"__doc__": doc, "__module__": module or sys._getframe(1).f_globals["__name__"]}
    if validate is not None:
        namespace["validate"] = validate
    return dataclasses.make_dataclass(name, [(key, cls, section(cls)) for key, cls in sections.items()],
                                      bases=(Section,), frozen=True, namespace=namespace)


def from_dict(cls, data: dict | None, prefix: str = ""):
    """Build the dataclass ``cls`` from a nested dict, validating every key and value (errors name
    the dotted key, ``prefix`` + field name)."""
    data = {} if data is None else data
    if not isinstance(data, dict):
        raise ParamError(f"{prefix.rstrip('.') or 'scene'}: expected a table of parameters, got {data!r}")
    hints = _hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls)}
    unknown = [k for k in data if k not in fields]
    if unknown:
        raise ParamError(f"unknown parameter '{prefix}{unknown[0]}'; allowed keys here: "
                         f"{', '.join(prefix + k for k in fields)}")
    kwargs = {}
    for name, f in fields.items():
        if name not in data:
            continue
        ftype = hints[name]
        if dataclasses.is_dataclass(ftype):
            kwargs[name] = from_dict(ftype, data[name], f"{prefix}{name}.")
        else:
            kwargs[name] = _check_value(prefix + name, data[name], ftype, f.metadata)
    return cls(**kwargs)  # Section.__post_init__ runs validate()


def to_dict(obj) -> dict:
    """Nested plain dict of a parameter dataclass (for summary files)."""
    return dataclasses.asdict(obj)


def parse_value(text: str) -> Any:
    """A command-line value as a TOML literal (``1e-3``, ``true``, ``"E2"``); bare words stay strings."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def set_dotted(data: dict, key: str, value: Any) -> None:
    """``data['a']['b'] = value`` for ``key = 'a.b'``, creating intermediate tables."""
    parts = key.split(".")
    if not all(parts):
        raise ParamError(f"malformed parameter key {key!r}; use dotted names like fluid.viscosity")
    node = data
    for part in parts[:-1]:
        node = node.setdefault(part, {})
        if not isinstance(node, dict):
            raise ParamError(f"'{key}': '{part}' is a value, not a section")
    node[parts[-1]] = value


def describe(cls, prefix: str = "") -> list[tuple[str, str, str, str]]:
    """Rows ``(dotted key, default, unit, doc)`` for every parameter of ``cls`` (for the docs)."""
    rows = []
    hints = _hints(cls)
    default = cls()
    for f in dataclasses.fields(cls):
        if dataclasses.is_dataclass(hints[f.name]):
            rows.extend(describe(hints[f.name], f"{prefix}{f.name}."))
        else:
            doc = f.metadata.get("doc", "")
            if f.metadata.get("choices"):
                doc += " (one of " + ", ".join(map(str, f.metadata["choices"])) + ")"
            rows.append((prefix + f.name, repr(getattr(default, f.name)), f.metadata.get("unit", ""), doc))
    return rows


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


@dataclasses.dataclass(frozen=True)
class SolverParams(Section):
    """Nonlinear and linear solver settings."""

    linear: str = param("auto", "linear solver for the Newton systems ('auto': with particles direct, in 3D "
                        "multigrid above 150 000 unknowns (50 000 without PARDISO); without particles "
                        "multigrid above 20 000 unknowns in 2D / 15 000 in 3D (300 000 with PARDISO))",
                        choices=("auto", "direct", "multigrid"))
    linear_rtol: float = param(1e-8, "relative residual per linear solve (multigrid: its stopping "
                               "rule; direct with PARDISO: its refinement target in Newton steps)",
                               positive=True, maximum=0.1)
    mg_cycle: str = param("V", "multigrid cycle", choices=("V", "W", "F"))
    mg_smoother: str = param("auto", "multigrid smoother ('auto': vanka-factored, local factors stored; "
                             "vanka-full stores none and factorises in every sweep)",
                             choices=("auto", "vanka-full", "vanka-factored", "vanka-diagonal"))
    mg_coarse_obstacle: str = param("nodes", "how coarse multigrid levels see particles: their own nodes "
                                    "inside them, or Galerkin rows of the truncated prolongation",
                                    choices=("nodes", "galerkin"))
    mg_smoothing_steps: int = param(2, "multigrid pre- and post-smoothing sweeps", minimum=1)
    mg_krylov: str = param("fgmres", "Krylov acceleration of multigrid", choices=("fgmres", "none"))
    mg_linearisation: str = param("auto", "operator the multigrid hierarchy is built from: newton, picard "
                                  "(FGMRES applies the Newton matrix; dim times fewer velocity entries) or "
                                  "auto (picard in time steps, newton in steady solves)",
                                  choices=("auto", "newton", "picard"))
    mg_sweeps: str = param("auto", "order of the smoothing sweeps: forward, symmetric (forward and backward "
                           "in turn) or auto (forward in time steps, symmetric in steady solves)",
                           choices=("auto", "forward", "symmetric"))
    newton_rtol: float = param(1e-10, "Newton stop: residual reduction", positive=True, maximum=1.0)
    newton_atol: float = param(1e-12, "Newton stop: absolute residual", positive=True)
    newton_max_iterations: int = param(30, "Newton iteration limit per solve", minimum=1)
    newton_reuse_jacobian: bool = param(True, "keep a factorised Jacobian while it contracts the "
                                        "residual 10x per iteration (same solution, less work)")

    def linear_solver(self):
        """The configured linear solver: the name ``"direct"`` or ``"auto"`` (resolved by its user:
        the flow problem or the simulation), or a :class:`~fbmflow.solvers.MultigridSolver`."""
        if self.linear != "multigrid":
            return self.linear
        return MultigridSolver(MultigridSettings(
            cycle=self.mg_cycle, smoother=self.mg_smoother, pre_smooth=self.mg_smoothing_steps,
            post_smooth=self.mg_smoothing_steps, rtol=self.linear_rtol, krylov=self.mg_krylov,
            coarse_obstacle=self.mg_coarse_obstacle, linearisation=self.mg_linearisation,
            sweeps=self.mg_sweeps))

    def newton_settings(self) -> NewtonSettings:
        """The Newton stopping rule and Jacobian reuse of these settings."""
        return NewtonSettings(rtol=self.newton_rtol, atol=self.newton_atol,
                              max_iterations=self.newton_max_iterations,
                              reuse_jacobian=self.newton_reuse_jacobian, linear_rtol=self.linear_rtol)


@dataclasses.dataclass(frozen=True)
class SteadySolverParams(SolverParams):
    """Solver settings of a steady Newton solve: inexact Newton steps (the stopping rule is on the
    nonlinear residual, so the accuracy is Newton's; measured cost: docs/validation.md)."""

    linear_rtol: float = param(1e-2, "relative residual per linear solve (inexact Newton steps; the "
                               "Newton stop on the nonlinear residual decides the accuracy; multigrid: "
                               "at most this, tighter near the solution by Eisenstat-Walker)",
                               positive=True, maximum=0.1)
    continuation_rtol: float = param(1e-3, "Newton stop of the intermediate steady solves of a continuation "
                                     "(they only start the next one; the last solves to newton_rtol)",
                                     positive=True, maximum=1.0)


_INTEGRATORS = ("semi-implicit-euler", "trapezoidal")  # the integrators that couple with a flow
_INTEGRATOR_DOC = ("particle integrator: semi-implicit-euler (first order) or trapezoidal (second order with "
                   "time.scheme = crank-nicolson; not with hard contact)")


@dataclasses.dataclass(frozen=True)
class CouplingParams(Section):
    """Fluid–particle coupling: the scheme (:data:`fbmflow.coupling.COUPLINGS`) and the particle
    integrator."""

    scheme: str = param("implicit", "coupling: explicit (staggered), stabilised (explicit with each "
                        "particle's own stiffness implicit), newton-krylov (one Newton step on the particle "
                        "velocities, matrix-free), implicit (sub-iterated) or auto (implicit "
                        "while its stored flow responses fit 4 GB, else stabilised)",
                        choices=tuple(COUPLINGS) + ("auto",))
    tol: float = param(1e-6, "implicit coupling: estimated error of the particle velocities, relative",
                       positive=True, maximum=0.1)
    max_subiterations: int = param(20, "implicit coupling: sub-iteration limit per step (newton-krylov: "
                                   "FGMRES iteration limit)", minimum=1)
    first_rtol: float = param(1e-2, "implicit coupling: Newton's residual reduction in each step's first "
                              "flow solve, which only seeds the iteration (the step ends on a solve to "
                              "solver.newton_rtol; a value at or below that solves the first one alike)",
                              positive=True, maximum=0.5)
    flow_rtol: float = param(0.0, "explicit, stabilised and newton-krylov coupling: Newton's residual "
                             "reduction in the step's one flow solve, its linear steps asked for no more "
                             "than that (0, or a value at or below solver.newton_rtol: solver.newton_rtol)",
                             minimum=0.0, maximum=0.5)
    integrator: str = param("semi-implicit-euler", _INTEGRATOR_DOC, choices=_INTEGRATORS)
    krylov_rtol: float = param(1e-2, "newton-krylov coupling: FGMRES's residual reduction on the particles' "
                               "Newton equation (each iteration one linear solve; max_subiterations caps "
                               "them)", positive=True, maximum=0.5)
    added_mass: float = param(1.0, "stabilised and newton-krylov coupling: the added mass in each "
                              "particle's own stiffness (newton-krylov: its preconditioner), as a "
                              "multiple of a ball's potential-flow value (rho_f V for a disk, "
                              "rho_f V / 2 for a sphere); larger damps more, the steady state stays",
                              minimum=0.0)


@dataclasses.dataclass(frozen=True)
class SecondOrderCouplingParams(CouplingParams):
    """Fluid–particle coupling, second order in time with ``time.scheme = "crank-nicolson"``."""

    integrator: str = param("trapezoidal", _INTEGRATOR_DOC, choices=_INTEGRATORS)


_BOUNDARY_DOC = ("nodes: every velocity node inside a particle moves rigidly (first order in the mesh size); "
                 "sharp: the no-slip condition on the true surface (balls, boxes and cylinders)")


@dataclasses.dataclass(frozen=True)
class FictitiousBoundaryParams(Section):
    """How particles and obstacles meet the mesh (docs/method.md, "Particles as fictitious
    boundaries"), and the force estimator (:data:`fbmflow.coupling.FORCE_ESTIMATORS`)."""

    boundary: str = param("sharp", _BOUNDARY_DOC, choices=("nodes", "sharp"))
    force: str = param("volume", "hydrodynamic force: volume (-int sigma . grad alpha over the cut cells; "
                       "first order with the sharp boundary) or test-function (the momentum balance "
                       "tested with a function that is one on the particle, its gradient in the fluid "
                       "cells beyond the cut ones) or surface (the traction integrated over the true "
                       "surface; balls with the sharp boundary)", choices=tuple(FORCE_ESTIMATORS))


@dataclasses.dataclass(frozen=True)
class NodalBoundaryParams(FictitiousBoundaryParams):
    """How particles and obstacles meet the mesh; the nodal boundary by default, in the scenes
    where the sharp one is not yet the better choice (many particles in contact; fixed obstacles,
    whose drag from the cut cells converges only to first order with it, docs/method.md)."""

    boundary: str = param("nodes", _BOUNDARY_DOC, choices=("nodes", "sharp"))


@dataclasses.dataclass(frozen=True)
class RepulsionParams(Section):
    """Short-range repulsion from walls and other particles (Glowinski et al.)."""

    enabled: bool = param(True, "repulsive forces on (the flow cannot resolve the last gap)")
    range_cells: float = param(1.0, "force range in mesh cells", positive=True)
    strength: float = param(10.0, "force at contact over the particle's weight in the fluid", positive=True)

    def make(self, mesh, walls=None):
        """The :class:`~fbmflow.contact.Repulsion` for the walls of ``mesh`` (all faces, or the
        ``(axis, side)`` pairs in ``walls``); None when off. The range is counted in the
        mesh's finest cells (those of the fine zone of a graded mesh)."""
        if not self.enabled:
            return None
        from .contact import Repulsion

        return Repulsion(self.range_cells * float(max(mesh.finest_spacing)), tuple(mesh.lower),
                         tuple(mesh.upper), self.strength, None if walls is None else tuple(walls),
                         tuple(float(L) for L in mesh.periods) if any(mesh.periodic) else None)


@dataclasses.dataclass(frozen=True)
class ContactRepulsionParams(RepulsionParams):
    """Short-range repulsion, off by default in scenes with hard contact (which keeps the
    particles apart)."""

    enabled: bool = param(False, "repulsive forces on, in addition to hard contact")


@dataclasses.dataclass(frozen=True)
class ContactParams(Section):
    """Hard contact between particles and with the walls (projected Gauss–Seidel, sub-stepped)."""

    enabled: bool = param(True, "hard contact on (no overlap of particles or with the walls)")
    restitution: float = param(0.0, "coefficient of restitution (0: the fluid damps the rebound)",
                               minimum=0.0, maximum=1.0)
    friction: float = param(0.0, "Coulomb friction coefficient", nonnegative=True)
    substeps: int = param(10, "contact sub-steps per fluid step", minimum=1)
    iterations: int = param(50, "projected Gauss-Seidel sweeps per sub-step at most", minimum=1)
    broadphase: str = param("grid", "broadphase", choices=tuple(BROADPHASES))
    skin_cells: float = param(1.0, "contact distance in mesh cells: the fictitious boundary needs free "
                              "fluid nodes between surfaces", nonnegative=True)
    lubrication: bool = param(False, "lubrication correction for gaps below lubrication_range_cells")
    lubrication_range_cells: float = param(2.0, "gap in mesh cells below which the film force acts "
                                           "(the flow resolves larger gaps)", positive=True)
    lubrication_min_gap_cells: float = param(0.02, "gap in mesh cells at which the film force stops "
                                             "growing (surface roughness; below the range)", positive=True)
    lubrication_resolved_cells: float = param(0.37, "gap in mesh cells down to which the flow carries the "
                                              "film force (fitted to Brenner's exact drag)", nonnegative=True)

    def __post_init__(self):
        super().__post_init__()
        if not self.lubrication_min_gap_cells < self.lubrication_range_cells:
            raise ParamError(f"contact.lubrication_min_gap_cells = {self.lubrication_min_gap_cells} must be "
                             f"below contact.lubrication_range_cells = {self.lubrication_range_cells}")

    def make(self, mesh, viscosity: float, walls=None):
        """The :class:`~fbmflow.contact.ContactSet` with the walls of ``mesh`` (all faces, or the
        ``(axis, side)`` pairs in ``walls``); None when off. ``viscosity``: the fluid's, for the
        lubrication correction. Distances are counted in the mesh's finest cells."""
        if not self.enabled:
            return None
        from .contact import ContactSet, Lubrication, Planes

        h = float(max(mesh.finest_spacing))  # the fine zone's cells on a graded mesh
        lubrication = None
        if self.lubrication:
            lubrication = Lubrication(viscosity, self.lubrication_range_cells * h,
                                      self.lubrication_min_gap_cells * h, self.lubrication_resolved_cells * h)
        return ContactSet(Planes.box(mesh.lower, mesh.upper, walls), restitution=self.restitution,
                          friction=self.friction, iterations=self.iterations, broadphase=self.broadphase,
                          skin=self.skin_cells * h, lubrication=lubrication,
                          periods=tuple(float(L) for L in mesh.periods) if any(mesh.periodic) else None,
                          origin=tuple(mesh.lower))


@dataclasses.dataclass(frozen=True)
class WallContactParams(ContactParams):
    """Hard contact with the walls, off by default in single-particle scenes, where the repulsion
    keeps the particle off the walls. A heavy particle that reaches the wall faster than the
    repulsion can stop it (at most about ``sqrt(2 strength g' h)``, ``g'`` the reduced gravity,
    ``h`` its range) needs it;
    it advances the particle by semi-implicit Euler."""

    enabled: bool = param(False, "hard contact on: the particle stops skin_cells from the walls (for a "
                          "heavy particle the repulsion cannot stop; set coupling.integrator = "
                          "semi-implicit-euler with it)")


#: the time schemes a ``scheme`` parameter may name (:data:`fbmflow.flow.time_schemes.TIME_SCHEMES`)
SCHEMES = tuple(TIME_SCHEMES)


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
