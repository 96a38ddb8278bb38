"""Hindered settling of random suspensions from an ensemble of frozen configurations (issue 29,
item 3), carried to an unbounded suspension with a far-field reference and compared with
Richardson & Zaki.

Question: how fast does a random suspension of hard spheres settle against Richardson & Zaki at
volume fractions 0.05, 0.1 and 0.2, once the periodic box's size is accounted for?
Answer: the boxes (6-40 spheres, 4 cells/d) read 0.64-0.76 of Richardson-Zaki; carried to an
unbounded suspension (screened estimate) 1.021 +- 0.002 at 0.05, 0.937 +- 0.005 at 0.1 (0.88 +- 0.03
with the paired size law of study hindered_settling_sd) and 0.802 / 0.805 / 0.810 at 0.2 for
8 / 20 / 40 spheres: within 10 % at 0.05, borderline at 0.1, not at 0.2; 8 cells/d settles 3-6 %
slower (benchmarks/results/hindered_settling.md).
Measured: 2026-11-27, commit 38c1f7e; quoted in docs/validation/periodic-suspensions.md
Run: python -m fbmbench hindered_settling --counts 20 --seeds 0 1 2 3 --fraction 0.1

Usage: python -m fbmbench hindered_settling [--counts 8 20] [--seeds 0 1 2] [--level 2]
[--fraction 0.2] [--dt 0.1] [--steps 3] [--min-gap 0.02] [--moving] [--set KEY=VALUE ...]

At small Reynolds numbers the mean settling velocity of a suspension is an average over its
configurations (Ladd 1990), each settling at the velocity its particles' mobilities give. So
instead of one long run, ``suspension-3d`` is run from ``--seeds`` independent random placements
(gaps of at least ``--min-gap`` diameters, repulsion off: hard spheres placed at random, with no
pair force) held in place (``particles.frozen``) for ``--steps`` steps of ``--dt`` = 0.1 s from
rest, and the settling velocity is the mean over the steps after the first. A backward-Euler step
of ``dt`` screens the flow beyond ``sqrt(nu dt)`` (1.4 d here): the box's longest wave, of length
``L``, reaches ``k^2 nu dt / (1 + k^2 nu dt)`` of its steady amplitude per step (``k = 2 pi / L``;
0.91 for 8 spheres at 0.2, 0.78 for 40), so the first step reads low and the later ones settle.
``--moving`` lets the particles move (the protocol of the first ensembles, with ``--steps 1``).

A periodic box of ``N`` particles lacks the density fluctuations longer than the box, and settles
slower than an unbounded suspension (Brady & Durlofsky 1988, Ladd 1990). For every configuration
the bench computes the mean settling velocity of the same spheres at the Rotne–Prager–Yamakawa
level by Ewald sums (:mod:`fbmbench.ewald_rpy`: the far field exact, no near field), ``R_N``, and
that model's limit for an unbounded random suspension at the same fraction, ``R_inf``
(:func:`far_field_law`). The far field carries the box's effect and the flow solve the near
field, so each configuration gives three estimates of the unbounded suspension's ratio to
Richardson–Zaki, all control variates (R_N follows the configuration, so their scatter is well
below that of ``ratio``):

* *scaled*, ``ratio * R_inf / R_N``: the box's deficit in proportion to the mobility;
* *shifted*, ``ratio + (R_inf - R_N) U_0 / V_RZ``: the deficit as the far field gives it, in
  units of the Stokes velocity ``U_0``;
* *screened*, the shifted deficit divided by the suspension's relative viscosity
  ``1 + 2.5 phi + 5.2 phi^2`` (Batchelor & Green 1972): the box's longest waves move through the
  suspension, not through the fluid, which the far-field model (pure fluid between point-like
  spheres) misses. The one of the three that does not depend on N (docs/validation/).

Results: ``benchmarks/results/hindered_settling.md``, ``.json``, ``.png`` and
``hindered_settling_far_field.json`` (the limits ``R_inf``, computed once per fraction). An
independent Stokes solver on the same configurations, with its own box-size law:
study ``hindered_settling_sd``.
"""
from __future__ import annotations

