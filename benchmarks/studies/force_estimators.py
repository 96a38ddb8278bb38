"""How consistent is the flow around a settling sphere with its hydrodynamic force? Three
estimators of the force on one flow field of a ten-cate run.

Question: do the cut-cell volume force and a momentum balance tested with a function moving with
the sphere agree on the force of one flow field of ten Cate's E4 near terminal velocity?
Answer: no: on the level-1 flow (6 cells/d) at t = 0.95 / 1.00 s the volume force is within
+0.7 / +3.5 % of the net weight (the step's own force -0.4 / +1.8 %), the moving test function
gives +23 to +28 % (+23.5 to +23.8 % with dI/dt from one more step) and the lab-frame variant
-13.6 to -16.6 %: at 6 cells/d the flow next to the moving surface is not resolved well enough
for any of them to be exact (benchmarks/results/force_estimators.md).
Measured: 2026-11-24, commit 00345b4; quoted in docs/validation/ten-cate-e1-e4.md
Run: python -m fbmbench force_estimators CHECKPOINT --step

``CHECKPOINT``: a ``checkpoint.h5`` of ``ten-cate`` (e.g. from ``python -m fbmbench
tencate --cases E4 --levels 1 --checkpoint-every 5``, in
``out/bench/ten-cate-level1-fluid.case=E4-time.dt=0.01/``; runs from before the pytest suite kept
theirs in ``out/bench-tencate/``). Evaluated on its flow:

* the **volume force** over the cut cells (what the particle dynamics use by default), of the
  step that computed the flow ('dynamics') and of the stored flow itself, whose ghost nodes that
  the particle uncovered carry its rigid velocity ('volume');
* the momentum balance tested with a smooth function ``psi(x - X(t))`` that **moves with the
  particle**: one up to a distance ``a`` from the surface, falling to zero at ``b`` (quintic
  smoothstep of the distance), for several bands ``(a, b)``:

      F = -int_fluid [sigma grad psi + rho psi (u . grad) u + rho (U . grad psi) u] dx - dI/dt,
      I = int_fluid rho psi u dx,

  exact for any such ``psi`` for the continuous flow (Reynolds' transport theorem; the surface
  term vanishes for a rigid motion about the centre of mass). ``dI/dt`` needs a second flow and
  is left out without ``--step`` (near terminal velocity it is small).

With ``--step`` one more time step is solved (minutes at level 1) and the step's
``-int rho psi du/dt`` compares in the lab frame (the mesh's ``(u - u_old) / dt``, ``psi`` at the
step's mid position) and in the moving frame (``dI/dt`` plus the transport term averaged over
the step): for a converged flow the two agree.

Near terminal velocity the hydrodynamic force balances the net weight ``(rho_s - rho_f) V g``;
every estimator is reported against it. Writes ``benchmarks/results/force_estimators.md`` and
``.json`` (one entry per checkpoint time, replaced when run again).
"""
from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from fbmflow.config import from_dict
from fbmflow.coupling import TestFunctionForces, mirror_images
from fbmflow.io import load_checkpoint
from fbmflow.scenes.tencate import TenCate, TenCateParams

RESULTS = Path(__file__).resolve().parents[1] / "results"
BANDS = ((0.5, 2.5), (1.0, 3.0), (np.sqrt(3.0), np.sqrt(3.0) + 2.0), (2.0, 5.0))  # (a, b) in cells


