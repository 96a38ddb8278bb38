"""Steady terminal velocity of ten Cate's sphere in its box's cross-section, per mesh level: does
the discretisation converge towards the measured peak?

Question: which steady terminal velocity does each force estimator give ten Cate's sphere in its
box's cross-section at 4 / 6 / 8 cells per diameter, against the measured peak velocity?
Answer: E4: 0.12134 / 0.12032 / 0.12049 m/s with the volume force (-1.4 % at 8 cells/d),
0.12505 / 0.12456 / 0.12303 with the surface force (+0.6 %), 0.13147 / 0.12611 / 0.12572 with
the test-function force; E1: 0.03381 / 0.03386 / 0.03397 m/s with the volume force (-6.0 / -5.9
/ -5.6 % against Table II), surface -2.3 / -2.1 / -3.2 %, test function +5.6 / +0.6 / -0.3 %
(benchmarks/results/terminal_velocity_E4.md, terminal_velocity_E1.md).
Measured: 2026-11-25, commit 5f35762; quoted in docs/validation/ten-cate-e1-e4.md
Run: python -m fbmbench terminal_velocity --case E1 --cells 4 6 8

In the frame of a sphere settling at speed ``U`` through ten Cate's 100 x 100 mm box far from
its bottom and lid, the flow is steady: the sphere is a fixed (sharp) fictitious boundary, the
fluid enters from below at ``U``, the side walls move up at ``U``, the top is a do-nothing outflow.
The steady terminal velocity ``U*`` balances the drag against the net weight,

    F_z(U*) = (rho_s - rho_f) (pi d^3 / 6) g,

found by the secant method on ``log F`` against ``log U`` with the volume force (the one the
transient runs use by default, 3-4 steady solves); the test-function and surface
(:class:`~fbmflow.coupling.SurfaceForces`) forces' ``U*`` come from the same solves, by the power
law through the two whose drags lie nearest the weight. The transient
run's peak lies a little below ``U*`` (the sphere is still accelerating when the bottom slows
it), so ``U*`` per level shows how the mesh alone moves the answer, at a fraction of a transient
run's cost. Quarter domain (two mirror planes through the sphere's axis), graded mesh with cells
of ``d / n`` within one diameter of the axis and from one diameter below to two above the
centre; 8 diameters of inflow, 10 of wake (measured at 4 cells/d: 4 diameters of inflow gave
2.1 % more drag, 12 of inflow and 30 of wake changed it by less than 0.01 %).

Run with ``python -m fbmbench terminal_velocity [--case E4] [--cells 4 6 8]``.

Writes ``benchmarks/results/terminal_velocity_<case>.md`` and ``.json``: cells per diameter,
unknowns, the balancing ``U*`` with each force estimator, its deviation from ten Cate's u_max
(Table II), steady solves and wall time (without the JIT warm-up on the coarsest mesh).
"""
from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Literal

import numpy as np

from fbmflow.coupling import (
    FixedObstacles,
    SurfaceForces,
    TestFunctionForces,
    hydrodynamic_forces,
    mirror_images,
    node_owner,
)
from fbmflow.flow import Dirichlet, DoNothing, NavierStokesProblem, Slip
from fbmflow.mesh import StructuredMesh, graded_axis
from fbmflow.particles import Ball
from fbmflow.scenes.data import tencate2002
from fbmflow.scenes.tencate import CASES
from fbmflow.solvers import DirectSolver

RESULTS = Path(__file__).resolve().parents[1] / "results"
D, RHO_S, G = 0.015, 1120.0, 9.81
HALF_WIDTH, UPSTREAM, WAKE = 0.05, 8 * D, 10 * D


def mesh(cells: int) -> StructuredMesh:
    """Quarter channel [0, 50 mm]^2 x [0, 18 d], sphere centre on the axis x = y = 0 at z = 8 d."""
    h = D / cells
    side = graded_axis(0.0, HALF_WIDTH, (0.0, D), h)
    return StructuredMesh.rectilinear([side, side.copy(),
                                       graded_axis(0.0, UPSTREAM + WAKE,
                                                   (UPSTREAM - D, UPSTREAM + 2 * D), h)])


class SteadyDrag:
    """Drag (N, whole sphere, +z) at sphere speed ``U`` on one mesh, with both force estimators."""

    def __init__(self, cells: int, mu: float, rho: float):
        self.mu, self.rho = mu, rho
        self.mesh = mesh(cells)
        self.centre = np.array([[0.0, 0.0, UPSTREAM]])
        self.ball = Ball(D / 2, 3)
        self.obstacle = FixedObstacles([self.ball], self.centre, "sharp")
        self.n_dofs = None

    def __call__(self, U: float) -> tuple[dict, int]:
        wall = Dirichlet((0.0, 0.0, U))
        bcs = {"zmin": wall, "xmax": wall, "ymax": wall, "xmin": Slip(), "ymin": Slip(), "zmax": DoNothing()}
        problem = NavierStokesProblem(self.mesh, self.mu, bcs, density=self.rho, linear_solver=DirectSolver(),
                                      extra_constraints=self.obstacle)
        x, report = problem.solve_steady()
        self.n_dofs = problem.n_dofs
        space = problem.space
        u, p = x[:space.n_u], x[space.n_u:]
        owner = node_owner(space.V, self.centre, [self.ball])
        volume = hydrodynamic_forces(space, owner, self.centre, u, p, self.mu)
        walls = problem.constraints().fixed
        tested = TestFunctionForces(space, owner, self.centre, [self.ball], walls=walls[walls < space.n_v])(
            u, p, self.mu, self.rho)
        surface = SurfaceForces(space, self.centre, [self.ball])(u, p, self.mu)
        drag = {name: float(mirror_images(*ft, (0, 1))[0][0, 2])
                for name, ft in (("volume", volume), ("test-function", tested), ("surface", surface))}
        return drag, report.iterations


