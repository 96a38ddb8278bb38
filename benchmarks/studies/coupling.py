"""The coupling schemes against each other (issue 29, item 4): what the stabilised scheme's one
flow solve per step costs in accuracy against the implicit scheme, and what it saves.

Question: how far do the stabilised, Newton-Krylov and explicit couplings deviate from the
implicit scheme's particle velocities, and how much faster are they?
Answer: the stabilised scheme deviates 5.6-13.9 % (one disk) and 4.9-5.2 % from step 6 (100
disks; 0.1-0.2 % at the last step) and is 3.6x (level 1) to 12x (level 2) faster with 100 disks;
the explicit scheme fails at step 7 there. In the dense suspension (24 disks at 0.3) Newton-Krylov
is 1.9x faster at 2.1 % (0.9 % at the last step) where the stabilised scheme fails at step 9
(benchmarks/results/coupling.md).
Measured: 2026-11-27, commit 2456127; quoted in docs/validation/many-particles.md, "The stabilised coupling"
(the dense suspension in "The Newton–Krylov coupling")
Run: python -m fbmbench coupling

The dense suspension alone: ``python -m fbmbench coupling --cases suspension-dense``.

Cases (scene defaults but for the keys named; every case runs its schemes one after the other in
this process, after an untimed warm-up step, so that the time ratios compare like with like):

* ``light``: ``glowinski-free-fall`` at level 1 with ``particle.density = 0.5`` (the disk rises;
  its added mass is twice its mass), 20 steps of 5 ms;
* ``glowinski``: ``glowinski-free-fall`` at level 1 (density ratio 1.25), 100 steps (0.5 s, the
  terminal velocity reached);
* ``sedimentation-1``, ``sedimentation-2``: ``sedimentation-2d`` (100 disks, hard contact) at
  levels 1 and 2 (2 and 4 cells per diameter), 40 steps (0.2 s);
* ``suspension-dense``: ``suspension-2d`` with 24 disks at area fraction 0.3 at level 2 (4 cells
  per diameter, repulsion), 20 steps of the scene's 10 ms (0.2 s), where close neighbours pull on
  each other through the fluid.

Per scheme: steps done (a scheme that fails says where), flow solves, wall time and its ratio to
the implicit scheme's, and the mean vertical particle velocity's deviation from the implicit
scheme's: the largest over all steps, the largest from the 6th step on (the first steps from rest
are where the schemes differ most) and at the last step. Results: ``benchmarks/results/coupling.md``
and ``.json`` (a new run replaces the rows of its case).
"""
from __future__ import annotations

import logging
import time

import numpy as np
from fbmbench.common import RESULTS, merge_row, provenance, write_text

from fbmflow.config import from_dict
from fbmflow.scenes import get_scene
from fbmflow.solvers import ConvergenceError

#: the Newton tolerances the recorded sedimentation rows were measured with (before the scene's
#: own defaults became 1e-6 / 1e-3)
TIGHT = {"solver": {"newton_rtol": 1e-10, "linear_rtol": 1e-8}}
#: case: scene, level, settings, steps, dt [s]
CASES = {"light": ("glowinski-free-fall", 1, {"particle": {"density": 0.5}}, 20, 0.005),
         "glowinski": ("glowinski-free-fall", 1, {}, 100, 0.005),
         "sedimentation-1": ("sedimentation-2d", 1, TIGHT, 40, 0.005),
         "sedimentation-2": ("sedimentation-2d", 2, TIGHT, 40, 0.005),
         "suspension-dense": ("suspension-2d", 2, {"particles": {"count": 24, "volume_fraction": 0.3}}, 20,
                              0.01)}
SKIP = 5  # steps from rest left out of the second deviation


def series(scene_name: str, level: int, settings: dict, scheme: str, steps: int, dt: float) -> dict:
    """Run ``steps`` steps of ``dt`` with ``coupling.scheme = scheme``: the mean vertical velocity after
    each, the flow solves, the wall time and where it failed ('' if not)."""
    scene = get_scene(scene_name)
    data = {**settings, "coupling": {"scheme": scheme}, "time": {"t_end": 10.0}}
    sim = scene.build(from_dict(scene.Params, data), level).sim
    v, solves, failure = [], 0, ""
    start = time.perf_counter()
    try:
        for _ in range(steps):
            report = sim.step(dt)
            solves += report.flow_solves
            v.append(float(sim.particles.velocity[:, -1].mean()))
    except ConvergenceError as error:
        failure = str(error).split(":")[0]
    return {"v": v, "flow_solves": solves, "wall_s": time.perf_counter() - start, "failure": failure,
            "n_dofs": int(sim.x.size), "particles": int(sim.particles.n)}


