"""ten Cate's approach to the bottom with and without the lubrication correction: the gap curve
below gap/d = 1 against the experiment.

Question: does the lubrication correction (with wall contact) bring the simulated sphere's
approach to the bottom below gap/d = 1 closer to ten Cate's experiment?
Answer: no: at level 1 (6 cells/d) E4's gaps at the experiment's samples below gap/d = 1 agree
within 0.007 between the variants (0.588 / 0.365 / 0.11 / 0.02-0.03 against the experiment's
0.846 / 0.583 / 0.387 / 0.125; gap/d 1 to 0.125 in 0.112 s against 0.121 s); lubrication only
slows the last step, by 12 %. In E2 the sphere overshoots to gap/d 0.07-0.08 and rebounds at
1-2 cm/s; lubrication halves the rebound (0.84 against 1.77 cm/s) and leaves the approach
(benchmarks/results/tencate_approach_E4_L1.md, tencate_approach_E2_L1.md).
Measured: 2026-11-26, commit 2c03a44 (E4; E2: commit b8e16f7); quoted in docs/validation/lubrication.md
Run: python -m fbmbench tencate_approach --base RUN_DIR

E2: ``python -m fbmbench tencate_approach --case E2 --dt 0.02 --steps 45``.

One run of the scene (its defaults, ``solver.linear = multigrid``) goes to the first step whose
gap falls below ``--branch-gap`` diameters, or ``--base`` names a run whose checkpoint is that
state (e.g. ``fbmflow run ten-cate --level 1 --set time.dt=0.01 --set time.t_end=0.95 --set
solver.linear=multigrid --checkpoint-every 5``). From that state
three variants take ``--steps`` more steps, or fewer where the gap falls below the scene's
``particle.stop_gap`` (a run made here is not kept):

* ``defaults``: the scene as it is (Crank-Nicolson with the trapezoidal particle integrator, no
  contact; the sphere sinks until the run's end);
* ``contact``: wall contact with a skin of 0.1 cells, which contact needs with semi-implicit
  Euler (the integrator hard contact advances the sphere with);
* ``lubrication``: the same with the lubrication correction at the package's defaults.

Each variant's gap and velocity per step go into
``benchmarks/results/tencate_approach_CASE_LLEVEL.json``, with ``.md`` (the gap at the
experiment's samples below gap/d = 1, and the time from gap/d = 1 to the experiment's last
sample) and ``.png``.
"""
from __future__ import annotations

import json
import time
from pathlib import Path
from types import SimpleNamespace
from typing import Literal

import numpy as np
from fbmbench.common import RESULTS, provenance

from fbmflow.config import from_dict
from fbmflow.io import load_checkpoint
from fbmflow.scenes import get_scene
from fbmflow.scenes.data import tencate2002

VARIANTS = {
    "defaults": {},
    "contact": {"contact": {"enabled": True, "skin_cells": 0.1},
                "coupling": {"integrator": "semi-implicit-euler"}},
    "lubrication": {"contact": {"enabled": True, "skin_cells": 0.1, "lubrication": True},
                    "coupling": {"integrator": "semi-implicit-euler"}},
}


def _params(scene, case: str, dt: float, extra: dict):
    tree = {"fluid": {"case": case}, "time": {"dt": dt}, "solver": {"linear": "multigrid"}}
    for section, values in extra.items():
        tree.setdefault(section, {}).update(values)
    return from_dict(scene.Params, tree)


def _gap(sim, d: float) -> float:
    return float(sim.particles.position[0, 2] - d / 2) / d


def base_state(scene, args) -> tuple[dict, list]:
    """The state at the branch point and the curve up to it: the checkpoint of ``--base`` (the
    curve before it is then left out) or a run made here."""
    if args.base is not None:
        return load_checkpoint(args.base / "checkpoint.h5")[0], []
    params = _params(scene, args.case, args.dt, {})
    sim = scene.build(params, args.level).sim
    d = params.particle.diameter
    rows = []
    while _gap(sim, d) > args.branch_gap:
        r = sim.step()
        rows.append((r.t, _gap(sim, d), float(r.velocity[0, 2])))
        print(f"base step {r.step}: t = {r.t:.3f} s, gap/d = {rows[-1][1]:.3f}", flush=True)
    return sim.state(), rows


def branch(scene, args, state: dict, name: str) -> dict:
    params = _params(scene, args.case, args.dt, VARIANTS[name])
    sim = scene.build(params, args.level).sim
    if sim.contact is not None and "contact_keys" not in state:  # no warm start from a run without
        state = {**state, "contact_keys": np.zeros(0, dtype=np.int64), "contact_normal": np.zeros(0),
                 "contact_friction": np.zeros((0, 3))}
    sim.set_state(state)
    d = params.particle.diameter
    rows, t0 = [], time.perf_counter()
    for _ in range(args.steps):
        r = sim.step()
        rows.append((r.t, _gap(sim, d), float(r.velocity[0, 2])))
        print(f"{name} step {r.step}: t = {r.t:.3f} s, gap/d = {rows[-1][1]:.4f}, "
              f"w = {rows[-1][2]:.5f} m/s", flush=True)
        if rows[-1][1] < params.particle.stop_gap:  # the scene's own end
            break
    return {"variant": name, "rows": rows, "wall_s": time.perf_counter() - t0}


def _first_crossing(t: np.ndarray, gap: np.ndarray, level: float) -> float:
    """The time the gap first falls to ``level`` (linear between the steps; NaN if it never
    does; the sphere may rebound from the bottom afterwards)."""
    below = np.flatnonzero(gap <= level)
    if below.size == 0 or below[0] == 0:
        return float("nan")
    k = below[0]
    return float(t[k - 1] + (t[k] - t[k - 1]) * (gap[k - 1] - level) / (gap[k - 1] - gap[k]))