def terminal_velocity(drag_of, weight: float, U0: float, rtol: float = 2e-4, max_solves: int = 8):
    """``U*`` with ``drag(U*) = weight`` for the volume force by the secant method on
    (log U, log F), the first step assuming ``F ~ U^1.5``; the test-function and surface forces'
    ``U*`` by the power law through the two solves whose drags lie nearest the weight.
    Returns {estimator: U*}, the solves [(U, drags, Newton iterations)] and the volume force's
    last relative imbalance."""
    history = []
    U, slope = U0, 1.5
    for _ in range(max_solves):
        drags, newton = drag_of(U)
        history.append((U, drags, newton))
        F = drags["volume"]
        print(f"    U {U:.5f} m/s: drag " + ", ".join(f"{k} {v:.5e} N" for k, v in drags.items())
              + f" (weight {weight:.5e} N), Newton {newton}", flush=True)
        if abs(F / weight - 1.0) < rtol and len(history) > 1:
            break
        if len(history) > 1:
            slope = _power(*history[-2:], "volume")
        U = U * (weight / F) ** (1.0 / slope)
    U_star = {"volume": U}
    for other in ("test-function", "surface"):
        a, b = sorted(history, key=lambda h: abs(np.log(h[1][other] / weight)))[:2]
        U_star[other] = a[0] * (weight / a[1][other]) ** (1.0 / _power(a, b, other))
    return U_star, history, F / weight - 1.0


def _power(first, second, estimator: str) -> float:
    """Exponent ``n`` of ``F ~ U^n`` through two solves (U, drags, ...)."""
    return np.log(second[1][estimator] / first[1][estimator]) / np.log(second[0] / first[0])


def run(*, case: Literal["E1", "E2", "E3", "E4"] = "E4", cells: list[int] = (4, 6, 8)) -> None:
    """``U*`` per mesh for ``case``; writes the table.

    Parameters
    ----------
    case : ten Cate's experiment
    cells : cells per diameter near the sphere
    """
    rho, mu = CASES[case]
    weight = (RHO_S - rho) * np.pi * D**3 / 6 * G
    u_exp = tencate2002.U_MAX[case]
    t0 = time.perf_counter()
    SteadyDrag(2, mu, rho)(u_exp)  # JIT warm-up
    print(f"JIT warm-up {time.perf_counter() - t0:.0f} s", flush=True)
    rows = []
    for n in cells:
        drag_of = SteadyDrag(n, mu, rho)
        print(f"{case}: {n} cells/d", flush=True)
        t0 = time.perf_counter()
        U, history, imbalance = terminal_velocity(drag_of, weight, rows[-1]["U"]["volume"] if rows else u_exp)
        rows.append(dict(case=case, cells_per_diameter=n, n_dofs=drag_of.n_dofs, U=U,
                         error={k: v / u_exp - 1.0 for k, v in U.items()}, imbalance=imbalance,
                         solves=len(history), wall_s=time.perf_counter() - t0,
                         history=[dict(U=h[0], newton=h[2], **h[1]) for h in history]))
        r = rows[-1]
        print("  " + ", ".join(f"U* {k} {v:.5f} m/s ({100 * r['error'][k]:+.2f} %)" for k, v in U.items())
              + f" vs u_max {u_exp}; {r['solves']} solves, {r['n_dofs']} unknowns, {r['wall_s']:.0f} s",
              flush=True)
    RESULTS.mkdir(exist_ok=True)
    stem = RESULTS / f"terminal_velocity_{case}"
    stem.with_suffix(".json").write_text(json.dumps(rows, indent=1))
    lines = [f"# Steady terminal velocity, ten Cate {case}, sharp boundary "
             "(python -m fbmbench terminal_velocity)", "",
             f"Sphere d = {D} m, rho_s = {RHO_S}, fluid (rho, mu) = ({rho}, {mu}), in the box's 100 x 100 mm "
             "cross-section (quarter, two mirror planes), sphere frame: inflow and side walls at U, "
             f"{UPSTREAM / D:.0f} d of inflow, {WAKE / D:.0f} d of wake. "
             "U*: the speed whose steady drag balances the "
             f"net weight {weight:.5e} N, with the cut-cell volume force (secant to |F/W - 1| < 2e-4) "
             "and with the "
             "test-function and surface forces (power law through the two solves nearest to each); "
             "against ten Cate's transient "
             f"peak u_max = {u_exp} m/s (Table II), which lies a little below a steady terminal velocity. "
             "Direct "
             "solver (PARDISO); wall time per level without the JIT warm-up, with other jobs beside it.", "",
             "| cells/d | unknowns | U* volume force m/s | vs u_max | U* test function m/s | vs u_max "
             "| U* surface force m/s "
             "| vs u_max | steady solves | wall s |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    lines += [f"| {r['cells_per_diameter']} | {r['n_dofs']} | {r['U']['volume']:.5f} | "
              f"{100 * r['error']['volume']:+.2f} % | "
              f"{r['U']['test-function']:.5f} | {100 * r['error']['test-function']:+.2f} % | "
              f"{r['U']['surface']:.5f} | {100 * r['error']['surface']:+.2f} % | {r['solves']} | "
              f"{r['wall_s']:.0f} |" for r in rows]
    stem.with_suffix(".md").write_text("\n".join(lines) + "\n")
    print(f"wrote {stem}.md", flush=True)
