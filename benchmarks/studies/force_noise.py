"""Force noise of the fictitious boundary: a disk / sphere dragged at constant velocity through a
uniform mesh.

Question: how much does the drag of a particle dragged at constant velocity in Stokes flow
fluctuate as it slides across one cell (discretisation noise), per boundary and resolution?
Answer: rms/mean of the drag for the disk 0.30 / 0.065 / 0.012 % (sharp boundary) and 1.01 /
0.28 / 0.13 % (nodal) at 6 / 12 / 24 cells/d; for the sphere (graded mesh, 8 positions) 0.33 /
0.094 % (sharp) and 1.47 / 0.24 % (nodal) at 6 / 12 cells/d: the sharp boundary meets the < 1 %
target from 6 cells/d, the nodal one from 12 (benchmarks/results/force_noise_*.md).
Measured: 2026-11-24, commit fe24c28; quoted in docs/validation/force-noise.md
Run: python -m fbmbench force_noise --dims 3 --cells 6 12 --shifts 8 --graded --boundary sharp

The 2D rows: ``python -m fbmbench force_noise --dims 2 --cells 6 12 24 [--boundary sharp]``.

In the Stokes limit the drag of a particle moving at constant velocity U through fluid at rest
is steady, so every change of the computed drag as the particle slides across the fixed mesh is
discretisation noise. For each resolution the particle (d = 1) is placed at ``shifts`` equally
spaced positions across one cell (plus an irrational offset so that no position is special), the
steady Stokes problem with ``u = U`` on the particle's nodes and no-slip walls is solved, and the
drag is evaluated by the volume integral. Reported: mean drag, rms of its fluctuation over the
mean, max - min over the mean, unknowns and wall time (direct solver; 3D uses the quarter domain
with two mirror planes through the centre, forces of the whole sphere). ``--boundary sharp``: the
sharp fictitious boundary (docs/method.md) instead of the nodal one. With ``--graded`` the mesh
is uniform only within two cells of the particle's path and grows by 1.3 per cell towards the
walls (a rectilinear mesh): the noise comes from the cut cells, the far field sets the mean.
Writes ``benchmarks/results/force_noise_<dims>d[_graded][_sharp].md`` and ``.json``.
"""
from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Literal

import numpy as np

from fbmflow.coupling import (
    hydrodynamic_forces,
    mirror_images,
    node_owner,
    rigid_body_constraints,
    sharp_boundary,
)
from fbmflow.flow import NavierStokesProblem, NoSlip, Slip
from fbmflow.mesh import StructuredMesh, graded_axis
from fbmflow.particles import Ball
from fbmflow.solvers import DirectSolver

RESULTS = Path(__file__).resolve().parents[1] / "results"
HALF = {2: 3.0, 3: 1.5}  # half-width of the box in diameters (2D: 6 d x 6 d; 3D quarter: 3 x 1.5 x 1.5 d)


