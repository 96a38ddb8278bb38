"""The lubrication correction against exact Stokes solutions: a sphere approaching a plane wall,
and two equal spheres approaching each other (Brenner 1961, :mod:`fbmflow.scenes.data.brenner1961`).

A sphere of radius a = 1 moves at U = 1 towards the plane z = 0 through fluid of viscosity 1
(quasi-steady Stokes flow, sharp fictitious boundary, :class:`~fbmflow.coupling.FixedObstacles`
with the sphere's velocity). The plane is a no-slip wall (``wall = "rigid"``) or a mirror plane
(``"free"``), which is the flow of two spheres approaching each other with surface gap 2h.
Quarter domain ``[0, R] x [0, R] x [0, h + 2.5 a + R]`` with mirror planes x = y = 0 through
the sphere's centre and no-slip far walls. They raise the drag (at h / a = 10 and 4 cells/d,
R = 20 a gives 1.4 % more than R = 40 a; at h / a = 1, 0.01 %): each flow is solved with
R = 20 a and 40 a and the drag extrapolated to R -> infinity, linearly in 1 / R (the far walls'
reflection is of order a / R). Cells of 2a / n (n cells per diameter) from the
plane (or from a radius below the sphere, for gaps above a radius) to half a radius above the
sphere and within 1.5 a of its axis, growing by 1.3 per cell beyond.

Per gap h / a: the resolved drag factor ``lambda_flow = F / (6 pi mu a U)`` of the volume force
(the estimator the particle dynamics use), the correction of :class:`~fbmflow.contact.Lubrication`
with the given range and cut-off (``c(g) U / (6 pi mu a U)``; the spheres: gap 2h, relative speed
2U), their sum, and the error against Brenner's series.
Results: ``benchmarks/results/lubrication.md``, ``.json`` and ``lubrication.png``.
"""

from __future__ import annotations

import time

import numpy as np

from fbmflow.contact import Lubrication
from fbmflow.contact.lubrication import BLEND_EXPONENT
from fbmflow.coupling import FixedObstacles, hydrodynamic_forces, mirror_images, node_owner
from fbmflow.flow import NavierStokesProblem, NoSlip, Slip
from fbmflow.mesh import StructuredMesh, graded_axis
from fbmflow.particles import Ball
from fbmflow.scenes.data.brenner1961 import drag_factor
from fbmflow.solvers import NewtonSettings

from .common import RESULTS, load_rows, merge_row, provenance, write_text

A, MU, U = 1.0, 1.0, 1.0
FAR = (20.0, 40.0)  # distances R of the far walls, the drag extrapolated from both to R = infinity
GAPS = (10.0, 3.0, 1.0, 0.5, 0.2, 0.1, 0.05, 0.02, 0.01)


def mesh(cells: int, gap: float, far: float) -> StructuredMesh:
    """The quarter domain for gap ``gap`` (h / a) with ``cells`` per diameter near the sphere and
    the far walls ``far`` away."""
    h = 2 * A / cells
    side = graded_axis(0.0, far, (0.0, 1.5 * A), h, multiple=8)
    fine = (max(0.0, gap - A), gap + 2.5 * A)  # from the plane (or a radius below the sphere) up
    return StructuredMesh.rectilinear([side, side, graded_axis(0.0, fine[1] + far, fine, h, multiple=8)])


def _drag_factor(m: StructuredMesh, centres: np.ndarray, velocities, bc: dict, linear_solver: str
                 ) -> tuple[float, int]:
    """Quasi-steady Stokes flow on the quarter mesh ``m`` (mirror planes x = y = 0, the rest as
    ``bc`` says) of spheres of radius a at ``centres`` moving at ``velocities``: the drag factor
    ``F_z / (6 pi mu a U)`` of the last sphere's volume force (whole sphere; it moves downwards, so
    the drag points up), and the unknowns."""
    balls = [Ball(A, 3)] * len(centres)
    bc = {**{tag: NoSlip() for tag in m.tags}, "xmin": Slip(), "ymin": Slip(), **bc}
    problem = NavierStokesProblem(m, MU, bc, convection=False, linear_solver=linear_solver,
                                  newton=NewtonSettings(rtol=1e-6, linear_rtol=1e-3),
                                  extra_constraints=FixedObstacles(balls, centres, "sharp",
                                                                   velocities=velocities))
    x, _ = problem.solve_steady()
    space = problem.space
    owner = node_owner(space.V, centres, balls)
    force = mirror_images(*hydrodynamic_forces(space, owner, centres, x[:space.n_u], x[space.n_u:], MU),
                          (0, 1))[0][-1, 2]
    return float(force / (6 * np.pi * MU * A * U)), problem.n_dofs


