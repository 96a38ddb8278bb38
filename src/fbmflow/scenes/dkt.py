"""Drafting, kissing and tumbling of two disks settling in a closed channel (2D, CGS units).

Setups (``setup``):

* ``glowinski`` (the default; Glowinski et al. 2001): disks of diameter 0.2 cm, rho_s = 1.01,
  in a 2 x 8 cm channel of fluid with rho_f = 1, nu = 0.01 cm^2/s, g = 981 cm/s^2, centres at
  (1, 7.2) and (1, 6.8) cm, the upper disk shifted by ``offset`` = 1e-4 cm in x to break the
  symmetry. Level ``L``: ``10 2^L x 40 2^L`` cells, ``2^L`` across the diameter.
* ``uhlmann`` (Uhlmann 2005, recomputed by Koblitz et al. 2017): d = 0.25 cm, rho_s / rho_f =
  1.5, 2 x 6 cm channel, centres on the axis 1 and 1.5 cm below the top wall (trailing, leading),
  the lateral offsets ``+- d / 250``. Level ``L``: ``8 2^L x 24 2^L`` cells. Koblitz et al.'s
  curves (digitised) put the kiss at t = 0.175 s and the tumble at t = 0.26 s.

Quantities: ``t_kiss``, the first time the centres come closer than ``kiss_distance`` diameters
(1.05 by default, the separation the reference curves show during the kiss) plus the contact
skin (one cell by default: hard contact stops the surfaces that far apart); ``t_tumble``, the
first time the trailing disk's centre passes below the leading one's; time series ``t``,
``x_leading``, ``y_leading``, ``x_trailing``, ``y_trailing``, ``v_leading``, ``v_trailing``.
Hard contact (restitution 0) keeps the disks apart and off the walls.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..config import Section, derive, param
from ..mesh import StructuredMesh
from ..params import FluidParams, TimeParams
from ..particles import Ball, Particles
from .base import pyplot, save_figure
from .builder import CONTACT_SECTIONS, Layout, ParticleScene, particle_params

# setup: (box (width, height) [cm], diameter [cm], rho_s, rho_f, nu [cm^2/s], leading centre,
# trailing centre, (leading, trailing) x offsets in units of `offset`, cells per cm at level 0)
SETUPS = {
    "glowinski": dict(box=(2.0, 8.0), d=0.2, rho_s=1.01, rho_f=1.0, nu=0.01, leading=(1.0, 6.8),
                      trailing=(1.0, 7.2), shift=(0.0, 1.0), cells_per_cm=5),
    "uhlmann": dict(box=(2.0, 6.0), d=0.25, rho_s=1.5, rho_f=1.0, nu=0.01, leading=(1.0, 4.5),
                    trailing=(1.0, 5.0), shift=(-1.0, 1.0), cells_per_cm=4),
}
DEFAULTS = {"glowinski": dict(dt=0.01, t_end=4.0, offset=1e-4),
            "uhlmann": dict(dt=0.002, t_end=0.4, offset=0.25 / 250)}
REFERENCE = {"uhlmann": {"t_kiss": 0.175, "t_tumble": 0.26}}  # Koblitz et al. 2017, Fig. 10c


@dataclass(frozen=True)
class DktCase(Section):
    """The set-up."""

    setup: str = param("glowinski", "glowinski (rho_s 1.01, 2 x 8 cm) or uhlmann (rho_s 1.5, 2 x 6 cm)",
                       choices=tuple(SETUPS))
    offset: float = param(0.0, "lateral shift that breaks the symmetry (0: 1e-4 cm for glowinski, "
                          "d / 250 for uhlmann)", "cm", nonnegative=True)
    gravity: float = param(981.0, "gravitational acceleration (downwards)", "cm/s^2", positive=True)
    kiss_distance: float = param(1.05, "kissing: centre distance below this many diameters", minimum=1.0)


DktTime = derive(TimeParams, "DktTime",
                 "Time stepping (``t_end = 0``: 4 s for glowinski, 0.4 s for uhlmann).",
                 dt=param(0.0, "time step (0: 0.01 s for glowinski, 0.002 s for uhlmann)", "s",
                          nonnegative=True),
                 t_end=param(0.0, "final time", "s", nonnegative=True), scheme="backward-euler")
DktParams = particle_params("DktParams", "Parameters of ``dkt-2d``.", case=DktCase, time=DktTime,
                            **CONTACT_SECTIONS)


def _first_crossing(t: np.ndarray, f: np.ndarray) -> float | None:
    """First time the series ``f`` becomes negative, linearly interpolated; None if never."""
    k = np.flatnonzero(f < 0)
    if len(k) == 0:
        return None
    k = k[0]
    if k == 0:
        return float(t[0])
    return float(t[k - 1] + (t[k] - t[k - 1]) * f[k - 1] / (f[k - 1] - f[k]))


class DKT2D(ParticleScene):
    name = "dkt-2d"
    description = "drafting, kissing and tumbling of two settling disks (Glowinski / Uhlmann set-ups)"
    Params = DktParams
    default_level = 2
    max_level = 5

    @staticmethod
    def mesh(setup: str, level: int) -> StructuredMesh:
        s = SETUPS[setup]
        n = s["cells_per_cm"] * 2**level
        return StructuredMesh.box((int(s["box"][0] * n), int(s["box"][1] * n)), upper=s["box"])

    def layout(self, params: DktParams, level: int) -> Layout:
        c = params.case
        s = SETUPS[c.setup]
        centres = np.array([s["leading"], s["trailing"]], dtype=float)
        centres[:, 0] += (c.offset or DEFAULTS[c.setup]["offset"]) * np.array(s["shift"])
        disk = Ball(s["d"] / 2, 2)
        fluid = FluidParams(density=s["rho_f"], viscosity=s["nu"] * s["rho_f"], gravity=c.gravity)
        return Layout(self.mesh(c.setup, level), Particles.at_rest([disk, disk], s["rho_s"], centres), fluid)

    def time(self, params: DktParams, place) -> TimeParams:
        """``params.time`` with the set-up's time step and final time where it leaves them 0."""
        default, t = DEFAULTS[params.case.setup], params.time
        return dataclasses.replace(t, dt=t.dt or default["dt"], t_end=t.t_end or default["t_end"])

    def observe(self, params: DktParams, sim) -> dict:
        X, V = sim.particles.position, sim.particles.velocity
        return {"t": sim.t, "x_leading": float(X[0, 0]), "y_leading": float(X[0, 1]),
                "x_trailing": float(X[1, 0]), "y_trailing": float(X[1, 1]),
                "v_leading": float(V[0, 1]), "v_trailing": float(V[1, 1])}

    def quantities(self, params: DktParams, series: dict, sim) -> dict:
        c = params.case
        d = SETUPS[c.setup]["d"]
        t = np.array(series["t"])
        lead = np.column_stack([series["x_leading"], series["y_leading"]])
        trail = np.column_stack([series["x_trailing"], series["y_trailing"]])
        distance = np.linalg.norm(lead - trail, axis=1) / d
        skin = 0.0 if sim.contact is None else sim.contact.skin / d  # hard contact keeps them this far apart
        q = {"t_kiss": _first_crossing(t, distance - c.kiss_distance - skin),
             "t_tumble": _first_crossing(t, trail[:, 1] - lead[:, 1]),  # trailing below leading
             "min_distance_over_d": float(distance.min()),
             "cells_per_diameter": float(d / sim.mesh.spacing[0]), **series}
        for key, ref in REFERENCE.get(c.setup, {}).items():
            q[f"{key}_reference"] = ref
            if q[key] is not None:
                q[f"{key}_error"] = (q[key] - ref) / ref
        return q

    def plot(self, summary: dict, path) -> bool:
        plt = pyplot()

        q = summary["quantities"]
        setup = summary["params"]["case"]["setup"]
        fig, ax = plt.subplots(1, 3, figsize=(13, 4.2))
        for who, style in (("leading", "-"), ("trailing", "--")):
            ax[0].plot(q["t"], q[f"y_{who}"], style, label=who)
            ax[1].plot(q["t"], q[f"x_{who}"], style, label=who)
            ax[2].plot(q["t"], q[f"v_{who}"], style, label=who)
        for a, label in zip(ax, ("y [cm]", "x [cm]", "vertical velocity [cm/s]")):
            a.set_xlabel("t [s]")
            a.set_ylabel(label)
            a.grid(alpha=0.3)
            for key, colour in (("t_kiss", "C2"), ("t_tumble", "C3")):
                if q.get(key) is not None:
                    a.axvline(q[key], c=colour, lw=0.8, label=f"{key} = {q[key]:.3f} s")
                if f"{key}_reference" in q:
                    a.axvline(q[f"{key}_reference"], c=colour, ls=":", lw=0.8,
                              label=f"{key}, Koblitz et al. 2017")
        ax[0].legend(fontsize=8)
        fig.suptitle(f"dkt-2d ({setup}), level {summary['level']} ({q['cells_per_diameter']:.0f} cells/d)")
        return save_figure(fig, path)
