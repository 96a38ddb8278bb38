"""Rotation that feeds back: the viscous torque on a turning disk or sphere, and the rate at which a
torque-free one turns in simple shear, per resolution.

Question: how close do the torque on a disk / sphere turning at omega (exact, unbounded:
4 pi mu a^2 omega / 8 pi mu a^3 omega) and the torque-free rotation rate in simple shear (exact
in Stokes flow: gamma / 2) come at 4-16 cells per diameter?
Answer: the free sphere turns at 0.9938 / 0.9933 / 0.9934 of gamma / 2 at 4 / 6 / 8 cells per
diameter in a box of 4 diameters and 0.9982 at 4 in a box of 6 (the deficit is the walls'; every
estimator alike), the disk at 0.993 at 4-16; the turning sphere's torque is within 1 % of the
walls' bounds at 6 and 8 cells per diameter with the volume and test-function forces, 5 / 2 % low
at 6 / 8 with the surface force (benchmarks/results/rotation.md).
Measured: 2026-11-28, commit a547da0 (8 cells per diameter: commit 1d56541); quoted in
docs/validation/converged-answers.md.
Run: python -m fbmbench rotation --dim 3 --cells 4 6 8 --width 4

A ball of diameter 1 sits in the middle of a box of ``width`` diameters, mu = 1, rho = 1e-3 (Re
below 1e-3), one steady solve per case (Stokes flow is linear):

* **turning**: closed box, the ball turning at omega = 1 about z; its torque against the
  unbounded value and the containers' (a concentric cylinder / sphere of the box's inscribed and
  circumscribed radius bound the walls' effect);
* **in shear**: walls y = 0, L moving at -/+ gamma L / 2 along x, periodic in x (and z), the ball
  held still; its torque ``T_0``. The torque-free rate is ``omega* = -T_0 / T_1`` with ``T_1`` the
  torque per unit rate of the same ball turning in the same (Couette) box, the second solve: the
  quasi-steady answer that the coupled time loop settles to (tests/coupling/test_rotation.py runs
  that loop for the disk).

Torques from the volume force, the test-function force and (sharp boundary, balls) the surface
force. Writes ``benchmarks/results/rotation.md`` and ``.json``.
"""
from __future__ import annotations

import time
from typing import Literal

import numpy as np
from fbmbench.common import RESULTS, merge_row, provenance, write_text

from fbmflow.coupling import (
    FixedObstacles,
    SurfaceForces,
    TestFunctionForces,
    hydrodynamic_forces,
    node_owner,
)
from fbmflow.flow import Dirichlet, NoSlip
from fbmflow.mesh import StructuredMesh
from fbmflow.particles import Ball
from fbmflow.scenes.builder import flow_problem
from fbmflow.solvers.settings import SteadySolverParams

ESTIMATORS = ("volume", "test-function", "surface")


def torques(dim: int, cells: int, width: float, boundary: str, shear: bool, spin: float) -> dict:
    """The z torque of each estimator on the ball of one steady solve."""
    a, L, mu = 0.5, width, 1.0
    n = int(round(width * cells))
    periodic = (True, False, True)[:dim] if shear else None
    mesh = StructuredMesh.box((n,) * dim, upper=(L,) * dim, periodic=periodic)
    centre, ball = np.full((1, dim), L / 2), Ball(a, dim)
    omega = np.array([spin]) if dim == 2 else np.array([[0.0, 0.0, spin]])
    obstacle = FixedObstacles([ball], centre, boundary, angular_velocities=omega)
    if shear:
        wall = np.zeros(dim)
        wall[0] = L / 2
        bcs = {"ymin": Dirichlet(-wall), "ymax": Dirichlet(wall)}
    else:
        bcs = {t: NoSlip() for t in mesh.tags}
    problem = flow_problem(mesh, mu, bcs, SteadySolverParams(linear="auto"), density=1e-3,
                           extra_constraints=obstacle)
    x, _ = problem.solve_steady()
    space = problem.space
    u, p = x[:space.n_u], x[space.n_u:]
    owner = node_owner(space.V, centre, [ball])
    walls = problem.constraints().fixed
    out = {"volume": hydrodynamic_forces(space, owner, centre, u, p, mu)[1][0, 2],
           "test-function": TestFunctionForces(space, owner, centre, [ball],
                                               walls=walls[walls < space.n_v])(u, p, mu, 1e-3)[1][0, 2]}
    if boundary == "sharp":
        out["surface"] = SurfaceForces(space, centre, [ball])(u, p, mu)[1][0, 2]
    return {"torque": out, "n_dofs": problem.n_dofs}