def box_mesh(dim: int, cells_per_d: int, graded: bool) -> StructuredMesh:
    """The box about the particle (2D whole, 3D quarter with y, z >= 0); uniform, or graded
    outside the zone the particle (d = 1) sweeps plus two cells."""
    half, h = HALF[dim], 1.0 / cells_per_d
    lower = (-half, -half) if dim == 2 else (-half, 0.0, 0.0)
    if not graded:
        n = int(2 * half * cells_per_d)
        return StructuredMesh.box((n, n) if dim == 2 else (n, n // 2, n // 2), lower=lower,
                                  upper=(half,) * dim)
    def zone(a, b):  # whole cells of size h, an even number of them (nested coarsening)
        a, b = np.floor(a / h + 1e-9) * h, np.ceil(b / h - 1e-9) * h
        return (a, b + h) if round((b - a) / h) % 2 else (a, b)

    reach = 0.5 + 2 * h  # the sphere's surface plus two cells; it moves by one cell along x
    axes = [graded_axis(-half, half, zone(-reach, reach + h), h)]
    axes += [graded_axis(lo, half, zone(max(lo, -reach), reach), h) for lo in lower[1:]]
    return StructuredMesh.rectilinear(axes)


def drag_samples(dim: int, cells_per_d: int, shifts: int, graded: bool = False, boundary: str = "nodes"):
    mesh = box_mesh(dim, cells_per_d, graded)
    if dim == 2:
        symmetry, bc = (), {t: NoSlip() for t in ("xmin", "xmax", "ymin", "ymax")}
    else:  # quarter: mirror planes y = 0 and z = 0 through the centre, motion along x
        symmetry = (1, 2)
        bc = {t: NoSlip() for t in mesh.tags}
        bc["ymin"] = bc["zmin"] = Slip()
    h = 1.0 / cells_per_d
    shape = Ball(0.5, dim)
    U = np.zeros((1, dim))
    U[0, 0] = 1.0
    omega = np.zeros(1) if dim == 2 else np.zeros((1, 3))
    drags, walls = [], []
    for k in range(shifts):
        centre = np.zeros((1, dim))
        centre[0, 0] = (k / shifts + 0.1234) * h
        if dim == 2:
            centre[0, 1] = 0.1 * np.sqrt(2.0) * h  # off the mesh lines in y as well

        flow = None  # the problem below (the sharp boundary needs its space)

        def constraints(V, t, centre=centre):
            owner = node_owner(V, centre, [shape])
            rigid = rigid_body_constraints(V, owner, centre, U, omega)
            if boundary == "nodes":
                return rigid
            return sharp_boundary(flow.space, owner, centre, [shape]).constraints(rigid, U, omega)

        flow = NavierStokesProblem(mesh, 1.0, bc, convection=False, linear_solver=DirectSolver(),
                                   extra_constraints=constraints)
        t0 = time.perf_counter()
        x, _ = flow.solve_steady()
        walls.append(time.perf_counter() - t0)
        s = flow.space
        F, T = hydrodynamic_forces(s, node_owner(s.V, centre, [shape]), centre, x[:s.n_u], x[s.n_u:], 1.0)
        if symmetry:
            F, T = mirror_images(F, T, symmetry)
        drags.append(-F[0, 0])
    return np.array(drags), flow.n_dofs, float(np.sum(walls)), flow.linear_solver_description


def run(*, dims: list[int] = (2,), cells: list[int] = (6, 12, 24), shifts: int = 16, graded: bool = False,
        boundary: Literal["nodes", "sharp"] = "nodes") -> None:
    """Drag samples per dimension and resolution; writes the table.

    Parameters
    ----------
    dims : space dimensions to run (2 and/or 3)
    cells : cells per diameter
    shifts : positions of the particle across one cell
    graded : uniform near the particle only
    boundary : fictitious boundary
    """
    drag_samples(2, 2, 1)  # JIT warm-up
    rows = []
    for dim in dims:
        for c in cells:
            drag, n_dofs, wall, solver = drag_samples(dim, c, shifts, graded, boundary)
            mean = float(drag.mean())
            row = dict(dim=dim, cells_per_diameter=c, n_dofs=n_dofs, shifts=shifts, wall_s=wall,
                       linear_solver=solver, mean_drag=mean, rms_over_mean=float(drag.std() / mean),
                       range_over_mean=float(np.ptp(drag) / mean), drag=drag.tolist())
            rows.append(row)
            print(f"{dim}D {c} cells/d: {n_dofs} unknowns, {wall:.1f} s, drag {mean:.4f}, "
                  f"rms/mean {100 * row['rms_over_mean']:.3f} %, "
                  f"range/mean {100 * row['range_over_mean']:.3f} %",
                  flush=True)
    RESULTS.mkdir(exist_ok=True)
    tag = ("".join(str(d) for d in dims) + ("d_graded" if graded else "d")
           + ("_sharp" if boundary == "sharp" else ""))
    (RESULTS / f"force_noise_{tag}.json").write_text(json.dumps(rows, indent=1))
    lines = ["# Force noise of a dragged particle (python -m fbmbench force_noise)", "",
             f"Stokes flow, d = 1, U = 1, mu = 1, box {2 * HALF[2]:g} d (2D) / {2 * HALF[3]:g} d (3D) wide, "
             f"{shifts} positions across one cell"
             + (", mesh uniform within two cells of the particle and graded (1.3 per cell) beyond. "
                if graded else ", uniform mesh. ")
             + f"{boundary.capitalize()} fictitious boundary. Linear solver: "
             + " / ".join(sorted({r["linear_solver"] for r in rows})) + ". "
             "Target: rms/mean below 1 % at 12 cells/d "
             "(the established FEM-FBM code reports 3.8 % at 11).", "",
             "| dim | cells/d | unknowns | wall s (all positions) | mean drag | rms / mean "
             "| (max - min) / mean |",
             "|---|---|---|---|---|---|---|"]
    lines += [f"| {r['dim']}D | {r['cells_per_diameter']} | {r['n_dofs']} | {r['wall_s']:.1f} | "
              f"{r['mean_drag']:.4f} | "
              f"{100 * r['rms_over_mean']:.3f} % | {100 * r['range_over_mean']:.3f} % |" for r in rows]
    (RESULTS / f"force_noise_{tag}.md").write_text("\n".join(lines) + "\n")