def deviation(v: list, ref: list, start: int = 0) -> float | None:
    """Largest |v - ref| over the steps from ``start``, relative to the largest |ref| (None when
    ``v`` does not cover ``ref``)."""
    if len(v) < len(ref):
        return None
    v, ref = np.asarray(v), np.asarray(ref)
    return float(np.max(np.abs(v[start:] - ref[start:])) / np.max(np.abs(ref)))


def run_case(case: str, schemes: list[str]) -> list[dict]:
    scene, level, settings, steps, dt = CASES[case]
    series(scene, level, settings, schemes[0], 1, dt)  # Numba kernels loaded, first-call costs paid
    runs = {s: series(scene, level, settings, s, steps, dt) for s in schemes}
    ref = runs.get("implicit")
    rows = []
    for scheme, r in runs.items():
        row = {"case": case, "scene": scene, "level": level, "scheme": scheme, "steps": len(r["v"]),
               "planned_steps": steps, **{k: r[k] for k in ("flow_solves", "wall_s", "failure", "n_dofs",
                                                           "particles")}, "v": r["v"], **provenance()}
        if ref is not None and ref["wall_s"] > 0:
            row["speedup"] = ref["wall_s"] / r["wall_s"] * len(r["v"]) / max(len(ref["v"]), 1)
            row["dev_all"] = deviation(r["v"], ref["v"])
            row["dev_late"] = deviation(r["v"], ref["v"], SKIP)
            row["dev_last"] = (None if len(r["v"]) < len(ref["v"])
                               else abs(r["v"][-1] / ref["v"][-1] - 1.0))
        rows.append(row)
        print(f"{case} {scheme}: {len(r['v'])}/{steps} steps {r['wall_s']:.1f} s {r['failure']}", flush=True)
    return rows


def pct(x) -> str:
    return "–" if x is None else f"{100 * x:.1f} %"


def table(rows: list[dict]) -> str:
    lines = ["# Coupling schemes: accuracy against the implicit scheme, and cost "
             "(python -m fbmbench coupling)",
             "",
             "Each case runs its schemes one after the other in one process (the JIT warm-up excluded), "
             "dt = 5 ms (suspension-dense: 10 ms). Deviation: of the mean vertical particle velocity from "
             "the implicit scheme's, relative to its largest value; 'from step 6' leaves out the first five "
             "steps from rest. "
             "Speed-up: the implicit scheme's wall time per step over the scheme's.",
             "",
             "| case | scene | level | particles | unknowns | scheme | steps | flow solves | wall [s] "
             "| s / step | speed-up | deviation (all) | deviation (from step 6) | deviation (last) | failure "
             "| date | commit |",
             "|" + "---|" * 17]
    order = list(CASES)
    for r in sorted(rows, key=lambda r: (order.index(r["case"]) if r["case"] in order else 99, r["scheme"])):
        speedup = f"{r['speedup']:.1f}" if "speedup" in r else "–"
        lines.append(f"| {r['case']} | {r['scene']} | {r['level']} | {r['particles']} | {r['n_dofs']} | "
                     f"{r['scheme']} | {r['steps']} / {r['planned_steps']} | {r['flow_solves']} | "
                     f"{r['wall_s']:.1f} | {r['wall_s'] / max(r['steps'], 1):.2f} | {speedup} | "
                     f"{pct(r.get('dev_all'))} | {pct(r.get('dev_late'))} | {pct(r.get('dev_last'))} | "
                     f"{r['failure']} | {r['date']} | {r['commit']} |")
    return "\n".join(lines) + "\n"


def same(a: dict, b: dict) -> bool:
    return (a["case"], a["scheme"]) == (b["case"], b["scheme"])


def run(*, cases: list[str] = tuple(CASES),
        schemes: list[str] = ("implicit", "stabilised", "newton-krylov", "explicit")) -> None:
    """Run each case's schemes and record their rows.

    Parameters
    ----------
    cases : the cases (light, glowinski, sedimentation-1, sedimentation-2, suspension-dense)
    schemes : the coupling schemes, each case's in this order
    """
    unknown = [c for c in cases if c not in CASES]
    if unknown:
        raise SystemExit(f"coupling: no case {', '.join(unknown)}; cases: {', '.join(CASES)}")
    logging.getLogger("fbmflow").setLevel(logging.ERROR)
    rows = []
    for case in cases:
        for row in run_case(case, list(schemes)):
            rows = merge_row("coupling", row, same)
    write_text(RESULTS / "coupling.md", table(rows))