def run(*, dim: Literal[2, 3] = 3, cells: list[int] = (4, 6, 8), width: float = 4.0,
        boundary: Literal["sharp", "nodes"] = "sharp") -> None:
    """Both cases at each resolution; one row each.

    Parameters
    ----------
    dim : 2 (disk) or 3 (sphere)
    cells : cells per diameter
    width : box side in diameters
    boundary : fbm.boundary
    """
    a, mu = 0.5, 1.0
    unbounded = 4 * np.pi * mu * a**2 if dim == 2 else 8 * np.pi * mu * a**3
    radii = np.array([width / 2, width / 2 * np.sqrt(dim)])
    container = radii**2 / (radii**2 - a**2) if dim == 2 else 1 / (1 - (a / radii)**3)
    for n in cells:
        t0 = time.perf_counter()
        closed = torques(dim, n, width, boundary, shear=False, spin=1.0)
        spin = torques(dim, n, width, boundary, shear=True, spin=1.0)
        still = torques(dim, n, width, boundary, shear=True, spin=0.0)
        row = dict(dim=dim, cells=n, width=width, boundary=boundary, n_dofs=closed["n_dofs"],
                   wall_s=time.perf_counter() - t0, container=container.tolist(),
                   turning={k: -v / unbounded for k, v in closed["torque"].items()},
                   free_rate={k: still["torque"][k] / (spin["torque"][k] - still["torque"][k]) / 0.5
                              for k in closed["torque"]}, **provenance())
        print(f"dim {dim} {n} cells/d {boundary}: turning {row['turning']}, free rate / (gamma/2) "
              f"{row['free_rate']} ({row['wall_s']:.0f} s)", flush=True)
        rows = merge_row("rotation", row, lambda r, s: all(r[k] == s[k] for k in ("dim", "cells", "width",
                                                                                     "boundary")))
    write(rows)


def write(rows: list[dict]) -> None:
    lines = ["# Rotation: torque on a turning ball, torque-free rate in shear (rotation)", "",
             "Ball of diameter 1 in the middle of a box (side in diameters), Stokes flow, one steady "
             "solve per case. 'turning': torque on the ball turning at omega in the closed box over the "
             "unbounded value (4 pi mu a^2 omega in 2D, 8 pi mu a^3 omega in 3D); the walls raise it by "
             "the factor between the two 'container' values. 'free rate': the torque-free rotation rate "
             "in simple shear (moving walls "
             "y = 0, L; periodic in x and z) over gamma / 2, exact in unbounded Stokes flow. Per force "
             "estimator: volume / test-function / surface. Reproduce: `python -m fbmbench rotation --dim D "
             "--cells N --width W --boundary B`.", "",
             "| dim | box | boundary | cells/d | unknowns | container | turning (vol / test / surf) | "
             "free rate (vol / test / surf) | wall s | measured |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in sorted(rows, key=lambda r: (r["dim"], r["width"], r["boundary"], r["cells"])):
        turn = " / ".join(f"{r['turning'][k]:.4f}" for k in ESTIMATORS if k in r["turning"])
        free = " / ".join(f"{r['free_rate'][k]:.4f}" for k in ESTIMATORS if k in r["free_rate"])
        lines.append(f"| {r['dim']} | {r['width']:g} | {r['boundary']} | {r['cells']} | {r['n_dofs']} | "
                     f"{r['container'][1]:.4f}-{r['container'][0]:.4f} | {turn} | {free} | "
                     f"{r['wall_s']:.0f} | "
                     f"{r['date']} {r['commit']} |")
    write_text(RESULTS / "rotation.md", "\n".join(lines) + "\n")
