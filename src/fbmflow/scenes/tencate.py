"""ten Cate et al. (2002): a sphere settling in a closed box, cases E1-E4 (SI units).

Box 100 x 100 x 160 mm, sphere d = 15 mm, rho_s = 1120 kg/m^3, centre released from rest
127.5 mm above the bottom, g = 9.81 m/s^2; the case sets the silicone oil (rho_f, mu):
E1 (970, 0.373), E2 (965, 0.212), E3 (962, 0.113), E4 (960, 0.058). By default the quarter box
``[50, 100] x [50, 100] x [0, 160] mm`` with slip (mirror) planes x = y = 50 mm through the
sphere's centre; forces are those of the whole sphere. Level ``L`` has cells of
``h = 5 / 2^L`` mm, ``3 2^L`` across the diameter, along the sphere's path: by default
(``domain.mesh = "graded"``) a rectilinear mesh, uniform within one diameter of the vertical axis
through the sphere's centre and from the bottom to one diameter above the release height, its
cells growing by at most 1.3 per cell towards the side walls and the lid (about a third of the
unknowns of the uniform mesh, ``domain.mesh = "uniform"``). The defaults are the sharp
fictitious boundary (``fbm.boundary``), Crank–Nicolson with the trapezoidal particle integrator
(second order in time for a fixed boundary; with the sphere's surface crossing the mesh the
peak's change between dt 0.02 / 0.01 / 0.005 s at E4 level 0 is -1.3 / -0.16 % with the
pressure's force taken half a step back, against +2.3 / +1.5 % without, see docs/method.md,
"The pressure's time level") and the implicit coupling; the nodal boundary with backward Euler and
semi-implicit Euler, the earlier defaults, settled 6-8 % too fast at level 1 (E4).

The run stops at ``time.t_end`` (by default the time the experiment reached the bottom) or when
the gap between sphere and bottom falls below ``stop_gap`` diameters. Contact with the walls
(``contact.enabled``, with ``coupling.integrator = "semi-implicit-euler"``) is off by default; it
carries the lubrication correction (``contact.lubrication``; its effect on the approach to the
bottom: docs/validation/lubrication.md).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..config import ParamError, Section, derive, param
from ..contact.settings import WallContactParams
from ..coupling.settings import SecondOrderCouplingParams
from ..flow import NoSlip, Slip
from ..mesh import StructuredMesh, graded_axis
from ..params import SCHEMES, FluidParams, TimeParams
from ..particles import Ball, Particles
from ..particles.drag import terminal_velocity
from ..solvers.settings import SolverParams
from .base import pyplot, save_figure
from .builder import DomainParams, Layout, MeshTime, ParticleScene, particle_params
from .data import tencate2002

CASES = {"E1": (970.0, 0.373), "E2": (965.0, 0.212), "E3": (962.0, 0.113), "E4": (960.0, 0.058)}
T_END = {"E1": 4.0, "E2": 2.5, "E3": 1.7, "E4": 1.3}  # the experiment's sphere reached the bottom
BOX = np.array([0.1, 0.1, 0.16])


@dataclass(frozen=True)
class TenCateFluid(Section):
    """Fluid (silicone oil) and gravity."""

    case: str = param("E4", "experiment: E1 | E2 | E3 | E4 sets (density, viscosity)",
                      choices=tuple(CASES))
    gravity: float = param(9.81, "gravitational acceleration (downwards)", "m/s^2", positive=True)


@dataclass(frozen=True)
class TenCateParticle(Section):
    """The sphere."""

    diameter: float = param(0.015, "sphere diameter", "m", positive=True)
    density: float = param(1120.0, "sphere density", "kg/m^3", positive=True)
    height: float = param(0.1275, "initial centre height above the bottom", "m", positive=True)
    stop_gap: float = param(0.05, "stop when the gap to the bottom is below this many diameters",
                            nonnegative=True)


@dataclass(frozen=True)
class TenCateDomain(DomainParams):
    """Domain and mesh."""

    symmetry: str = param("quarter", "quarter box with two mirror planes, or the whole box",
                          choices=("quarter", "none"))


TenCateTime = derive(
    MeshTime, "TenCateTime",
    "Time stepping (``dt = 0``: ``courant h / U`` with U the sphere's terminal velocity by the "
    "Schiller–Naumann drag, so that each level halves it; ``t_end = 0``: the time the experiment's "
    "sphere reached the bottom).",
    t_end=param(0.0, "final time (0: by case, 1.3 s for E4 to 4 s for E1)", "s", nonnegative=True),
    scheme=param("crank-nicolson", "implicit time scheme (crank-nicolson with the trapezoidal particle "
                 "integrator: second order for a fixed boundary, lower with the sphere crossing the mesh)",
                 choices=SCHEMES))
TenCateSolver = derive(
    SolverParams, "TenCateSolver", "Nonlinear and linear solver settings: Newton stops at a 1e-6 residual "
    "reduction (docs/method.md on the linear and Newton tolerances).", newton_rtol=1e-6,
    linear_rtol=param(1e-3, "relative residual per linear solve (the chord-Newton steps contract the "
                      "residual 50-300x each, so a tighter solve changes nothing: at E4 level 0 the "
                      "velocities of 1e-3 and 1e-8 agree to 1e-8, with 2.4x fewer multigrid cycles)",
                      positive=True, maximum=0.1))


def _inside_the_box(params) -> None:
    r = params.particle.diameter / 2
    if not r < params.particle.height < BOX[2] - r:
        raise ParamError(f"particle.height = {params.particle.height} m puts the sphere (radius {r} m) "
                         f"outside the {BOX[2]} m high box; choose a height in ({r}, {BOX[2] - r})")
    if not params.particle.diameter < BOX[0]:
        raise ParamError(f"particle.diameter = {params.particle.diameter} m does not fit the {BOX[0]} m box")


TenCateParams = particle_params("TenCateParams", "Parameters of ``ten-cate``.", _inside_the_box,
                                fluid=TenCateFluid, particle=TenCateParticle, domain=TenCateDomain,
                                time=TenCateTime, coupling=SecondOrderCouplingParams, solver=TenCateSolver,
                                contact=WallContactParams)


def gap_deviation(t: np.ndarray, gap: np.ndarray, case: str, up_to: float = 1.0,
                  reference: np.ndarray | None = None) -> float:
    """Largest relative deviation ``|gap(t_k) - gap_exp(t_k)| / gap_exp(t_k)`` over the
    experiment's samples with ``gap_exp >= up_to`` inside the simulated time span; ``reference``
    (t, gap/d) replaces the measured gap curve ``tencate2002.GAP[case]`` (e.g. the one its
    velocity curve gives, :func:`~fbmflow.scenes.data.tencate2002.gap_from_velocity`)."""
    ref = tencate2002.GAP[case] if reference is None else reference
    sel = (ref[:, 1] >= up_to) & (ref[:, 0] >= t[0]) & (ref[:, 0] <= t[-1])
    sim = np.interp(ref[sel, 0], t, gap)
    return float(np.max(np.abs(sim - ref[sel, 1]) / ref[sel, 1])) if sel.any() else float("nan")


class TenCate(ParticleScene):
    name = "ten-cate"
    description = "3D sphere settling in a closed box, ten Cate et al. (2002) E1-E4"
    Params = TenCateParams
    default_level = 1
    max_level = 3

    @staticmethod
    def mesh(level: int, symmetry: str, kind: str = "graded", diameter: float = 0.015,
             height: float = 0.1275) -> StructuredMesh:
        """The box (or its quarter) with cells of ``h = 5 mm / 2^level`` along the sphere's path
        (``kind = "graded"``: only there, within ``diameter`` of the axis and up to ``diameter``
        above the release height ``height``) [m]. Every axis has a multiple of ``2^(level + 1)``
        cells, so that multigrid coarsens at least ``level + 1`` times."""
        n, h = 2**level, 0.005 / 2**level
        lower = (0.05, 0.05, 0.0) if symmetry == "quarter" else (0.0, 0.0, 0.0)
        if kind == "uniform":
            cells = (10 * n, 10 * n, 32 * n) if symmetry == "quarter" else (20 * n, 20 * n, 32 * n)
            return StructuredMesh.box(cells, lower=lower, upper=tuple(BOX))
        reach = 0.05 + diameter  # the fine zone about the axis x = y = 50 mm
        side = [graded_axis(lower[a], BOX[a], (max(lower[a], 0.1 - reach), min(reach, BOX[a])), h,
                            multiple=2 * n) for a in (0, 1)]
        top = min(height + diameter, BOX[2])
        return StructuredMesh.rectilinear(side + [graded_axis(0.0, BOX[2], (0.0, top), h, multiple=2 * n)])

    def layout(self, params: TenCateParams, level: int) -> Layout:
        pp, quarter = params.particle, params.domain.symmetry == "quarter"
        rho_f, mu = CASES[params.fluid.case]
        mesh = self.mesh(level, params.domain.symmetry, params.domain.mesh, pp.diameter, pp.height)
        bc = {t: NoSlip() for t in mesh.tags}
        if quarter:
            bc["xmin"] = bc["ymin"] = Slip()
        particles = Particles.at_rest([Ball(pp.diameter / 2, 3)], pp.density, [[0.05, 0.05, pp.height]])
        fluid = FluidParams(density=rho_f, viscosity=mu, gravity=params.fluid.gravity)
        return Layout(mesh, particles, fluid, bc, (0, 1) if quarter else ())

    def velocity_scale(self, params: TenCateParams) -> float:
        """The sphere's terminal velocity in unbounded fluid (Schiller–Naumann drag,
        :func:`~fbmflow.particles.drag.terminal_velocity`): 0.129 m/s for E4, whose unbounded
        terminal velocity ten Cate et al. give as 0.128 m/s."""
        rho_f, mu = CASES[params.fluid.case]
        pp = params.particle
        return terminal_velocity(pp.diameter, pp.density, rho_f, mu, params.fluid.gravity, 3)

    def time(self, params: TenCateParams, place) -> TimeParams:
        """The time step that follows the mesh (:meth:`ParticleScene.time
        <fbmflow.scenes.builder.ParticleScene.time>`) and the case's final time where
        ``params.time`` leaves it 0."""
        t = super().time(params, place)
        return dataclasses.replace(t, t_end=t.t_end or T_END[params.fluid.case])

    def observe(self, params: TenCateParams, sim) -> dict:
        d, p = params.particle.diameter, sim.particles
        return {"t": sim.t, "gap_over_d": float((p.position[0, 2] - d / 2) / d),
                "settling_velocity": float(-p.velocity[0, 2])}

    def stop(self, params: TenCateParams, row: dict) -> bool:
        return row["gap_over_d"] < params.particle.stop_gap

    def quantities(self, params: TenCateParams, series: dict, sim) -> dict:
        case = params.fluid.case
        u_max = max(series["settling_velocity"])
        return {"max_settling_velocity": u_max,
                "max_settling_velocity_error": u_max / tencate2002.U_MAX[case] - 1.0,
                "gap_max_deviation": gap_deviation(np.array(series["t"]), np.array(series["gap_over_d"]),
                                                   case),
                "gap_max_deviation_from_velocity": gap_deviation(
                    np.array(series["t"]), np.array(series["gap_over_d"]), case,
                    reference=tencate2002.gap_from_velocity(case)),
                "cells_per_diameter": float(params.particle.diameter / sim.mesh.finest_spacing.max()),
                **series}

    def plot(self, summary: dict, path) -> bool:
        plt = pyplot()

        q, case = summary["quantities"], summary["params"]["fluid"]["case"]
        fig, ax = plt.subplots(1, 2, figsize=(10, 4.2))
        ax[0].plot(q["t"], q["gap_over_d"], label="fbmflow")
        ax[0].plot(*tencate2002.GAP[case].T, "o", mfc="none", label="ten Cate et al. 2002 (PIV)")
        ax[0].plot(*tencate2002.gap_from_velocity(case).T, "k:", label="their velocity curve, integrated")
        ax[0].set_ylabel("gap / d")
        ax[1].plot(q["t"], q["settling_velocity"], label="fbmflow")
        ax[1].plot(*tencate2002.VELOCITY[case].T, "o", mfc="none", label="ten Cate et al. 2002 (PIV)")
        ax[1].axhline(tencate2002.U_MAX[case], ls=":", c="k", label="u_max, Table II")
        ax[1].set_ylabel("settling velocity [m/s]")
        for a in ax:
            a.set_xlabel("t [s]")
            a.grid(alpha=0.3)
            a.legend()
        fig.suptitle(f"ten-cate {case}, level {summary['level']} "
                     f"({q['cells_per_diameter']:.0f} cells/d, {summary['n_cells']} cells)")
        return save_figure(fig, path)