def drag(cells: int, gap: float, wall: str, far: float, linear_solver: str = "auto") -> tuple[float, int]:
    """Quasi-steady Stokes flow of the sphere at gap ``gap`` moving at U towards the plane, with
    the far walls ``far`` away: the drag factor of its volume force, and the unknowns."""
    return _drag_factor(mesh(cells, gap, far), np.array([[0.0, 0.0, A + gap]]), [[0.0, 0.0, -U]],
                        {"zmin": Slip()} if wall == "free" else {}, linear_solver)


def resolved(cells: int, gap: float, wall: str, linear_solver: str = "auto") -> dict:
    """``lambda_flow``: the drag factor extrapolated to far walls at infinity from the two
    :data:`FAR`; the drag factors there, the unknowns of the larger box and the wall time of both
    solves."""
    t0 = time.perf_counter()
    (near, _), (far, n_dofs) = (drag(cells, gap, wall, R, linear_solver) for R in FAR)
    r0, r1 = FAR
    return {"lambda_flow": (far * r1 - near * r0) / (r1 - r0), "lambda_walls": [near, far], "n_dofs": n_dofs,
            "wall_s": time.perf_counter() - t0}


def pair_drag(cells: int, gap: float, offset: float, far: float, linear_solver: str = "auto") -> float:
    """Two spheres, both fictitious boundaries, at surface gap ``2 gap`` (h / a) approaching each
    other at U each, their midplane ``offset`` cells above a mesh plane (0: the mirror set-up's
    mesh): the drag factor of the upper sphere's volume force, far walls ``far`` away."""
    h = 2 * A / cells
    side = graded_axis(0.0, far, (0.0, 1.5 * A), h, multiple=8)
    reach = gap + 2.5 * A
    axis = graded_axis(-reach - far, reach + far, (-reach, reach), h, multiple=8)
    mid = axis[np.argmin(np.abs(axis))] + offset * h  # a vertex near z = 0, shifted
    centres = np.array([[0.0, 0.0, mid - A - gap], [0.0, 0.0, mid + A + gap]])
    return _drag_factor(StructuredMesh.rectilinear([side, side, axis]), centres,
                        [[0.0, 0.0, U], [0.0, 0.0, -U]], {}, linear_solver)[0]


def correction(gap, cells: int, wall: str, model: dict) -> np.ndarray:
    """The lubrication correction's drag factor at gaps ``gap`` (h / a) for a mesh of ``cells``
    per diameter; ``model``: ``range``, ``min_gap`` and ``resolved`` gaps counted in cells."""
    h = 2 * A / cells
    lub = Lubrication(MU, model["range"] * h, model["min_gap"] * h, model["resolved"] * h)
    gap = np.asarray(gap, dtype=float)
    if wall == "rigid":
        c, speed = lub.coefficient(gap * A, np.full(gap.shape, A), np.full(gap.shape, np.inf), 3), U
    else:  # two spheres ("free", "pair"): surface gap 2h, relative speed 2U
        c, speed = lub.coefficient(2 * gap * A, np.full(gap.shape, A), np.full(gap.shape, A), 3), 2 * U
    return c * speed / (6 * np.pi * MU * A * U)


def run(cells: int, wall: str, gaps=GAPS, linear_solver: str = "auto") -> list[dict]:
    """Rows (one per gap) of ``lambda_flow`` and Brenner's ``lambda``; a small JIT warm-up first."""
    drag(2, 1.0, wall, FAR[0], linear_solver)
    rows = []
    for gap in gaps:
        row = {"wall": wall, "cells_per_diameter": cells, "gap": gap,
               "lambda_exact": float(drag_factor(gap, wall)), **resolved(cells, gap, wall, linear_solver),
               **provenance()}
        print(f"{wall} wall, {cells} cells/d, h/a = {gap}: lambda_flow {row['lambda_flow']:.4f}, "
              f"Brenner {row['lambda_exact']:.4f}, {row['n_dofs']} unknowns, {row['wall_s']:.1f} s",
              flush=True)
        rows.append(row)
    return rows


def run_pairs(cells: int, gaps, offsets) -> list[dict]:
    """Rows of two fictitious spheres (:func:`pair_drag`, far walls at the larger :data:`FAR`;
    the extrapolation changes them by 0.1 % at h / a = 0.1) per gap and midplane offset, against
    Brenner's free-surface series."""
    rows = []
    for gap in gaps:
        for offset in offsets:
            t0 = time.perf_counter()
            lam = pair_drag(cells, gap, offset, FAR[1])
            row = {"wall": "pair", "cells_per_diameter": cells, "gap": gap, "offset": offset,
                   "lambda_exact": float(drag_factor(gap, "free")), "lambda_flow": lam, "n_dofs": 0,
                   "wall_s": time.perf_counter() - t0, **provenance()}
            print(f"two spheres, {cells} cells/d, h/a = {gap}, midplane {offset} cells off a mesh plane: "
                  f"lambda_flow {lam:.4f}, Brenner {row['lambda_exact']:.4f}, {row['wall_s']:.1f} s",
                  flush=True)
            rows.append(row)
    return rows


