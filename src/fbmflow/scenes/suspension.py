"""Periodic suspensions: hindered settling of disks (2D) or spheres (3D) in a periodic box, CGS units.

``count`` particles (diameter 0.1 cm, rho_s = 1.5 g/cm^3) are placed at random, without overlap,
in a box periodic along every axis, sized so that they fill ``particles.volume_fraction`` of it
(the box has a whole number of cells; the fraction it gives is reported). Fluid rho_f = 1 g/cm^3,
mu = 0.2 g/(cm s), g = 980 cm/s^2: a single sphere settles at about 1.2 cm/s (Re about 0.6).

Gravity points along a periodic axis, so a mean pressure gradient carries the particles' weight in
the fluid (:func:`~fbmflow.coupling.placement.periodic_drive`): the suspension as a whole does not
accelerate and its mean volume flux stays zero. The particles cross the periodic sides; repulsion
(nearest image) keeps them apart, or hard contact (``contact.enabled``, off by default), which
acts across the periodic sides too.

Level ``L``: ``2^L`` cells per diameter (uniform, square / cubic cells).

The settling velocity is the particles' mean vertical velocity relative to the mixture, whose
volume flux (the volume average of the velocity over the box, particles included) should stay
zero; its drift is reported (``mixture_velocity``) and comes from the force estimator's error
(the momentum the particles get from the estimated force is not exactly what the fluid loses).

Quantities: time series ``t``, ``settling_velocity`` (cm/s, positive downwards),
``mixture_velocity`` (vertical, cm/s) and ``overlap`` (largest overlap of two particles over the
radius, nearest images); ``mean_settling_velocity`` (average over the second half of the run),
``volume_fraction`` (of the box as built), ``cells_per_diameter``, ``box``, ``max_overlap``,
``final_positions``, and the references:

* ``array_velocity``: the settling velocity of the square or simple cubic array at the same
  fraction (exact for one particle per box; an ordered suspension settles slower than a random
  one), Stokes flow, from Sangani & Acrivos (1982),
  ``F / (4 pi mu U) = 1 / (-ln(c) / 2 - 0.738 + c - 0.887 c^2 + 2.038 c^3)`` for disks and
  ``F / (3 pi mu d U) = 1 / (1 - 1.7601 c^(1/3) + c - 1.5593 c^2 + 3.9799 c^(8/3) - 3.0734 c^(10/3))``
  for spheres, ``F`` the particle's weight in the fluid and ``U`` the settling velocity relative
  to the mixture (the superficial velocity of the array);
* spheres: ``terminal_velocity`` of one sphere in unbounded fluid (Schiller & Naumann's drag,
  ``C_D = 24 / Re (1 + 0.15 Re^0.687)``), the Richardson–Zaki exponent ``rz_exponent`` of Garside
  & Al-Dibouni (1977), ``n = (5.1 + 0.27 Re^0.9) / (1 + 0.1 Re^0.9)`` at that Reynolds number, and
  ``richardson_zaki = V_t (1 - phi)^n``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..config import ParamError, Section, derive, param
from ..contact.settings import ContactParams
from ..coupling.settings import FictitiousBoundaryParams
from ..mesh import StructuredMesh
from ..params import TimeParams
from ..particles import Ball, Particles
from .base import pyplot, save_figure
from .builder import CgsFluid, Layout, ParticleScene, check_mesh_size, particle_params

SuspensionFluid = derive(CgsFluid, "SuspensionFluid", "Fluid and gravity (CGS units).", viscosity=0.2)
SuspensionBoundary = derive(FictitiousBoundaryParams, "SuspensionBoundary",
                            "Fictitious boundary of the balls: sharp, with the surface force (the most "
                            "accurate for balls).",
                            force="surface")
SuspensionTime = derive(TimeParams, "SuspensionTime", "Time stepping.", dt=0.01, t_end=1.0,
                        scheme="backward-euler")
SphereSuspensionTime = derive(SuspensionTime, "SphereSuspensionTime", "Time stepping.", t_end=0.5)


@dataclass(frozen=True)
class SuspensionParticles(Section):
    """The particles."""

    count: int = param(16, "number of particles", minimum=1, maximum=10**6)
    volume_fraction: float = param(0.1, "volume (2D: area) fraction of the particles; sets the box size",
                                   positive=True, maximum=0.4)
    diameter: float = param(0.1, "particle diameter", "cm", positive=True)
    density: float = param(1.5, "particle density", "g/cm^3", positive=True)
    seed: int = param(0, "seed of the random placement", minimum=0)
    min_gap: float = param(0.1, "smallest gap between particles at the start, in diameters", minimum=0.0)
    frozen: bool = param(False, "hold the particles in place while their velocities and the flow evolve: "
                                "the settling of one frozen configuration (hindered-settling ensembles)")


SphereSuspension = derive(SuspensionParticles, "SphereSuspension", "The particles.", count=8)
SuspensionContact = derive(ContactParams, "SuspensionContact",
                           "Hard contact between the particles, through the periodic sides (off by default: "
                           "repulsion keeps them apart).",
                           enabled=param(False, "hard contact on (no overlap, nearest images)"))
Suspension2DParams = particle_params("Suspension2DParams", "Parameters of ``suspension-2d``.",
                                     fluid=SuspensionFluid, particles=SuspensionParticles,
                                     time=SuspensionTime, fbm=SuspensionBoundary, contact=SuspensionContact)
Suspension3DParams = particle_params("Suspension3DParams", "Parameters of ``suspension-3d``.",
                                     fluid=SuspensionFluid, particles=SphereSuspension,
                                     time=SphereSuspensionTime, fbm=SuspensionBoundary,
                                     contact=SuspensionContact)


def random_positions(count: int, d: float, box: np.ndarray, gap: float, seed: int,
                     tries: int = 1000) -> np.ndarray:
    """``count`` centres (count, dim) placed one after another at uniformly random points of the
    periodic box ``[0, box]``, each at least ``d + gap`` from the others (nearest images); ParamError
    when a particle finds no place in ``tries`` attempts."""
    rng = np.random.default_rng(seed)
    X = np.empty((count, box.size))
    for k in range(count):  # set-up only: one particle at a time, each against all placed
        for _ in range(tries):
            x = rng.uniform(0.0, box)
            diff = X[:k] - x
            diff -= box * np.round(diff / box)
            if k == 0 or np.min(np.einsum("ij,ij->i", diff, diff)) >= (d + gap) ** 2:
                X[k] = x
                break
        else:
            raise ParamError(f"no room for particle {k} of {count} at gaps of {gap / d:g} diameters: lower "
                             "particles.volume_fraction or particles.min_gap")
    return X


def nearest_overlap(X: np.ndarray, radius: float, box: np.ndarray) -> float:
    """Largest overlap of two balls of ``radius`` at ``X (n, dim)`` in the periodic ``box``, over
    the radius (0 when none)."""
    if len(X) < 2:
        return 0.0
    from scipy.spatial import cKDTree

    tree = cKDTree(np.mod(X, box), boxsize=box)
    dist = tree.sparse_distance_matrix(tree, 2.0 * radius, output_type="ndarray")
    dist = dist[dist["i"] < dist["j"]]["v"]
    return float(max(0.0, (2.0 * radius - dist.min()) / radius)) if dist.size else 0.0


def sangani_acrivos_velocity(dim: int, c: float, weight: float, mu: float, d: float) -> float:
    """Settling velocity relative to the mixture of a square (2D) or simple cubic (3D) array at
    volume fraction ``c`` whose particles weigh ``weight`` in the fluid (2D: per unit length),
    Stokes flow (Sangani & Acrivos 1982; see the module docstring)."""
    if dim == 2:
        return weight / (4.0 * math.pi * mu) * (-0.5 * math.log(c) - 0.738 + c - 0.887 * c**2 + 2.038 * c**3)
    inv_K = 1 - 1.7601 * c ** (1 / 3) + c - 1.5593 * c**2 + 3.9799 * c ** (8 / 3) - 3.0734 * c ** (10 / 3)
    return weight / (3.0 * math.pi * mu * d) * inv_K


def terminal_velocity(d: float, rho_s: float, rho_f: float, mu: float, g: float) -> tuple[float, float]:
    """Terminal velocity [cm/s] (downwards positive: a light sphere's is negative, it rises) and
    Reynolds number (of the speed) of one sphere in unbounded fluid with Schiller & Naumann's drag
    ``C_D = 24 / Re (1 + 0.15 Re^0.687)`` (fixed-point iteration from Stokes' law)."""
    stokes = (rho_s - rho_f) * g * d**2 / (18.0 * mu)
    speed = abs(stokes)
    for _ in range(200):
        re = rho_f * speed * d / mu
        speed = abs(stokes) / (1.0 + 0.15 * re**0.687)
    return math.copysign(speed, stokes), rho_f * speed * d / mu


def garside_al_dibouni(re: float) -> float:
    """Richardson–Zaki exponent ``n`` at the terminal Reynolds number ``re`` (Garside & Al-Dibouni
    1977)."""
    return (5.1 + 0.27 * re**0.9) / (1.0 + 0.1 * re**0.9)


class _Suspension(ParticleScene):
    dim = 2
    default_level = 2
    max_level = 5

    def box(self, params, level: int) -> tuple[int, float]:
        """Cells per side (at least 4) and the side [cm] of the periodic box that holds ``count``
        particles at about ``volume_fraction`` (the nearest whole number of cells)."""
        pp = params.particles
        h = pp.diameter / 2**level
        volume = Ball(pp.diameter / 2, self.dim).volume
        side = (pp.count * volume / pp.volume_fraction) ** (1.0 / self.dim)
        n = max(4, int(round(side / h)))
        return n, n * h

    def layout(self, params, level: int) -> Layout:
        pp = params.particles
        n, side = self.box(params, level)
        check_mesh_size((n,) * self.dim, (True,) * self.dim, self.dim,
                        f"particles.volume_fraction = {pp.volume_fraction:g} with {pp.count} particles")
        mesh = StructuredMesh.box((n,) * self.dim, upper=(side,) * self.dim, periodic=(True,) * self.dim)
        X = random_positions(pp.count, pp.diameter, np.full(self.dim, side), pp.min_gap * pp.diameter,
                             pp.seed)
        particles = Particles.at_rest([Ball(pp.diameter / 2, self.dim)] * pp.count, pp.density, X)
        return Layout(mesh, particles, params.fluid)

    def observe(self, params, sim) -> dict:
        mixture = float(sim.mixture_velocity()[-1])
        p, mesh = sim.particles, sim.mesh
        return {"t": sim.t, "settling_velocity": mixture - float(p.velocity[:, -1].mean()),
                "mixture_velocity": mixture,
                "overlap": nearest_overlap(p.position, params.particles.diameter / 2, mesh.periods)}

    def quantities(self, params, series: dict, sim) -> dict:
        pp, fl, mesh = params.particles, params.fluid, sim.mesh
        t = np.array(series["t"])
        late = t >= 0.5 * t[-1]
        volume = Ball(pp.diameter / 2, self.dim).volume
        phi = pp.count * volume / float(np.prod(mesh.periods))
        q = {"mean_settling_velocity": float(np.mean(np.array(series["settling_velocity"])[late])),
             "volume_fraction": phi, "cells_per_diameter": float(pp.diameter / mesh.spacing[0]),
             "box": [float(b) for b in mesh.periods], "max_overlap": max(series["overlap"]),
             "t": series["t"], "settling_velocity": series["settling_velocity"],
             "mixture_velocity": series["mixture_velocity"], "overlap": series["overlap"],
             "final_positions": sim.particles.position.tolist()}
        weight = (pp.density - fl.density) * volume * fl.gravity
        q["array_velocity"] = sangani_acrivos_velocity(self.dim, phi, weight, fl.viscosity, pp.diameter)
        if self.dim == 3:
            vt, re = terminal_velocity(pp.diameter, pp.density, fl.density, fl.viscosity, fl.gravity)
            n = garside_al_dibouni(re)
            q.update(terminal_velocity=vt, terminal_reynolds=re, rz_exponent=n,
                     richardson_zaki=vt * (1.0 - phi) ** n)
        return q

    def plot(self, summary: dict, path) -> bool:
        plt = pyplot()
        q = summary["quantities"]
        fig, ax = plt.subplots(1, 2, figsize=(10, 4.2))
        ax[0].plot(q["t"], q["settling_velocity"], label="particles relative to the mixture")
        ax[0].plot(q["t"], q["mixture_velocity"], lw=0.8, label="mixture (volume flux)")
        for key, label, style in (("richardson_zaki", "Richardson-Zaki", "--"),
                                  ("array_velocity", "periodic array (Sangani & Acrivos)", ":")):
            if key in q:
                ax[0].axhline(q[key], color="k", ls=style, lw=1, label=label)
        ax[0].set_xlabel("t [s]")
        ax[0].set_ylabel("settling velocity [cm/s]")
        ax[0].grid(alpha=0.3)
        ax[0].legend(fontsize=8)
        X, box = np.array(q["final_positions"]), q["box"]
        d = summary["params"]["particles"]["diameter"]
        last = ax[1]
        last.set_aspect("equal")
        last.set_xlim(0, box[0])
        last.set_ylim(0, box[-1])
        for x in X:
            for sx in (-box[0], 0.0, box[0]):  # the images that show across the periodic sides
                for sz in (-box[-1], 0.0, box[-1]):
                    last.add_patch(plt.Circle((x[0] + sx, x[-1] + sz), d / 2, fc="C0", ec="k", lw=0.3))
        last.set_title(f"t = {q['t'][-1]:.3g} s" + (" (projected on x-z)" if X.shape[1] == 3 else ""))
        fig.suptitle(f"{summary['scene']}, level {summary['level']}, volume fraction "
                     f"{q['volume_fraction']:.3g}, mean settling velocity "
                     f"{q['mean_settling_velocity']:.3g} cm/s")
        return save_figure(fig, path)


class Suspension2D(_Suspension):
    name = "suspension-2d"
    description = "disks settling in a doubly periodic box (hindered settling, no mean flux)"
    Params = Suspension2DParams


class Suspension3D(_Suspension):
    name = "suspension-3d"
    description = "spheres settling in a triply periodic box, against Richardson-Zaki"
    Params = Suspension3DParams
    dim = 3
    default_level = 2
    max_level = 4