def summary(case: str, runs: list[dict], base: list) -> list[dict]:
    """Per variant: the gap at the experiment's samples with gap_exp < 1, and the time from the
    first crossing of gap/d = 1 to the first crossing of the experiment's last sample's gap,
    against the experiment's."""
    ref = tencate2002.GAP[case]
    below = ref[ref[:, 1] < 1.0]
    t_exp_1 = float(np.interp(1.0, ref[::-1, 1], ref[::-1, 0]))
    g_last = float(below[-1, 1])
    out = []
    for run in runs:
        rows = np.array(base + run["rows"])
        t, gap = rows[:, 0], rows[:, 1]
        t1, t_last = _first_crossing(t, gap, 1.0), _first_crossing(t, gap, g_last)
        out.append({"variant": run["variant"], "gap_at_samples": np.interp(below[:, 0], t, gap).tolist(),
                    "t_gap_1": t1, "time_1_to_last": t_last - t1, "min_gap": float(gap.min()),
                    "exp_time_1_to_last": float(below[-1, 0]) - t_exp_1, "wall_s": run["wall_s"]})
    return out


def _stem(case: str, level: int) -> Path:
    return RESULTS / f"tencate_approach_{case}_L{level}"


def write(case: str, level: int, runs: list[dict], base: list, stats: list[dict], measured: dict) -> None:
    ref = tencate2002.GAP[case]
    below = ref[ref[:, 1] < 1.0]
    stem = _stem(case, level)
    stem.with_suffix(".json").write_text(json.dumps({"case": case, "level": level, "base": base, "runs": runs,
                                                     "summary": stats, **measured}, indent=1))
    samples = " | ".join(f"t = {t:.3f} s" for t in below[:, 0])
    lines = [f"# ten Cate {case}, level {level}: the approach to the bottom, with and without lubrication "
             "(python -m fbmbench tencate_approach)", "",
             "Gap/d at the experiment's samples below gap/d = 1, and the time from gap/d = 1 to the "
             "experiment's last sample's gap (experiment: first row).", "",
             f"| variant | {samples} | time from gap/d = 1 | smallest gap/d | wall s |",
             "|---" * (len(below) + 4) + "|",
             "| experiment | " + " | ".join(f"{g:.3f}" for g in below[:, 1])
             + f" | {stats[0]['exp_time_1_to_last']:.3f} s | | |"]
    for s in stats:
        lines.append(f"| {s['variant']} | " + " | ".join(f"{g:.3f}" for g in s["gap_at_samples"])
                     + f" | {s['time_1_to_last']:.3f} s | {s['min_gap']:.3f} | {s['wall_s']:.0f} |")
    stem.with_suffix(".md").write_text("\n".join(lines) + "\n")
    from fbmflow.scenes.base import pyplot, save_figure
    plt = pyplot()
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(10, 4))
    t0 = min(np.array(base + run["rows"])[0, 0] for run in runs) - 0.02
    shown = ref[ref[:, 0] >= t0]
    ax.plot(shown[:, 0], shown[:, 1], "ko", label="experiment")
    for k, run in enumerate(runs):
        rows = np.array(base + run["rows"])
        style = dict(label=run["variant"], ls=("-", "--", ":")[k % 3])
        ax.plot(rows[:, 0], rows[:, 1], **style)
        bx.plot(rows[:, 0], -rows[:, 2], **style)
    ax.set(xlabel="t [s]", ylabel="gap / d", ylim=(0, None), title=f"ten Cate {case}, level {level}: gap")
    bx.set(xlabel="t [s]", ylabel="settling velocity [m/s]", title="velocity")
    ax.legend()
    save_figure(fig, stem.with_suffix(".png"))


def run(*, case: Literal["E1", "E2", "E3", "E4"] = "E4", level: int = 1, dt: float = 0.01,
        branch_gap: float = 2.0, steps: int = 30, base: Path | None = None,
        variants: list[str] = tuple(VARIANTS), table_only: bool = False) -> None:
    """Branch the variants from one state and record their approach.

    Parameters
    ----------
    case : ten Cate's experiment
    level : the mesh level
    dt : the time step [s]
    branch_gap : branch below this gap/d
    steps : steps of each variant after the branch
    base : a run directory whose checkpoint is the branch point
    variants : the variants to run (defaults, contact, lubrication)
    table_only : redraw the table and plot from the JSON
    """
    unknown = [v for v in variants if v not in VARIANTS]
    if unknown:
        raise SystemExit(f"tencate_approach: no variant {', '.join(unknown)}; "
                         f"variants: {', '.join(VARIANTS)}")
    if table_only:
        old = json.loads(_stem(case, level).with_suffix(".json").read_text())
        stats = summary(old["case"], old["runs"], old["base"])
        write(old["case"], old["level"], old["runs"], old["base"], stats,
              {k: old[k] for k in ("date", "commit", "cpus")})
        return
    args = SimpleNamespace(case=case, level=level, dt=dt, branch_gap=branch_gap, steps=steps,
                           base=None if base is None else Path(base))
    scene = get_scene("ten-cate")
    state, base_rows = base_state(scene, args)
    runs = [branch(scene, args, state, name) for name in variants]
    earlier = _stem(case, level).with_suffix(".json")  # keep the other variants of the run
    if earlier.is_file():
        old = json.loads(earlier.read_text())
        if old["base"] == base_rows:
            runs = [r for r in old["runs"] if r["variant"] not in variants] + runs
    runs.sort(key=lambda r: list(VARIANTS).index(r["variant"]))
    stats = summary(case, runs, base_rows)
    write(case, level, runs, base_rows, stats, provenance())