class MovingTestFunction(TestFunctionForces):
    """The tested momentum balance with ``psi(s)``, ``s`` the distance from the particle's surface
    (by the shape's ``project``): 1 for ``s <= a``, ``1 - (10 t^3 - 15 t^4 + 6 t^5)`` with
    ``t = (s - a) / (b - a)`` up to ``s = b`` [m], on every cell within ``b`` of a particle
    (tensor-product meshes, particles away from periodic sides)."""

    def __init__(self, space, centres: np.ndarray, shapes: list, a: float, b: float, n_1d: int = 8):
        mesh = space.mesh
        corners = mesh.vertices[mesh.cell_vertices]
        lo, hi = corners.min(axis=1), corners.max(axis=1)
        cells, body = [], []
        for i, (X, shape) in enumerate(zip(centres, shapes)):
            near = np.flatnonzero(np.linalg.norm(np.clip(X, lo, hi) - X, axis=1) < shape.bounding_radius + b)
            cells.append(near)
            body.append(np.full(near.size, i))
        self._quadrature(space, np.concatenate(cells), np.concatenate(body), centres, shapes, None, n_1d)
        m, nq, d = self.rel.shape
        s, normal = np.empty((m, nq)), np.empty((m, nq, d))
        for i, shape in enumerate(shapes):
            rows = self.body == i
            surface, n_out = shape.project(self.rel[rows].reshape(-1, d))
            normal[rows] = n_out.reshape(-1, nq, d)
            s[rows] = np.einsum("kd,kd->k", self.rel[rows].reshape(-1, d) - surface, n_out).reshape(-1, nq)
        t = np.clip((s - a) / (b - a), 0.0, 1.0)
        self.psi_q = 1.0 - (10 * t**3 - 15 * t**4 + 6 * t**5)
        self.grad_psi = (-(30 * t**2 - 60 * t**3 + 30 * t**4) / (b - a))[..., None] * normal

    def transport(self, u: np.ndarray, rho: float, velocities: np.ndarray) -> np.ndarray:
        """``-int rho (U_i . grad psi_i) u dx`` per particle, (n, dim)."""
        uq = self._velocity(u)[0]
        f = -rho * np.einsum("ck,cqk->cq", velocities[self.body], self.grad_psi)[..., None] * uq
        return self._sum(f)

    def momentum(self, u: np.ndarray, rho: float) -> np.ndarray:
        """``I_i = int rho psi_i u dx`` per particle, (n, dim)."""
        return self._sum(rho * self.psi_q[..., None] * self._velocity(u)[0])

    def _sum(self, f: np.ndarray) -> np.ndarray:
        out = np.zeros((self.n_particles, self.dim))
        np.add.at(out, self.body, (f * self.weight[..., None]).sum(axis=1))
        return out


def whole(force: np.ndarray, sim) -> float:
    """Vertical component of the whole sphere's force (mirror images of the quarter)."""
    return float(mirror_images(force, np.zeros((len(force), 3)), sim.system.symmetry)[0][0, 2])