import functools
import json
import math

import numpy as np
from fbmbench.common import (
    RESULTS,
    RunFailed,
    merge_row,
    parse_settings,
    provenance,
    run_scene,
    warm_up,
    write_text,
)
from fbmbench.ewald_rpy import mean_settling

from fbmflow.scenes.suspension import SphereSuspension, SuspensionFluid, random_positions

NAME = "hindered_settling"
LIMIT_ENSEMBLES = ((125, 32), (343, 16), (1000, 8))  # (spheres, configurations) behind R_inf


def run_configuration(count: int, seed: int, level: int, fraction: float, dt: float, steps: int,
                      min_gap: float, extra: dict) -> dict:
    """The row of one frozen (or moving) configuration: ``count`` spheres placed with ``seed``."""
    settings = {"particles.count": count, "particles.seed": seed, "particles.volume_fraction": fraction,
                "particles.min_gap": min_gap, "repulsion.enabled": False, "time.dt": dt,
                "time.t_end": round(dt * steps, 12), "particles.frozen": True, **extra}
    row = {"count": count, "seed": seed, "level": level, "fraction": fraction, "min_gap": min_gap,
           "steps": steps, "settings": settings, **provenance()}
    try:
        s = run_scene("suspension-3d", level, settings)
    except RunFailed as error:
        return {**row, "failure": str(error)}
    q = s["quantities"]
    series = np.array(q["settling_velocity"][min(2, steps):])  # past the first step (one step: itself)
    pp, fl = s["params"]["particles"], s["params"]["fluid"]
    stokes = (pp["density"] - fl["density"]) * fl["gravity"] * pp["diameter"] ** 2 / (18.0 * fl["viscosity"])
    return {**row, "failure": "", "volume_fraction": q["volume_fraction"], "stokes_velocity": stokes,
            "cells_per_diameter": q["cells_per_diameter"], "n_dofs": s["n_dofs"], "wall_s": s["wall_s"],
            "settling": float(series.mean()), "series": q["settling_velocity"],
            "richardson_zaki": q["richardson_zaki"], "terminal_velocity": q["terminal_velocity"],
            "ratio": float(series.mean()) / q["richardson_zaki"], "max_overlap": q["max_overlap"],
            "array": q["array_velocity"], "diameter": pp["diameter"]}


def diameter(row: dict) -> float:
    return row.get("diameter", SphereSuspension().diameter)


def relative_viscosity(phi: float) -> float:
    """Batchelor & Green's (1972) effective viscosity of a random suspension of hard spheres, over
    the fluid's."""
    return 1.0 + 2.5 * phi + 5.2 * phi**2


def stokes_velocity(row: dict) -> float:
    """One sphere's Stokes velocity ``U_0`` [cm/s] (rows measured before it was stored: the scene's
    defaults)."""
    if "stokes_velocity" in row:
        return row["stokes_velocity"]
    pp, fl = SphereSuspension(), SuspensionFluid()
    return (pp.density - fl.density) * fl.gravity * pp.diameter**2 / (18.0 * fl.viscosity)


@functools.lru_cache(maxsize=None)
def placed_far_field(n: int, d: float, phi: float, min_gap: float, seed: int) -> float:
    """The RPY mean settling velocity (over one sphere's Stokes velocity) of ``n`` spheres of
    diameter ``d`` placed as the scene places them (seed ``seed``, gaps of ``min_gap`` diameters)
    in the periodic cube that they fill to ``phi``."""
    side = (n * math.pi / 6.0 * d**3 / phi) ** (1.0 / 3.0)
    return mean_settling(random_positions(n, d, np.full(3, side), min_gap * d, seed), side, d / 2)


def far_field(row: dict) -> float:
    """``R_N``: :func:`placed_far_field` of the row's configuration, in its box as built."""
    return placed_far_field(row["count"], diameter(row), row["volume_fraction"], row["min_gap"], row["seed"])