def record(rows: list[dict], model: dict) -> list[dict]:
    """Merge ``rows`` into ``lubrication.json``; redraw the table and plot with ``model``."""
    table = load_rows("lubrication")
    for row in rows:
        table = merge_row("lubrication", row, lambda a, b: all(a.get(k) == b.get(k) for k in (
            "wall", "cells_per_diameter", "gap", "offset")))
    write(table, model)
    return table


def label(row: dict) -> str:
    """'rigid', 'free' (the mirror set-ups) or 'pair, midplane +0.5' (two fictitious spheres)."""
    return f"pair, midplane {row['offset']:+g}" if row["wall"] == "pair" else row["wall"]


def write(rows: list[dict], model: dict) -> None:
    rows = sorted(rows, key=lambda r: (r["wall"], r["cells_per_diameter"], -r["gap"], r.get("offset", 0)))
    lines = [
        "# Lubrication: a sphere approaching a wall, two spheres approaching each other (lubrication)",
        "",
        "Quasi-steady Stokes drag factor lambda = F / (6 pi mu a U) of the resolved flow (sharp boundary, "
        "volume force) and with the lubrication correction (range "
        f"{model['range']} cells, cut-off {model['min_gap']} cells, resolved gap {model['resolved']} cells, "
        f"effective gap (g^p + s^p)^(1/p) with p = {BLEND_EXPONENT}) "
        "against Brenner's (1961) series: 'rigid' "
        "is the no-slip wall at gap h, 'free' the mirror plane of two equal spheres at surface gap 2h, "
        "'pair' two fictitious spheres at surface gap 2h whose midplane lies the given cells above a mesh "
        "plane (far walls at 40a, not extrapolated; unknowns not recorded). "
        "Reproduce: `python -m fbmbench lubrication` (see `--help`).",
        "",
        "| wall | cells/d | h/a | Brenner | resolved | error | with correction | error | unknowns | wall s "
        "| measured |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        total = r["lambda_flow"] + correction(r["gap"], r["cells_per_diameter"], r["wall"], model)
        lines.append(
            f"| {label(r)} | {r['cells_per_diameter']} | {r['gap']:g} | {r['lambda_exact']:.4f} | "
            f"{r['lambda_flow']:.4f} | {100 * (r['lambda_flow'] / r['lambda_exact'] - 1):+.1f} % | "
            f"{total:.4f} | {100 * (total / r['lambda_exact'] - 1):+.1f} % | {r['n_dofs']} | "
            f"{r['wall_s']:.1f} | {r.get('date', '')} {r.get('commit', '')} |")
    write_text(RESULTS / "lubrication.md", "\n".join(lines) + "\n")
    plot(rows, model)


def plot(rows: list[dict], model: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.3), sharey=False)
    fine = np.geomspace(0.005, 20, 200)
    for ax, wall in zip(axes, ("rigid", "free")):
        ax.loglog(fine, drag_factor(fine, wall), "k-", label="Brenner (1961)")
        for n in sorted({r["cells_per_diameter"] for r in rows if r["wall"] == wall}):
            sel = [r for r in rows if r["wall"] == wall and r["cells_per_diameter"] == n]
            g = np.array([r["gap"] for r in sel])
            lam = np.array([r["lambda_flow"] for r in sel])
            line, = ax.loglog(g, lam + correction(g, n, wall, model), "o-",
                              label=f"{n} cells/d, with correction")
            ax.loglog(g, lam, "x:", color=line.get_color(), label=f"{n} cells/d, resolved flow")
        pairs = [r for r in rows if r["wall"] == "pair"] if wall == "free" else []
        if pairs:
            g = np.array([r["gap"] for r in pairs])
            lam = np.array([r["lambda_flow"] for r in pairs])
            total = lam + np.array([correction(r["gap"], r["cells_per_diameter"], "pair", model)
                                    for r in pairs])
            ax.loglog(g, total, "k^", mfc="none", label="two fictitious spheres, with correction")
        ax.set_xlabel("gap h / a")
        ax.set_ylabel("F / (6 pi mu a U)")
        ax.set_title("sphere towards a wall" if wall == "rigid" else "two spheres (gap 2h)")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(RESULTS / "lubrication.png", dpi=120)
    plt.close(fig)
