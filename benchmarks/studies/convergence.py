"""Accuracy against cost: manufactured-solution errors, fitted orders and wall time per level,
and the time order of every registered time scheme (Taylor–Green vortex).

Question: do the discretisation's errors fall at the orders of Q2/P1 elements in 2D and 3D,
Stokes and Navier-Stokes, and are the time schemes of their nominal orders?
Answer: yes: fitted orders velocity L2 2.99-3.01, H1 2.00-2.02, pressure L2 2.01-2.21 (2D up to
32^2 cells, 3D up to 8^3); on Taylor-Green backward Euler 0.89-0.97, Crank-Nicolson and
fractional-step theta 2.00 (benchmarks/results/convergence.md).
Measured: 2026-11-21, commit 33107c3; quoted in docs/validation/discretisation-and-solvers.md
Run: python -m fbmbench convergence

Writes ``benchmarks/results/convergence.md`` and ``convergence.json``. The same set-ups are the
assertions of ``tests/flow/test_convergence.py`` and ``tests/flow/test_time_schemes.py``.
"""
from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tests"))
from mms import Manufactured2D, Manufactured3D, body_force, fitted_order  # noqa: E402

from fbmflow.fem.functions import error_norms  # noqa: E402
from fbmflow.flow import Dirichlet, NavierStokesProblem  # noqa: E402
from fbmflow.flow.time_schemes import TIME_SCHEMES, advance  # noqa: E402
from fbmflow.mesh import StructuredMesh  # noqa: E402
from fbmflow.scenes.taylor_green import TaylorGreen2D  # noqa: E402

RESULTS = Path(__file__).resolve().parents[1] / "results"


def space_convergence(sol, cells, convection):
    rows = []
    for n in cells:
        t0 = time.perf_counter()
        mesh = StructuredMesh.box((n,) * sol.dim)
        bc = {t: Dirichlet(lambda x, t: sol.u(x)) for t in mesh.tags}
        prob = NavierStokesProblem(mesh, 1.0, bc, body_force=body_force(sol, 1.0, 1.0, convection),
                                   convection=convection)
        x, report = prob.solve_steady()
        wall = time.perf_counter() - t0
        u, p = prob.split(x)
        e = error_norms(prob.space, u.ravel(), p, sol.u, sol.grad, sol.p)
        rows.append(dict(cells=n, n_dofs=prob.n_dofs, newton=report.iterations, wall_s=wall, **e))
    h = [1.0 / r["cells"] for r in rows]
    orders = {k: fitted_order(h, [r[k] for r in rows]) for k in ("u_l2", "u_h1", "p_l2")}
    return rows, orders


def time_convergence(scheme, nu=0.05, T=0.4, steps=(4, 8, 16, 32, 64)):
    prob = NavierStokesProblem(TaylorGreen2D.mesh(1), nu, {})
    finals, walls = [], []
    for n in steps:
        t0 = time.perf_counter()
        x, t = TaylorGreen2D.initial_state(prob, nu), 0.0
        for _ in range(n):
            x, _ = advance(prob, x, t, T / n, scheme)
            t += T / n
        walls.append(time.perf_counter() - t0)
        finals.append(x[:prob.space.n_u])
    diffs = [float(np.linalg.norm(finals[i] - finals[i + 1])) for i in range(len(steps) - 1)]
    orders = [float(np.log2(diffs[i] / diffs[i + 1])) for i in range(len(diffs) - 1)]
    return dict(steps=list(steps), wall_s=walls, successive_differences=diffs, orders=orders)


def run() -> None:
    """Measure the space and time convergence and write the tables (no options)."""
    out = {"space": {}, "time": {}}
    lines = ["# Convergence (measured by python -m fbmbench convergence)", ""]
    for label, sol, cells in (("2D", Manufactured2D, (4, 8, 16, 32)), ("3D", Manufactured3D, (2, 4, 8))):
        for convection in (False, True):
            name = f"{label} {'Navier-Stokes' if convection else 'Stokes'}"
            rows, orders = space_convergence(sol, cells, convection)
            out["space"][name] = dict(rows=rows, orders=orders)
            lines += [f"## {name} (manufactured solution, unit box)", "",
                      "| cells/axis | unknowns | Newton its | wall s | u L2 | u H1 | p L2 |",
                      "|---|---|---|---|---|---|---|"]
            lines += [f"| {r['cells']} | {r['n_dofs']} | {r['newton']} | {r['wall_s']:.2f} | "
                      f"{r['u_l2']:.3e} | "
                      f"{r['u_h1']:.3e} | {r['p_l2']:.3e} |" for r in rows]
            lines += ["", f"Fitted orders: u L2 {orders['u_l2']:.2f}, u H1 {orders['u_h1']:.2f}, "
                      f"p L2 {orders['p_l2']:.2f}", ""]
            print(name, {k: round(v, 2) for k, v in orders.items()}, flush=True)
    lines += ["## Time order (Taylor–Green, nu = 0.05, T = 0.4, 8x8 cells)", "",
              "| scheme | steps | wall s | |u_dt - u_dt/2| | order |", "|---|---|---|---|---|"]
    for scheme in TIME_SCHEMES:
        r = time_convergence(scheme)
        out["time"][scheme] = r
        for i, n in enumerate(r["steps"][:-1]):
            order = f"{r['orders'][i - 1]:.2f}" if i >= 1 else ""
            lines.append(f"| {scheme} | {n} | {r['wall_s'][i]:.2f} | "
                         f"{r['successive_differences'][i]:.3e} | {order} |")
        print(scheme, [round(o, 2) for o in r["orders"]], flush=True)
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "convergence.json").write_text(json.dumps(out, indent=1))
    (RESULTS / "convergence.md").write_text("\n".join(lines) + "\n")