def far_field_law(phi: float, min_gap: float) -> dict:
    """The RPY mean settling velocity of random suspensions at ``phi`` (placed as the scene places,
    gaps of ``min_gap`` diameters) against their size, ``R(N) = R_inf - c N^(-1/3)``, fitted to the
    ensembles :data:`LIMIT_ENSEMBLES` (weighted by their standard errors): ``{"limit": R_inf,
    "se": its standard error, "slope": c, "ensembles": [...]}``; computed once and kept in
    ``hindered_settling_far_field.json``."""
    path = RESULTS / f"{NAME}_far_field.json"
    cache = json.loads(path.read_text()) if path.is_file() else {}
    key = f"{phi:.6f} {min_gap:g}"
    made = [[e["count"], e["configurations"]] for e in cache.get(key, {}).get("ensembles", [])]
    if made != [list(e) for e in LIMIT_ENSEMBLES]:  # not computed yet, or from other ensembles
        d = SphereSuspension().diameter
        x, y, se = [], [], []
        for n, seeds in LIMIT_ENSEMBLES:
            v = [placed_far_field(n, d, phi, min_gap, s) for s in range(seeds)]
            x.append(n ** (-1 / 3))
            y.append(float(np.mean(v)))
            se.append(float(np.std(v, ddof=1) / math.sqrt(seeds)))
        w = 1.0 / np.array(se)
        A = np.column_stack([np.ones(len(x)), -np.array(x)]) * w[:, None]
        coef, *_ = np.linalg.lstsq(A, np.array(y) * w, rcond=None)
        cov = np.linalg.inv(A.T @ A)
        cache[key] = {"limit": float(coef[0]), "se": float(math.sqrt(cov[0, 0])), "slope": float(coef[1]),
                      "ensembles": [{"count": n, "configurations": k, "mean": m, "se": e}
                                    for (n, k), m, e in zip(LIMIT_ENSEMBLES, y, se)]}
        write_text(path, json.dumps(cache, indent=1))
    return cache[key]


def groups(rows: list[dict]) -> dict:
    """The rows that ran, by (level, fraction, min_gap, repulsion on, dt, steps, protocol, viscosity), then
    count: one ``(ratio, R_N, scaled, shifted, screened estimate, row)`` per seed (rows of one
    seed with other solver settings are averaged)."""
    seeds: dict = {}
    for r in rows:
        if not r["failure"]:
            key = (r["level"], r["fraction"], r["min_gap"], repulsion(r), r["settings"]["time.dt"],
                   r["steps"], protocol(r), viscosity(r))
            seeds.setdefault(key, {}).setdefault(r["count"], {}).setdefault(r["seed"], []).append(r)
    out: dict = {}
    for key, by_count in seeds.items():
        for n, by_seed in by_count.items():
            for rs in by_seed.values():
                r = rs[0]
                ratio, rpy = float(np.mean([x["ratio"] for x in rs])), far_field(r)
                limit = far_field_law(r["volume_fraction"], r["min_gap"])["limit"]
                shift = (limit - rpy) * stokes_velocity(r) / r["richardson_zaki"]
                screened = ratio + shift / relative_viscosity(r["volume_fraction"])
                estimates = (ratio, rpy, ratio * limit / rpy, ratio + shift, screened, r)
                out.setdefault(key, {}).setdefault(n, []).append(estimates)
    return out


def repulsion(row: dict) -> str:
    return "on" if row["settings"]["repulsion.enabled"] else "off"


def viscosity(row: dict) -> float:
    return float(row["settings"].get("fluid.viscosity", SuspensionFluid().viscosity))


def protocol(row: dict) -> str:
    return "frozen" if row["settings"].get("particles.frozen") else "moving"


def mean_se(values) -> str:
    v = np.asarray(values, dtype=float)
    return f"{v.mean():.3f} +- {v.std(ddof=1) / math.sqrt(len(v)):.3f}" if len(v) > 1 else f"{v.mean():.3f}"


