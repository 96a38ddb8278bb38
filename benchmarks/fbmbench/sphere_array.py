"""Stokes flow through a simple cubic array of fixed spheres: a 3D sphere whose drag is known
exactly, to test the force estimators of the sharp fictitious boundary per mesh level.

A body force ``f`` along z acts on the fluid (not inside the spheres) of a periodic array of
spheres of diameter ``d`` with spacing ``L``. At steady state the drag on each sphere balances the
force on the fluid of its cell exactly,

    F_exact = f (L^3 - pi d^3 / 6),

whatever the flow: each force estimator's error is its error alone. The flow itself is checked
by the dimensionless drag ``K = f L^3 / (3 pi mu d U)`` (the force of the mean pressure gradient
``f`` on the whole cell: the drag above plus the gradient's push ``f pi d^3 / 6`` on the sphere)
with ``U`` the superficial velocity (flux per cell face area) against Sangani & Acrivos' series
for simple cubic arrays (1982, Hasimoto's leading terms),
``1/K = 1 - 1.7601 c^(1/3) + c - 1.5593 c^2 + 3.9799 c^(8/3) - 3.0734 c^(10/3)``,
``c = pi d^3 / (6 L^3)``. Quarter cell ``[0, L/2]^2 x [0, L]`` (mirror planes through the sphere
centre and midway between spheres, periodic along z), d = 1, L = 2 (c = 0.0654), mu = 1, f = 1;
uniform cells of ``d / n``.

Per mesh: cells per diameter, unknowns, the errors of the volume, test-function and surface forces
against ``F_exact``, ``K`` and its error against the series, wall time (without the JIT warm-up).
Results: ``benchmarks/results/sphere_array.md``, ``.json`` and ``sphere_array-tradeoff.png``.

Unlike the other benchmarks this one is not a scene: it builds the flow problem itself.
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from fbmflow.coupling import (
    FixedObstacles,
    SurfaceForces,
    TestFunctionForces,
    hydrodynamic_forces,
    mirror_images,
    node_owner,
)
from fbmflow.fem.functions import sample_velocity
from fbmflow.fem.quadrature import gauss_tensor
from fbmflow.flow import NavierStokesProblem, Slip
from fbmflow.mesh import StructuredMesh
from fbmflow.particles import Ball
from fbmflow.solvers import DirectSolver

from .common import (
    BENCHMARKS,
    RESULTS,
    RunFailed,
    cpu,
    merge_row,
    monitored,
    overlap,
    provenance,
    tradeoff_plot,
    write_text,
)

D, L, MU, F = 1.0, 2.0, 1.0, 1.0


def series_K(c: float) -> float:
    """Sangani & Acrivos (1982): dimensionless drag of a simple cubic array at volume fraction c."""
    return 1.0 / (
        1 - 1.7601 * c ** (1 / 3) + c - 1.5593 * c**2 + 3.9799 * c ** (8 / 3) - 3.0734 * c ** (10 / 3)
    )


def solve(cells: int) -> dict:
    """Steady Stokes flow on the quarter cell with ``cells`` per diameter; forces, flux, K."""
    n = int(round(cells * L / (2 * D)))
    mesh = StructuredMesh.box((n, n, 2 * n), upper=(L / 2, L / 2, L), periodic=(False, False, True))
    centre = np.array([[0.0, 0.0, L / 2]])
    ball = Ball(D / 2, 3)

    def body_force(x, t):  # on the fluid only
        out = np.zeros_like(x)
        out[:, 2] = F * (np.linalg.norm(x - centre[0], axis=1) > D / 2)
        return out

    problem = NavierStokesProblem(
        mesh,
        MU,
        {tag: Slip() for tag in ("xmin", "xmax", "ymin", "ymax")},
        body_force=body_force,
        convection=False,
        linear_solver=DirectSolver(),
        extra_constraints=FixedObstacles([ball], centre, "sharp"),
    )
    x, _ = problem.solve_steady()
    space = problem.space
    u, p = x[: space.n_u], x[space.n_u :]
    owner = node_owner(space.V, centre, [ball])
    volume = mirror_images(*hydrodynamic_forces(space, owner, centre, u, p, MU), (0, 1))[0][0, 2]
    walls = problem.constraints().fixed
    tested = mirror_images(
        *TestFunctionForces(space, owner, centre, [ball], walls=walls[walls < space.n_v])(u, p, MU, 1.0),
        (0, 1),
    )[0][0, 2]
    surface = mirror_images(*SurfaceForces(space, centre, [ball])(u, p, MU), (0, 1))[0][0, 2]
    # flux through z = 0 (no sphere there): Gauss rule on the face cells, exact for Q2
    g, w = gauss_tensor(2, 3)  # on [-1, 1]^2
    edges = np.linspace(0.0, L / 2, n + 1)
    lo = np.stack(np.meshgrid(edges[:-1], edges[:-1], indexing="ij"), -1).reshape(-1, 2)
    h = L / 2 / n
    pts = (lo[:, None, :] + h * (g[None, :, :] + 1) / 2).reshape(-1, 2)
    uz = sample_velocity(space, u, np.column_stack([pts, np.zeros(len(pts))]))[:, 2]
    flux = 4 * (h / 2) ** 2 * np.sum(uz * np.tile(w, len(lo)))  # four quarters
    exact = F * (L**3 - np.pi * D**3 / 6)
    superficial = flux / L**2
    c = np.pi * D**3 / (6 * L**3)
    K = F * L**3 / (3 * np.pi * MU * D * superficial)
    return dict(
        cells_per_diameter=cells,
        n_dofs=problem.n_dofs,
        exact=exact,
        volume=volume,
        test_function=tested,
        surface=surface,
        volume_error=volume / exact - 1,
        test_function_error=tested / exact - 1,
        surface_error=surface / exact - 1,
        K=K,
        K_series=series_K(c),
        K_error=K / series_K(c) - 1,
    )


def child(cells: int, path: str) -> None:
    """In a child process: a JIT warm-up, then the timed solve; the row as JSON into ``path``."""
    solve(2)
    t0 = time.perf_counter()
    row = solve(cells)
    row["wall_s"] = time.perf_counter() - t0
    row["end"] = time.time()
    Path(path).write_text(json.dumps(row))


def run(cells: int) -> dict:
    """The row of ``cells`` per diameter: solved in a child process (after a JIT warm-up there),
    its wall time less the time that process was stopped by other jobs."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "row.json"
        code = (
            f"import sys; sys.path.insert(0, {str(BENCHMARKS)!r}); "
            f"from fbmbench.sphere_array import child; child({cells}, {str(path)!r})"
        )
        status, intervals, cpu = monitored([sys.executable, "-c", code])
        if status != 0 or not path.is_file():
            raise RunFailed(f"sphere array at {cells} cells/d exited with status {status}")
        row = json.loads(path.read_text())
    end = row.pop("end")
    row["stopped_s"] = overlap(intervals, end - row["wall_s"], end)
    row["wall_s"] -= row["stopped_s"]
    row["cpu_s"] = cpu
    row.update(provenance())
    print(
        f"sphere array {cells} cells/d, {row['n_dofs']} unknowns: "
        f"volume force {100 * row['volume_error']:+.2f} %, "
        f"test function {100 * row['test_function_error']:+.2f} %, "
        f"surface {100 * row['surface_error']:+.2f} %, "
        f"K {row['K']:.4f} ({100 * row['K_error']:+.2f} %), {row['wall_s']:.1f} s",
        flush=True,
    )
    return row


