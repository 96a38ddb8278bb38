"""Many particles: sedimentation in a closed box (2D, 3D) and a fluidised bed (2D), CGS units.

* ``sedimentation-2d``: ``n`` disks (100 by default, diameter 0.1 cm, rho_s = 2) released from
  rest on a jittered lattice in the upper half of a closed 2 x 4 cm box of fluid (rho_f = 1,
  mu = 0.1 g/(cm s)), g = 980 cm/s^2. ``particles.spacing``, ``bottom`` and ``top`` place the
  lattice (a dense packing resting on the bottom: ``spacing = 1.4``, ``bottom = 0``). Level
  ``L``: ``20 2^L x 40 2^L`` cells, ``2^L`` across a diameter.
* ``sedimentation-3d``: ``n`` spheres (20, d = 0.2 cm, rho_s = 2) released on a lattice filling a
  closed 1 x 1 x 2 cm box. Level ``L``: ``4 2^L x 4 2^L x 8 2^L`` cells, ``0.8 2^L`` across a
  diameter (a 3D direct solve per flow solve: level 1, 33 000 unknowns, is what a laptop carries).
* ``fluidized-bed-2d``: ``n`` disks (60, d = 0.1 cm, rho_s = 1.5) resting on a jittered lattice
  in the lower half of a 2 x 4 cm channel; fluid enters through the bottom at ``inflow`` cm/s
  (uniform) and leaves through the top (do-nothing); no-slip side walls. The bottom and top act
  as walls for the particles (a distributor plate and a sieve).

A count that the lattice region does not hold grows the box (``domain.grow``, on by default):
its shape and cell size stay, its size goes up in steps of half the scene's box until the
particles fit, so the lattice's volume fraction stays (``sedimentation-2d`` with 2 000 disks: a
9 x 18 cm box, 90 x 180 cells at level 0).

Hard contact (restitution 0, sub-stepped) keeps the particles apart and inside the box. The
coupling is ``auto``: implicit while its flow responses (three per disk, six per sphere) fit 4 GB,
else the stabilised scheme (one flow solve per step, none stored, so that thousands of particles
fit; :func:`~fbmflow.coupling.schemes.auto_coupling`). The plain explicit one is unstable here
(measured: at 2 cells per diameter the disks' rotation rates grow by about 3x per step from the
first steps, with alternating sign); the stabilised one is 3.6 to 12 times faster than the
implicit one and follows it within about 5 % over the first 0.2 s, but lags it over a whole
settling (docs/validation/many-particles.md).
Quantities:
``max_overlap`` (largest overlap of two particles or of a particle with a wall over all steps,
over the radius; 0 when none; per step in ``overlap``), ``min_height`` / ``max_height`` of the
centres, time series ``t`` and ``mean_velocity`` (mean vertical particle velocity, cm/s),
``final_positions``, ``box`` (its upper corner, cm), and the height of the suspension's top, the
mean centre height of the highest tenth of the particles plus a radius (cm): ``front_height``
for the settling scenes (the suspension front), ``bed_height`` for the bed.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from ..config import ParamError, Section, derive, param
from ..contact.broadphase import candidate_pairs
from ..coupling.settings import CouplingParams
from ..flow import Dirichlet, DoNothing, NoSlip
from ..mesh import StructuredMesh
from ..params import TimeParams
from ..particles import Ball, Particles
from ..solvers.settings import SolverParams
from .base import pyplot, save_figure
from .builder import CONTACT_SECTIONS, CgsFluid, Layout, ParticleScene, check_mesh_size, particle_params

log = logging.getLogger(__name__)

ManyTime = derive(TimeParams, "ManyTime", "Time stepping.", dt=0.005, scheme="backward-euler")
ManyCoupling = derive(CouplingParams, "ManyCoupling", CouplingParams.__doc__, scheme="auto", flow_rtol=1e-2)


@dataclass(frozen=True)
class ManyParticles(Section):
    """The particles."""

    count: int = param(100, "number of particles", minimum=1, maximum=10**6)
    diameter: float = param(0.1, "particle diameter", "cm", positive=True)
    density: float = param(2.0, "particle density", "g/cm^3", positive=True)
    seed: int = param(0, "seed of the random jitter of the initial lattice", minimum=0)
    spacing: float = param(2.0, "spacing of the initial lattice, in diameters (1.4: a dense packing)",
                           minimum=1.1)
    bottom: float = param(0.5, "lowest height of the initial lattice, as a fraction of the box height",
                          minimum=0.0, maximum=1.0)
    top: float = param(1.0, "highest height of the initial lattice, as a fraction of the box height",
                       minimum=0.0, maximum=1.0)

    def __post_init__(self):
        super().__post_init__()
        if not self.bottom < self.top:
            raise ParamError(f"particles.bottom = {self.bottom} must lie below particles.top = {self.top}")


@dataclass(frozen=True)
class ManyDomain(Section):
    """The box."""

    grow: bool = param(True, "grow the box (its shape and cell size kept, in steps of half its size) "
                       "until the initial lattice holds particles.count; false: refuse such counts")


@dataclass(frozen=True)
class BedInflow(Section):
    """Inflow through the bottom."""

    velocity: float = param(1.0, "uniform inflow velocity", "cm/s", positive=True)


SphereParticles = derive(ManyParticles, "SphereParticles", "The particles.", count=20, diameter=0.2,
                         bottom=0.0)
BedParticles = derive(ManyParticles, "BedParticles", "The particles.", count=60, density=1.5, bottom=0.0,
                      top=0.5)
ManySolver = derive(
    SolverParams, "ManySolver", "Nonlinear and linear solver settings: Newton stops at a 1e-6 residual "
    "reduction, each linear step at 1e-3 (the mean settling velocity the same to 6e-7 of its largest "
    "value as at 1e-10 / 1e-8; docs/validation/many-particles.md).",
    newton_rtol=param(1e-6, "Newton stop: residual reduction", positive=True, maximum=1.0),
    linear_rtol=param(1e-3, "relative residual per linear solve (multigrid: its stopping rule; Newton's "
                      "stopping rule decides the accuracy)", positive=True, maximum=0.1))
Sedimentation2DParams = particle_params("Sedimentation2DParams", "Parameters of ``sedimentation-2d``.",
                                        fluid=CgsFluid, particles=ManyParticles, domain=ManyDomain,
                                        time=ManyTime, coupling=ManyCoupling, solver=ManySolver,
                                        **CONTACT_SECTIONS)
Sedimentation3DParams = particle_params("Sedimentation3DParams", "Parameters of ``sedimentation-3d``.",
                                        fluid=CgsFluid, particles=SphereParticles, domain=ManyDomain,
                                        time=ManyTime, coupling=ManyCoupling, solver=ManySolver,
                                        **CONTACT_SECTIONS)
FluidizedBedParams = particle_params("FluidizedBedParams", "Parameters of ``fluidized-bed-2d``.",
                                     fluid=CgsFluid, particles=BedParticles, domain=ManyDomain,
                                     inflow=BedInflow,
                                     time=ManyTime, coupling=ManyCoupling, solver=ManySolver,
                                     **CONTACT_SECTIONS)


def lattice(count: int, d: float, lower: np.ndarray, upper: np.ndarray, seed: int,
            spacing: float = 2.0) -> np.ndarray:
    """``count`` centres (count, dim) on a lattice of spacing ``spacing d`` filling
    ``[lower, upper]`` row by row from ``lower`` along the first axes, at least ``spacing d / 2``
    from its sides, each jittered by up to ``0.15 (spacing - 1) d`` (the gaps between neighbours
    stay above ``0.7 (spacing - 1) d``); ParamError when they do not fit."""
    dim = lower.size
    per_axis, margin = _lattice_rows(d, lower, upper, spacing)
    spacing = spacing * d
    if np.prod(per_axis) < count:
        raise ParamError(f"{count} particles of diameter {d} cm do not fit the region {lower.tolist()} - "
                         f"{upper.tolist()} (room for {int(np.prod(per_axis))}); reduce particles.count or "
                         "particles.diameter, or set domain.grow = true")
    k = np.arange(count)
    idx = np.empty((count, dim), dtype=int)
    for a in range(dim):  # first axis fastest
        idx[:, a] = k % per_axis[a]
        k = k // per_axis[a]
    rng = np.random.default_rng(seed)
    jitter = 0.15 * (spacing - d)
    return lower + margin + idx * spacing + rng.uniform(-jitter, jitter, (count, dim))


def _lattice_rows(d: float, lower: np.ndarray, upper: np.ndarray, spacing: float) -> tuple[np.ndarray, float]:
    """Particles per axis (dim,) of :func:`lattice` in ``[lower, upper]``, and the margin from its
    sides to the first centres."""
    margin = max(spacing / 2, 1.0) * d  # half a diameter of fluid to the sides at spacing 2
    rows = np.floor((upper - lower - 2.0 * margin) / (spacing * d)).astype(int) + 1
    return np.maximum(rows, 0), margin


def max_overlap(p: Particles, lower, upper) -> float:
    """Largest overlap of two balls or of a ball with the box ``[lower, upper]``, over the
    radius (0 when none)."""
    R = p.bounding_radius
    pairs = candidate_pairs(p.position, R)
    worst = 0.0
    if len(pairs):
        i, j = pairs[:, 0], pairs[:, 1]
        dist = np.linalg.norm(p.position[i] - p.position[j], axis=1)
        worst = max(worst, float(np.max((R[i] + R[j] - dist) / np.minimum(R[i], R[j]))))
    wall = np.maximum(R[:, None] - (p.position - np.asarray(lower)),
                      R[:, None] - (np.asarray(upper) - p.position))
    return max(worst, float(np.max(wall / R[:, None])), 0.0)


class _ManyParticles(ParticleScene):
    """Shared set-up and loop of the many-particle scenes."""

    dim = 2
    box = (2.0, 4.0)
    cells_level0 = (20, 40)
    height_name = "front_height"  # the series of the suspension's top (_top)
    default_level = 2
    max_level = 5

    def scale(self, params) -> float:
        """The box's size over the scene's ``box``: 1, or with ``domain.grow`` the smallest of
        1.5, 2, 2.5, ... whose lattice region holds ``particles.count``."""
        pp, scale = params.particles, 1.0

        def room(scale: float) -> int:
            return int(np.prod(_lattice_rows(pp.diameter, *self._region(params, scale), pp.spacing)[0]))

        while params.domain.grow and room(scale) < pp.count:
            scale += 0.5
        return scale

    def _region(self, params, scale: float) -> tuple[np.ndarray, np.ndarray]:
        """Corners of the initial lattice's region in the box of size ``scale`` [cm]."""
        upper = scale * np.array(self.box, dtype=float)
        lower = np.zeros(self.dim)
        lower[-1], upper[-1] = params.particles.bottom * upper[-1], params.particles.top * upper[-1]
        return lower, upper

    def mesh(self, level: int, scale: float = 1.0) -> StructuredMesh:
        """The box of size ``scale`` (a multiple of 1/2) with the level's cells (refused before it
        is made where its flow cannot fit the machine)."""
        cells = tuple(int(round(n * scale)) * 2**level for n in self.cells_level0)
        check_mesh_size(cells, None, self.dim,
                        f"the box grown {scale:g} times (particles.count) at level {level}")
        return StructuredMesh.box(cells, upper=tuple(scale * b for b in self.box))

    def boundary(self, mesh, params) -> dict | None:
        """The flow's boundary conditions (None: no-slip walls all round)."""
        return None

    def initial_positions(self, params) -> np.ndarray:
        pp = params.particles
        return lattice(pp.count, pp.diameter, *self._region(params, self.scale(params)), pp.seed, pp.spacing)

    def layout(self, params, level: int) -> Layout:
        pp = params.particles
        mesh = self.mesh(level, self.scale(params))
        self._check_spacing(params, level, float(max(mesh.spacing)))
        particles = Particles.at_rest([Ball(pp.diameter / 2, self.dim)] * pp.count, pp.density,
                                      self.initial_positions(params))
        return Layout(mesh, particles, params.fluid, self.boundary(mesh, params))

    @staticmethod
    def _check_spacing(params, level: int, cell: float) -> None:
        """Warn when the lattice's gaps (at least ``0.7 (spacing - 1) d``) lie below the contact
        skin: contact pushes such particles apart in the first steps, and a dense packing bursts
        (measured: spacing 1.2 at 2 cells/d, skin one cell = 0.5 d: overlaps of 0.69 r in the
        second step, the packing 0.4 cm higher)."""
        skin = params.contact.skin_cells * cell if params.contact.enabled else 0.0
        pp = params.particles
        gap = 0.7 * (pp.spacing - 1.0) * pp.diameter
        if gap < skin:
            need = np.ceil((1.0 + skin / (0.7 * pp.diameter)) * 100) / 100
            log.warning("particles.spacing = %g leaves gaps down to %.3g cm, below the contact skin of %.3g "
                        "cm (%g cells at level %d): contact pushes such particles apart in the first steps; "
                        "use particles.spacing >= %g, a finer level or a smaller contact.skin_cells",
                        pp.spacing, gap, skin, params.contact.skin_cells, level, need)

    def observe(self, params, sim) -> dict:
        p, mesh = sim.particles, sim.mesh
        row = {"t": sim.t, "mean_velocity": float(p.velocity[:, -1].mean()),
               "overlap": max_overlap(p, mesh.lower, mesh.upper),
               "min_height": float(p.position[:, -1].min()), "max_height": float(p.position[:, -1].max())}
        row[self.height_name] = self._top(p.position, params.particles.diameter)
        return row

    def quantities(self, params, series: dict, sim) -> dict:
        q = {"max_overlap": max(series["overlap"]), "min_height": min(series["min_height"]),
             "max_height": max(series["max_height"]),
             "cells_per_diameter": float(params.particles.diameter / sim.mesh.spacing[0]),
             "box": [float(b) for b in sim.mesh.upper],
             "t": series["t"], "mean_velocity": series["mean_velocity"], "overlap": series["overlap"],
             "final_positions": sim.particles.position.tolist(), self.height_name: series[self.height_name]}
        return q

    @staticmethod
    def _top(X: np.ndarray, d: float) -> float:
        """Mean centre height of the highest tenth of the particles plus a radius."""
        z = np.sort(X[:, -1])
        return float(z[-max(1, len(z) // 10):].mean() + d / 2)

    def plot(self, summary: dict, path) -> bool:
        plt = pyplot()

        q = summary["quantities"]
        box = q.get("box", self.box)
        wide = min(1.5, max(0.5, box[0] / box[-1]))  # the positions' panel keeps the box's shape
        fig, ax = plt.subplots(1, 3, figsize=(9.0 + 4.5 * wide, 4.2), width_ratios=[1.0, 1.0, wide])
        ax[0].plot(q["t"], q["mean_velocity"])
        ax[0].set_ylabel("mean vertical velocity [cm/s]")
        ax[1].plot(q["t"], q[self.height_name])
        ax[1].set_ylabel(("bed height" if self.height_name == "bed_height" else "suspension front") + " [cm]")
        for a in ax[:2]:
            a.set_xlabel("t [s]")
            a.grid(alpha=0.3)
        X = np.array(q["final_positions"])
        d = summary["params"]["particles"]["diameter"]
        last = ax[-1]
        last.set_aspect("equal")
        last.set_xlim(0, box[0])
        last.set_ylim(0, box[-1])
        for x in X:
            last.add_patch(plt.Circle((x[0], x[-1]), d / 2, fc="C0", ec="k", lw=0.3))
        last.set_title(f"t = {q['t'][-1]:.3g} s" + ("\n(projected on x-z)" if X.shape[1] == 3 else ""))
        fig.suptitle(f"{summary['scene']}, level {summary['level']}, max overlap {q['max_overlap']:.2g} r")
        return save_figure(fig, path)


class Sedimentation2D(_ManyParticles):
    name = "sedimentation-2d"
    description = "100 disks settling in a closed 2 x 4 cm box (hard contact)"
    Params = Sedimentation2DParams


class Sedimentation3D(_ManyParticles):
    name = "sedimentation-3d"
    description = "20 spheres settling in a closed 1 x 1 x 2 cm box (hard contact)"
    Params = Sedimentation3DParams
    dim = 3
    box = (1.0, 1.0, 2.0)
    cells_level0 = (4, 4, 8)
    default_level = 1
    max_level = 3


class FluidizedBed2D(_ManyParticles):
    name = "fluidized-bed-2d"
    description = "60 disks fluidised by inflow through the bottom of a 2 x 4 cm channel"
    Params = FluidizedBedParams
    height_name = "bed_height"

    def boundary(self, mesh, params) -> dict:
        bc = {t: NoSlip() for t in mesh.tags}
        bc["ymin"] = Dirichlet((0.0, params.inflow.velocity))
        bc["ymax"] = DoNothing()
        return bc