def write(rows: list[dict]) -> None:
    by_group = groups(rows)
    lines = ["# Hindered settling from frozen random configurations (hindered_settling)", "",
             "`suspension-3d` (d = 0.1 cm, rho_s = 1.5, viscosity 0.2 g/(cm s), Re_t 0.6; at viscosity 1, "
             "Re_t 0.03), spheres placed at random with repulsion off, held in place ('frozen': the mean "
             "over steps 2, 3, ... of dt "
             "from rest) or moving (the earlier protocols: one step of dt from rest, or the mean over steps "
             "2, 3, ... of 0.01 s). Settling velocity relative to the mixture, and "
             "its ratio to Richardson-Zaki V_t (1 - phi)^n (V_t: Schiller-Naumann, n: Garside & "
             "Al-Dibouni at Re_t) at the box's own fraction. R_N: the same configuration's mean settling "
             "velocity at the Rotne-Prager-Yamakawa level (Ewald sums, Stokes flow), over one sphere's "
             "Stokes velocity. Wall time without the JIT warm-up, 2-core machine. Reproduce: "
             "`python -m fbmbench hindered_settling --counts N --seeds S --fraction PHI "
             "[--set solver.linear=multigrid]`.", "",
             "| spheres | seed | level | cells/d | phi (box) | min gap / d | repulsion | unknowns | "
             "steps x dt | particles | coupling | wall s | settling cm/s | Richardson-Zaki cm/s | ratio | "
             "R_N | array cm/s | max overlap / r | failure | measured |", "|---" * 20 + "|"]
    for r in sorted(rows, key=lambda r: (r["level"], r["fraction"], r["min_gap"], r["count"], r["seed"])):
        st = r["settings"]
        head = (f"| {r['count']} | {r['seed']} | {r['level']} | {r.get('cells_per_diameter', 0):.0f} | "
                f"{r.get('volume_fraction', r['fraction']):.4f} | {r['min_gap']} | {repulsion(r)} | "
                f"{r.get('n_dofs', '')} | {r['steps']} x {st['time.dt']} | {protocol(r)} | "
                f"{st['coupling.scheme']} |")
        if r["failure"]:
            lines.append(f"{head} | | | | | | | | {r['failure']} | {r['date']} {r['commit']} |")
            continue
        lines.append(f"{head} {r['wall_s']:.0f} | {r['settling']:.4g} | {r['richardson_zaki']:.4g} | "
                     f"{r['ratio']:.3f} | {far_field(r):.4f} | {r['array']:.4g} | {r['max_overlap']:.2g} | "
                     "– | "
                     f"{r['date']} {r['commit']} |")
    lines += ["", "Ensembles: the ratio to Richardson-Zaki (mean +- standard error over the configurations), "
              "the far-field model's R_N and its limit R_inf for an unbounded suspension at the box's "
              "fraction (+- its standard error; hindered_settling_far_field.json), and the unbounded "
              "suspension's ratio estimated as the mean of ratio * R_inf / R_N (scaled), of "
              "ratio + (R_inf - R_N) U_0 / V_RZ (shifted) and of the shift divided by the relative "
              "viscosity 1 + 2.5 phi + 5.2 phi^2 (screened); their +- is the configurations' scatter only.",
              "",
              "| level | phi | viscosity | min gap / d | repulsion | steps x dt s | particles | spheres | "
              "configurations | ratio | R_N | R_inf | ratio / R_N | unbounded, scaled | unbounded, shifted | "
              "unbounded, screened |", "|---" * 16 + "|"]
    for (level, fraction, gap, rep, dt, steps, how, mu), by_count in sorted(by_group.items()):
        for n, rs in sorted(by_count.items()):
            ratio, rpy, scaled, shifted, screened, rows_ = (list(c) for c in zip(*rs))
            law = far_field_law(rows_[0]["volume_fraction"], gap)
            lines.append(f"| {level} | {fraction} | {mu:g} | {gap} | {rep} | {steps} x {dt} | {how} | {n} | "
                         f"{len(rs)} | "
                         f"{mean_se(ratio)} | {np.mean(rpy):.4f} | {law['limit']:.4f} +- {law['se']:.4f} | "
                         f"{mean_se(np.array(ratio) / np.array(rpy))} | {mean_se(scaled)} | "
                         f"{mean_se(shifted)} | {mean_se(screened)} |")
    write_text(RESULTS / f"{NAME}.md", "\n".join(lines) + "\n")
    plot(by_group)