def run(*, checkpoint: Path, step: bool = False) -> None:
    """Evaluate the estimators on the flow of ``checkpoint``; adds its row to the table.

    Parameters
    ----------
    checkpoint : a checkpoint.h5 of ten-cate
    step : solve one more step for the time terms
    """
    state, meta, _ = load_checkpoint(checkpoint)
    params = from_dict(TenCateParams, meta["params"])
    setup = TenCate().build(params, meta["level"])
    sim = setup.sim
    sim.set_state(state)
    space, rho, mu = sim.flow.space, sim.flow.rho, sim.flow.mu
    n_u, h = space.n_u, float(sim.flow.mesh.finest_spacing.max())
    pp = params.particle
    weight = (pp.density - rho) * np.pi / 6 * pp.diameter**3 * params.fluid.gravity
    p0 = sim.particles.copy()
    x0 = sim.x.copy()
    row = {"case": params.fluid.case, "level": meta["level"], "t": sim.t,
           "cells_per_diameter": pp.diameter / h, "velocity": float(-p0.velocity[0, 2]), "net_weight": weight,
           "volume": float(sim.system.forces(x0, setup.dt)[0][0, 2]),  # whole sphere
           "dynamics": float(state["last_force"][0, 2]), "bands": []}
    tested = [MovingTestFunction(space, p0.position, p0.shapes, a * h, b * h) for a, b in BANDS]
    for (a, b), T in zip(BANDS, tested):
        stress = whole(T(x0[:n_u], x0[n_u:], mu, rho)[0], sim)
        transport = whole(T.transport(x0[:n_u], rho, p0.velocity), sim)
        row["bands"].append({"a_cells": a, "b_cells": b, "stress_convection": stress, "transport": transport,
                             "moving_without_dIdt": stress + transport})
    if step:
        t0 = time.perf_counter()
        sim.step(setup.dt)
        row["step_wall_s"] = time.perf_counter() - t0
        x1, p1 = sim.x, sim.particles
        mid = 0.5 * (p0.position + p1.position)
        for (a, b), T0, entry in zip(BANDS, tested, row["bands"]):
            T1 = MovingTestFunction(space, p1.position, p1.shapes, a * h, b * h)
            Tm = MovingTestFunction(space, mid, p1.shapes, a * h, b * h)
            dIdt = whole((T1.momentum(x1[:n_u], rho) - T0.momentum(x0[:n_u], rho)) / setup.dt, sim)
            transport = 0.5 * (entry["transport"] + whole(T1.transport(x1[:n_u], rho, p1.velocity), sim))
            steady = whole(Tm(x1[:n_u], x1[n_u:], mu, rho)[0], sim)
            lab = whole(Tm(x1[:n_u], x1[n_u:], mu, rho, u_old=x0[:n_u], dt=setup.dt)[0], sim) - steady
            entry.update(dudt_lab=lab, dudt_moving=transport - dIdt, dIdt=dIdt, lab_force=steady + lab,
                         moving_force=whole(T1(x1[:n_u], x1[n_u:], mu, rho)[0], sim)
                         + whole(T1.transport(x1[:n_u], rho, p1.velocity), sim) - dIdt)
    print(json.dumps(row, indent=1))
    write(row)


def pct(force: float, weight: float) -> str:
    """``force`` and its deviation from ``weight``."""
    return f"{force:.4e} ({force / weight - 1:+.1%})"


def write(row: dict) -> None:
    path = RESULTS / "force_estimators.json"
    rows = json.loads(path.read_text()) if path.exists() else []
    rows = [r for r in rows
            if (r["case"], r["level"], round(r["t"], 6)) != (row["case"], row["level"], round(row["t"], 6))]
    rows.append(row)
    path.write_text(json.dumps(rows, indent=1))
    lines = ["# Force estimators on one flow field (python -m fbmbench force_estimators)", "",
             "Vertical hydrodynamic force [N] on the ten-cate sphere from one checkpointed flow, "
             "against the net "
             "weight (rho_s - rho_f) V g that it balances near terminal velocity. "
             "'moving': the momentum balance "
             "tested with psi(x - X(t)), one up to a cells from the surface, zero from b cells; "
             "'lab': the same psi "
             "at the step's mid position with the mesh's (u - u_old)/dt. "
             "The time terms need one more step (--step).",
             "", "| case | level | cells/d | t s | U m/s | net weight | dynamics | volume force "
             "| band a-b cells | moving, no dI/dt "
             "| moving | lab | -int rho psi du/dt moving / lab |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        w = r["net_weight"]
        for b in r["bands"]:
            lines.append(f"| {r['case']} | {r['level']} | {r['cells_per_diameter']:.0f} | {r['t']:.2f} | "
                         f"{r['velocity']:.5f} | {w:.4e} | {pct(r['dynamics'], w)} | {pct(r['volume'], w)} | "
                         f"{b['a_cells']:.2f}-{b['b_cells']:.2f} | "
                         f"{pct(b['moving_without_dIdt'], w)} | "
                         + (f"{pct(b['moving_force'], w)} | {pct(b['lab_force'], w)} | "
                            f"{b['dudt_moving']:.3e} / {b['dudt_lab']:.3e} |"
                            if "lab_force" in b else "- | - | - |"))
    (RESULTS / "force_estimators.md").write_text("\n".join(lines) + "\n")