def record(row: dict) -> list[dict]:
    rows = merge_row("sphere_array", row, lambda a, b: a["cells_per_diameter"] == b["cells_per_diameter"])
    write(rows)
    return rows


def write(rows: list[dict]) -> None:
    rows = sorted(rows, key=lambda r: r["cells_per_diameter"])
    lines = [
        "# Stokes flow through a simple cubic array of spheres, sharp boundary (sphere_array)",
        "",
        f"d = {D}, spacing L = {L} (volume fraction {np.pi * D**3 / (6 * L**3):.4f}), mu = {MU}, "
        f"body force {F} "
        "on the fluid along z; quarter cell, uniform mesh, direct solver. Force errors against the "
        "exact drag "
        "f (L^3 - pi d^3/6); K = f L^3 / (3 pi mu d U) from the superficial velocity U against Sangani & "
        "Acrivos' series. Wall time on a 2-core machine without the JIT warm-up. Reproduce a row: "
        "`python -m fbmbench sphere_array --cells N`, or `python -m pytest benchmarks -k sphere`.",
        "",
        "| cells/d | unknowns | volume force error | test-function force error | surface force error "
        "| K | K error "
        "| wall s | CPU s | measured |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    lines += [
        f"| {r['cells_per_diameter']} | {r['n_dofs']} | {100 * r['volume_error']:+.2f} % | "
        f"{100 * r['test_function_error']:+.2f} % | {100 * r['surface_error']:+.2f} % | {r['K']:.4f} | "
        f"{100 * r['K_error']:+.2f} % | {r['wall_s']:.1f} | {cpu(r)} | "
        f"{r.get('date', 'earlier session')} "
        f"{r.get('commit', '')} |"
        for r in rows
    ]
    write_text(RESULTS / "sphere_array.md", "\n".join(lines) + "\n")
    curves = {
        name: [(r["wall_s"], abs(r[key]), f"{r['cells_per_diameter']}/d") for r in rows]
        for name, key in (
            ("volume force", "volume_error"),
            ("test-function force", "test_function_error"),
            ("surface traction", "surface_error"),
            ("K (flux)", "K_error"),
        )
    }
    tradeoff_plot(
        RESULTS / "sphere_array-tradeoff.png",
        curves,
        "|relative error|",
        "Sphere array: drag estimators against cost (labels: cells per diameter)",
    )