def plot(by_group: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    chosen = {key: by_count for key, by_count in by_group.items() if key[-2] == "frozen"}
    for k, ((level, fraction, gap, rep, dt, steps, how, mu), by_count) in enumerate(sorted(chosen.items())):
        label = f"phi {fraction}, {2 ** level} cells/d, viscosity {mu:g}"
        for n, rs in by_count.items():
            ax.plot([n ** (-1 / 3)] * len(rs), [ratio for ratio, *_ in rs], "o", ms=3, alpha=0.5,
                    color=f"C{k}")
            ax.plot([n ** (-1 / 3)], [np.mean([ratio for ratio, *_ in rs])], "s", ms=6, color=f"C{k}")
            ax.plot([n ** (-1 / 3) - 0.01] * len(rs), [c[4] for c in rs], "x", ms=4, alpha=0.6,
                    color=f"C{k}")
        screened = np.mean([c[4] for rs in by_count.values() for c in rs])
        # the far-field model's finite-size law, screened, through the unbounded estimate
        row = next(iter(by_count.values()))[0][-1]
        law = far_field_law(fraction, gap)
        slope = law["slope"] * stokes_velocity(row) / row["richardson_zaki"] / relative_viscosity(fraction)
        x = np.linspace(0.0, 0.55, 20)
        ax.plot(x, screened - slope * x, ":", color=f"C{k}",
                label=f"{label}: unbounded {screened:.2f} and the screened far-field law")
    ax.axhline(1.0, color="k", lw=0.8, label="Richardson-Zaki")
    ax.axhspan(0.9, 1.1, color="k", alpha=0.08, label="10 %")
    ax.set_xlabel("N^(-1/3)")
    ax.set_title("o: configurations, x: each carried to N = infinity (screened), square: mean", fontsize=8)
    ax.set_ylabel("settling velocity / Richardson-Zaki")
    ax.set_xlim(left=-0.01)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(RESULTS / f"{NAME}.png", dpi=120)
    plt.close(fig)


def run(
    *,
    counts: list[int] = (8, 20),
    seeds: list[int] = (0, 1, 2),
    level: int = 2,
    fraction: float = 0.2,
    dt: float = 0.1,
    moving: bool = False,
    steps: int = 3,
    min_gap: float = 0.02,
    set: list[str] = (),
) -> None:
    """Run each count of spheres from each seed's placement and record the rows.

    Parameters
    ----------
    counts : spheres per box
    seeds : the random placements
    level : 2^L cells per diameter
    fraction : volume fraction
    dt : time step [s]
    moving : let the particles move during the steps
    steps : steps per configuration: at least 3 (the first is the flow's start-up), or one long
        step (the earlier protocol)
    min_gap : smallest gap at the start, in diameters
    set : more scene settings KEY=VALUE
    """
    if steps == 2:
        raise SystemExit("--steps must be 1 or at least 3 (the first step is the flow's start-up)")
    extra = {"coupling.scheme": "newton-krylov", "coupling.max_subiterations": 40,  # (FGMRES's limit)
             **({"particles.frozen": False} if moving else {}), **parse_settings(set)}
    warm_up("suspension-3d", **{"particles.count": 1, "time.t_end": 0.02, "time.dt": 0.01})
    for count in counts:
        for seed in seeds:
            row = run_configuration(count, seed, level, fraction, dt, steps, min_gap, extra)
            print({k: v for k, v in row.items() if k not in ("settings", "series")}, flush=True)
            write(merge_row(NAME, row, lambda a, b: (a["count"], a["seed"], a["level"], a["settings"]) ==
                            (b["count"], b["seed"], b["level"], b["settings"])))
