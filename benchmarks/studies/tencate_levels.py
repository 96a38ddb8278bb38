"""ten Cate E4 at two mesh levels, each with the time step that follows its mesh: how far apart
are the settling-velocity curves, and how much of that is each level's time error?

Question: with the time step following the level (Courant 0.25), do ten Cate E4's settling
velocities at levels 1 and 2 (6 and 12 cells/d) agree within 1 % of Table II's u_max up to
t = 0.5 s, and which part of their difference is space and which time?
Answer: no, by 0.24 points: up to t = 0.2 s level 2 runs 1.09-1.24 % of u_max below level 1
(the largest 1.24 % at t = 0.2 s; up to t = 0.5 s at Courant 0.5, 1.29 % at t = 0.13 s, shrinking
to 0.70 % at t = 0.5 s). It is the mesh's: each level moves by at most 0.14 % of u_max when its
step is halved (level 1: Courant 0.25 against 0.125; level 2: 0.5 against 0.25), and the
difference at the same step is the same 1.18-1.25 % (benchmarks/results/tencate_levels.md).
Measured: 2026-11-28, commit 1d56541 (level 2 at Courant 0.25 and level 1 at 0.125, to t = 0.2 s;
the others at ffb4b16 and a547da0); quoted in docs/validation/converged-answers.md, "Time steps
that follow the mesh".
Run: python -m fbmbench tencate_levels

Reads the E4 runs with the scene's time step (``--dt 0`` in ``python -m fbmbench tencate``) from
``benchmarks/results/tencate.json``: per level and Courant number the latest row. Writes
``benchmarks/results/tencate_levels.md``: the settling velocity of each run at common times, and
the differences that separate the mesh from the time step (each level against itself at half the
step; level 2 against level 1 at the same Courant number and at the same step), in per cent of
Table II's u_max (the target's measure) and pointwise (from t = 0.05 s on, where the sphere has
reached a third of u_max).
"""
from __future__ import annotations

import numpy as np
from fbmbench.common import RESULTS, load_rows, write_text

from fbmflow.scenes.data import tencate2002

CASE = "E4"
#: the scene's default Courant number (a run without ``time.courant`` in its settings)
DEFAULT_COURANT = 0.25


def runs(rows: list[dict]) -> dict:
    """``{(level, courant): row}``: the latest E4 row per level and Courant number among the runs
    whose time step follows the mesh and that change nothing else but the end time."""
    out = {}
    for r in rows:
        extra = set(r["settings"]) - {"time.courant", "time.t_end"}
        if r["case"] != CASE or r["dt"] != 0 or extra:
            continue
        out[(r["level"], float(r["settings"].get("time.courant", DEFAULT_COURANT)))] = r
    return out


def velocity(row: dict, t: np.ndarray) -> np.ndarray:
    """The settling velocity [m/s] at times ``t`` (linear between the steps; NaN past the run's end)."""
    tt, u = np.asarray(row["t"]), np.asarray(row["settling_velocity"])
    return np.where(t <= tt[-1] + 1e-12, np.interp(t, tt, u), np.nan)


def run(*, t_end: float = 0.5, every: float = 0.05) -> None:
    """Tabulate the curves and their differences (the largest over times 2.5 ms apart).

    Parameters
    ----------
    t_end : the last time compared [s]
    every : spacing of the tabulated times [s]
    """
    found = runs(load_rows("tencate"))
    if not found:
        raise SystemExit("no E4 run with the scene's time step in benchmarks/results/tencate.json")
    keys = sorted(found)
    t = np.round(np.arange(every, t_end + 1e-9, every), 6)
    fine = np.round(np.arange(0.0025, t_end + 1e-9, 0.0025), 6)
    u = {k: velocity(found[k], t) for k in keys}
    uf = {k: velocity(found[k], fine) for k in keys}
    u_max = tencate2002.U_MAX[CASE]
    label = {k: f"level {k[0]}, Courant {k[1]:g} (dt {1e3 * found[k]['time_step']:.2f} ms)" for k in keys}
    lines = [
        "# ten Cate E4: levels and time steps against each other",
        "",
        "Settling velocity [m/s] of each run (E4, the scene's time step, `python -m fbmbench tencate "
        "--cases E4 --levels L --dt 0 --set time.courant=C --set time.t_end=T`), and the differences "
        f"in per cent of Table II's u_max ({u_max} m/s); largest over t <= {t_end} s where both runs "
        "reach. Written by `python -m fbmbench tencate_levels`.",
        "",
        "| t s | " + " | ".join(label[k] for k in keys) + " |",
        "|---|" + "---|" * len(keys),
    ]
    for i, ti in enumerate(t):
        cells = ["" if np.isnan(u[k][i]) else f"{u[k][i]:.5f}" for k in keys]
        if any(cells):
            lines.append(f"| {ti:g} | " + " | ".join(cells) + " |")
    pairs = [((lv, c), (lv, c / 2), f"level {lv}: Courant {c:g} - {c / 2:g} (its time error)")
             for lv, c in keys if (lv, c / 2) in found]
    pairs += [((lv + 1, c), (lv, c), f"level {lv + 1} - level {lv}, Courant {c:g} each")
              for lv, c in keys if (lv + 1, c) in found]
    pairs += [((lv + 1, 2 * c), (lv, c), f"level {lv + 1} - level {lv}, the same step (Courant {2 * c:g} / "
               f"{c:g})") for lv, c in keys if (lv + 1, 2 * c) in found]
    lines += ["", "| difference | " + " | ".join(f"{ti:g} s" for ti in t)
              + " | largest, % of u_max | at t s | largest pointwise |", "|---|" + "---|" * (len(t) + 3)]
    for a, b, name in pairs:
        d, df = 100 * (u[a] - u[b]) / u_max, 100 * (uf[a] - uf[b]) / u_max
        if np.isnan(df).all():
            continue
        worst = int(np.nanargmax(np.abs(df)))
        pointwise = np.where(fine >= 0.05, 100 * (uf[a] - uf[b]) / uf[b], 0.0)  # not the near-zero start
        at = int(np.nanargmax(np.abs(pointwise)))
        cells = ["" if np.isnan(x) else f"{x:+.2f}" for x in d]
        lines.append(f"| {name} | " + " | ".join(cells) + f" | {df[worst]:+.2f} | {fine[worst]:g} | "
                     f"{pointwise[at]:+.2f} % at {fine[at]:g} s |")
    text = "\n".join(lines) + "\n"
    write_text(RESULTS / "tencate_levels.md", text)
    print(text)
