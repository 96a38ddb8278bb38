"""Glowinski et al.'s 2D free fall of a disk in a closed channel (CGS units).

Disk of diameter 0.25 cm, rho_s = 1.25 g/cm^3, in a closed 2 x 6 cm box of fluid with rho_f = 1,
mu = 0.1 g/(cm s), g = 980 cm/s^2, released at rest at (1, 4) cm. Level ``L`` has cells of
``h = 0.25 / 2^L`` cm, ``2^L`` across the diameter, along the disk's path: by default
(``domain.mesh = "graded"``) a rectilinear mesh, uniform within one diameter of the vertical line
through the release point and from the bottom to one diameter above it, its cells growing by at
most 1.3 per cell towards the side walls and the lid (about a third of the cells); with
``domain.mesh = "uniform"`` the ``8 2^L x 24 2^L`` cells of size h everywhere. Implicit
(sub-iterated) fluid–particle coupling by default; ``coupling.scheme = "explicit"`` for the
staggered one. The sharp fictitious boundary by default (``fbm.boundary = "nodes"`` for the nodal
one, which needs about eight times finer cells for the same accuracy), with Crank–Nicolson and the
trapezoidal particle integrator (the settling velocity's plateau moves -0.80 / -0.34 % from dt 4 to 2
to 1 ms at 4 cells per diameter; with backward Euler and semi-implicit Euler the peak at dt 2 ms
is about 1 % high, docs/method.md, "The pressure's time level").

References: Glowinski et al. (2001) and Wan & Turek (2006) report Re_max about 17.3; Koblitz et
al. (2017), with a body-fitted overset grid, about 14.0 (their curve ships in
:mod:`fbmflow.scenes.data.koblitz2017` and is drawn in the plot). fbmflow converges towards the
latter (benchmarks/results/glowinski.md, and glowinski-nodes.md for the nodal boundary).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..config import ParamError, Section, derive, param
from ..contact.settings import WallContactParams
from ..coupling.settings import SecondOrderCouplingParams
from ..mesh import StructuredMesh, graded_axis
from ..params import SCHEMES
from ..particles import Ball, Particles
from ..particles.drag import terminal_velocity
from .base import pyplot, save_figure
from .builder import CgsFluid, DomainParams, Layout, MeshTime, ParticleScene, particle_params
from .data import koblitz2017


@dataclass(frozen=True)
class GlowinskiParticle(Section):
    """The disk."""

    diameter: float = param(0.25, "disk diameter", "cm", positive=True)
    density: float = param(1.25, "disk density", "g/cm^3", positive=True)
    x: float = param(1.0, "initial centre x", "cm")
    y: float = param(4.0, "initial centre y", "cm")


GlowinskiTime = derive(MeshTime, "GlowinskiTime", "Time stepping (``dt = 0``: ``courant h / U`` with U the "
                       "disk's terminal velocity by White's cylinder drag, 6.59 cm/s, so that each level "
                       "halves it).",
                       courant=param(0.1, "Courant number U dt / h of the time step when dt = 0 (U: the "
                                     "disk's terminal velocity, h: its cell); the peak moves -0.71 / -0.55 % "
                                     "from Courant 0.4 to 0.2 to 0.1 at level 2 "
                                     "(benchmarks/results/glowinski.md)", positive=True, maximum=10.0),
                       t_end=param(0.65, "final time (the settling velocity peaks between about 0.45 and "
                                   "0.6 s; the disk lands at about 0.75 s)", "s", positive=True),
                       scheme=param("crank-nicolson", "implicit time scheme (crank-nicolson with the "
                                    "trapezoidal particle integrator: second order)", choices=SCHEMES))


def _inside_the_box(params) -> None:
    r = params.particle.diameter / 2
    if not (r < params.particle.x < 2.0 - r and r < params.particle.y < 6.0 - r):
        raise ParamError(f"particle at ({params.particle.x}, {params.particle.y}) with radius {r} is not "
                         "inside the 2 x 6 cm box; move it inside")


GlowinskiParams = particle_params("GlowinskiParams", "Parameters of ``glowinski-free-fall``.",
                                  _inside_the_box, fluid=CgsFluid, particle=GlowinskiParticle,
                                  domain=DomainParams, time=GlowinskiTime, coupling=SecondOrderCouplingParams,
                                  contact=WallContactParams)


class GlowinskiFreeFall(ParticleScene):
    name = "glowinski-free-fall"
    description = "2D disk settling in a closed 2 x 6 cm channel (Glowinski et al.)"
    Params = GlowinskiParams
    default_level = 2
    max_level = 5

    @staticmethod
    def mesh(level: int, kind: str = "graded",
             particle: GlowinskiParticle = GlowinskiParticle()) -> StructuredMesh:
        """The 2 x 6 cm box with cells of ``h = 0.25 cm / 2^level`` along the disk's path
        (``kind = "graded"``: only there, within one diameter of ``x = particle.x`` and below one
        diameter above ``particle.y``)."""
        n, h, d = 2**level, 0.25 / 2**level, particle.diameter
        if kind == "uniform":
            return StructuredMesh.box((8 * n, 24 * n), upper=(2.0, 6.0))
        fine_x = (max(particle.x - d, 0.0), min(particle.x + d, 2.0))
        top = min(particle.y + d, 6.0)
        return StructuredMesh.rectilinear([graded_axis(0.0, 2.0, fine_x, h),
                                           graded_axis(0.0, 6.0, (0.0, top), h)])

    def velocity_scale(self, params: GlowinskiParams) -> float:
        """The disk's terminal velocity in unbounded fluid (White's cylinder drag,
        :func:`~fbmflow.particles.drag.terminal_velocity`): 6.59 cm/s, 18 % above the channel's."""
        f, pp = params.fluid, params.particle
        return terminal_velocity(pp.diameter, pp.density, f.density, f.viscosity, f.gravity, 2)

    def layout(self, params: GlowinskiParams, level: int) -> Layout:
        pp = params.particle
        particles = Particles.at_rest([Ball(pp.diameter / 2, 2)], pp.density, [[pp.x, pp.y]])
        return Layout(self.mesh(level, params.domain.mesh, pp), particles, params.fluid)

    def observe(self, params: GlowinskiParams, sim) -> dict:
        p = sim.particles
        return {"t": sim.t, "y": float(p.position[0, 1]), "v": float(p.velocity[0, 1])}

    def quantities(self, params: GlowinskiParams, series: dict, sim) -> dict:
        f, pp = params.fluid, params.particle
        speed = np.abs(np.array(series["v"]))
        return {"max_settling_velocity": float(speed.max()),
                "max_reynolds_number": float(f.density * speed.max() * pp.diameter / f.viscosity),
                "final_position": sim.particles.position[0].tolist(), **series}

    def plot(self, summary: dict, path) -> bool:
        plt = pyplot()

        q, f = summary["quantities"], summary["params"]["fluid"]
        d = summary["params"]["particle"]["diameter"]
        fig, ax = plt.subplots(1, 2, figsize=(10, 4))
        ax[0].plot(q["t"], q["y"])
        ax[0].set_ylabel("y [cm]")
        ax[1].plot(q["t"], -np.array(q["v"]), label="fbmflow")
        ax[0].plot(*koblitz2017.HEIGHT.T, "k.", ms=3, label="Koblitz et al. 2017 (overset grid)")
        ax[1].plot(*koblitz2017.VELOCITY.T, "k.", ms=3, label="Koblitz et al. 2017 (overset grid)")
        ax[1].axhline(17.3 * f["viscosity"] / (f["density"] * d), ls=":", c="k",
                      label="Re = 17.3 (Glowinski et al. 2001)")
        ax[0].legend()
        ax[1].set_ylabel("settling velocity [cm/s]")
        ax[1].legend()
        for a in ax:
            a.set_xlabel("t [s]")
            a.grid(alpha=0.3)
        fig.suptitle(f"glowinski-free-fall, level {summary['level']}: Re_max {q['max_reynolds_number']:.2f}")
        return save_figure(fig, path)
