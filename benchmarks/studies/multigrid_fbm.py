"""Multigrid with fictitious boundaries: cycles per solve for coarse-level and smoother variants.

Question: how many FGMRES/V(2,2) cycles does multigrid need with a moving ball under the nodal
or sharp fictitious boundary, for each coarse-obstacle and smoother variant, against no ball?
Answer: with the sharp boundary at most 1.25x the cycles without the ball, flat across levels
(2D 32^2 / 64^2: 7 / 7 against 7 / 6; 3D open box 16^3: 10 against 8; closed box 8^3 / 16^3:
9 / 9 against 8 / 8); the coarse obstacles ``nodes`` and ``galerkin`` within two cycles
(benchmarks/results/multigrid_fbm_2d.md, multigrid_fbm_3d.md, multigrid_fbm_3d_closed.md).
Measured: 2026-11-26, commit 9ec694b (3D open box: commit 9913149); quoted in
docs/validation/multigrid-with-fictitious-boundaries.md
Run: python -m fbmbench multigrid_fbm --dim 2 --cells 32 64

One linear solve of the first Newton step of a backward-Euler step (dt 0.01, mu 0.01, rho 1) in
the unit square/cube, walls no-slip except a do-nothing top (box "open") or everywhere (box
"closed": the pressure is determined up to a constant), a smooth body force, and a ball of
radius 0.15 near the centre moving down at 1 (Reynolds number 30) under the nodal or the sharp
fictitious boundary, or no ball. FGMRES(30) with one V(2,2) cycle per iteration to 1e-8, at most
100 iterations (100 means: not converged).

Variants: ``coarse_obstacle`` ``nodes`` (each coarse level constrains its own nodes inside the
ball) or ``galerkin`` (:mod:`fbmflow.solvers.galerkin`); smoother ``vanka-full`` (cell blocks
assembled and factorised in every sweep) or ``vanka-factored`` (blocks factorised once, patches
agglomerated where the sharp boundary continues pressures).

    python -m fbmbench multigrid_fbm --dim 2 --cells 32 64
    python -m fbmbench multigrid_fbm --dim 3 --cells 8 16
    python -m fbmbench multigrid_fbm --dim 3 --cells 8 16 --box closed

writes benchmarks/results/multigrid_fbm_{dim}d[_closed].{json,md}.
"""
from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Literal

import numpy as np

from fbmflow.coupling import node_owner, rigid_body_constraints, sharp_boundary
from fbmflow.flow import DoNothing, NavierStokesProblem, NoSlip
from fbmflow.mesh import StructuredMesh
from fbmflow.particles import Ball
from fbmflow.solvers import MultigridSettings, MultigridSolver

RESULTS = Path(__file__).resolve().parents[1] / "results"
VARIANTS = [("none", "nodes", "vanka-full"), ("none", "nodes", "vanka-factored"),
            ("nodes", "nodes", "vanka-full"), ("nodes", "nodes", "vanka-factored"),
            ("nodes", "galerkin", "vanka-factored"),
            ("sharp", "nodes", "vanka-factored"), ("sharp", "galerkin", "vanka-factored")]


def ball_problem(dim: int, n: int, fbm: str, solver, mu: float = 0.01, radius: float = 0.15,
                 closed: bool = False):
    """The flow problem of the module docstring: (problem, rhs, constraints)."""
    mesh = StructuredMesh.box((n,) * dim)
    bcs = {t: NoSlip() for t in mesh.tags}
    if not closed:
        bcs["ymax" if dim == 2 else "zmax"] = DoNothing()
    centre = np.array([[0.513] + [0.521] * (dim - 1)])
    shapes = [Ball(radius, dim)]
    vel = np.zeros((1, dim))
    vel[0, -1] = -1.0
    ang = np.zeros(1) if dim == 2 else np.zeros((1, 3))
    cache = {}

    def ball(V, t):
        owner = node_owner(V, centre, shapes)
        rigid = rigid_body_constraints(V, owner, centre, vel, ang)
        if fbm != "sharp" or V is not prob.space.V:
            return rigid
        if "sharp" not in cache:
            cache["sharp"] = sharp_boundary(prob.space, owner, centre, shapes)
        return cache["sharp"].constraints(rigid, vel, ang)

    def force(x, t):
        return np.stack([np.sin(3 * x[:, 0] + 1) * np.cos(2 * x[:, 1])]
                        + [np.cos(4 * x[:, k] * x[:, 0]) for k in range(1, dim)], axis=1)

    prob = NavierStokesProblem(mesh, mu, bcs, body_force=force, linear_solver=solver,
                               extra_constraints=None if fbm == "none" else ball)
    return prob, prob.load(0.0), prob.constraints(0.0)


def measure(dim: int, n: int, fbm: str, coarse: str, smoother: str, dt: float = 0.01,
            closed: bool = False) -> dict:
    solver = MultigridSolver(MultigridSettings(smoother=smoother, coarse_obstacle=coarse))
    prob, rhs, con = ball_problem(dim, n, fbm, solver, closed=closed)
    x0 = prob.zero_state()
    F = prob.residual(x0, 1.0 / dt, 1.0, rhs, con, prob.orphans(con))
    t0 = time.perf_counter()
    hierarchy = solver.factor(prob.linear_system(x0, 1.0 / dt, 1.0, con))
    t1 = time.perf_counter()
    _, _, report = hierarchy.solve(-F[:prob.space.n_u], -F[prob.space.n_u:])
    t2 = time.perf_counter()
    return dict(dim=dim, box="closed" if closed else "open", cells=n, unknowns=prob.n_dofs,
                levels=1 + len(prob.coarse), fbm=fbm, coarse=coarse,
                smoother=smoother, iterations=report.iterations,
                reduction=report.residuals[-1] / report.residuals[0], setup_s=t1 - t0, solve_s=t2 - t1)


def run(*, dim: int = 2, cells: list[int] = (32, 64), box: Literal["open", "closed"] = "open") -> None:
    """Measure every variant at each mesh size and write the table.

    Parameters
    ----------
    dim : space dimension (2 or 3)
    cells : cells per side of the unit box
    box : open (a do-nothing top) or closed (no-slip everywhere)
    """
    closed = box == "closed"
    for smoother in ("vanka-full", "vanka-factored"):  # JIT compilation outside the figures
        measure(dim, 8, *(("sharp", "galerkin") if smoother == "vanka-factored" else ("nodes", "nodes")),
                smoother)
    rows = []
    for n in cells:
        for fbm, coarse, smoother in VARIANTS:
            row = measure(dim, n, fbm, coarse, smoother, closed=closed)
            print(row, flush=True)
            rows.append(row)
    stem = RESULTS / (f"multigrid_fbm_{dim}d" + ("_closed" if closed else ""))
    stem.with_suffix(".json").write_text(json.dumps(rows, indent=1))
    lines = [f"# Multigrid with a moving ball, {dim}D, {box} box "
             "(python -m fbmbench multigrid_fbm)", "",
             "FGMRES iterations (one V(2,2) cycle each) to 1e-8; 100 = not converged. Times in seconds, "
             "measured one after the other in one process (JIT compilation excluded).", "",
             "| cells | unknowns | levels | boundary | coarse levels | smoother | iterations | reduction "
             "| set-up s | solve s |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['cells']}^{r['dim']} | {r['unknowns']} | {r['levels']} | {r['fbm']} | "
                     f"{r['coarse']} | {r['smoother']} | {r['iterations']} | {r['reduction']:.1e} | "
                     f"{r['setup_s']:.2f} | {r['solve_s']:.2f} |")
    stem.with_suffix(".md").write_text("\n".join(lines) + "\n")

