"""Stokesian-dynamics reference for the hindered-settling ensembles (issue 29, item 3): the same
random configurations in Stokes flow, with the near field, and the size of box they need.

Question: does an independent Stokes solver (Townsend's Stokesian dynamics) on the same random
configurations settle them as the flow solver does, and what size of box does it say they need?
Answer: paired configuration by configuration, the flow solver at 4 cells/d over Stokesian dynamics
is 0.991 +- 0.006 / 0.951 +- 0.004 / 0.862-0.887 at 0.05 / 0.1 / 0.2, as the exact simple cubic
array stands to it (0.993 / 0.970 / 0.869: SD is +0.7 / +3.1 / +15.0 % on the array); its own
ensembles (8-320 spheres) give U_inf = 0.697 / 0.483 / 0.256 U_0, so the flow solver carried to an
unbounded suspension is 0.99 / 0.86 / 0.74-0.76 of Richardson-Zaki (SD-scaled), 0.88 +- 0.03 at 0.1
and 0.79 +- 0.02 at 0.2 paired (benchmarks/results/hindered_settling_sd.md).
Measured: 2026-11-27, commit 412acd9; quoted in docs/validation/periodic-suspensions.md
Run: python -m fbmbench hindered_settling_sd PATH --counts 8 20 --seeds 0 1 2 --fraction 0.2 --level 2

Usage: python -m fbmbench hindered_settling_sd PATH [--counts 8 20] [--seeds 0 1 2] [--fraction 0.2]
[--level 2] [--min-gap 0.02] [--array] [--copy DIR]

``PATH`` is a checkout of github.com/Pecnut/stokesian-dynamics at commit
:data:`fbmbench.stokesian.COMMIT` (not installed with fbmflow; :mod:`fbmbench.stokesian`). Each
configuration is placed exactly as ``suspension-3d`` places it (:func:`random_positions`, gaps of at
least ``--min-gap`` diameters), in the box the scene builds at ``--level`` (a whole number of
cells), or with ``--level -1`` in the cube that the spheres fill to ``--fraction`` exactly (for
boxes larger than the flow solver can run). ``--array`` runs one sphere per box (a simple cubic
array), the case with an exact reference (Sangani & Acrivos 1982).

Stokesian dynamics answers in seconds to minutes for 8 to 320 spheres, so it gives two things the
flow solver cannot:

* the velocity of the *same* configurations as the frozen flow runs of study
  ``hindered_settling`` (paired: their ratio shows whether the fictitious boundary's near
  field at 4 cells per diameter loses or gains against an independent method);
* ensembles of up to 320 spheres, whose fit ``U(N) = U_inf - c N^(-1/3)`` carries the flow
  solver's boxes to an unbounded suspension (*SD-scaled*: ``ratio * U_inf / U_N`` per
  configuration, the box's deficit in proportion).

Results: ``benchmarks/results/hindered_settling_sd.md``, ``.json``.
"""
from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np
from fbmbench import stokesian
from fbmbench.common import RESULTS, RUNS, merge_row, provenance, write_text

from fbmflow.scenes.suspension import (
    SphereSuspension,
    SuspensionFluid,
    garside_al_dibouni,
    random_positions,
    sangani_acrivos_velocity,
)
from studies.hindered_settling import stokes_velocity

NAME = "hindered_settling_sd"
FLOW = "hindered_settling"


def box_side(count: int, fraction: float, level: int, d: float) -> float:
    """The periodic cube's side [cm]: as ``suspension-3d`` builds it at ``level`` (a whole number
    of cells ``d / 2^level``, at least 4), or for ``level < 0`` the cube filled to ``fraction``."""
    side = (count * math.pi / 6.0 * d**3 / fraction) ** (1.0 / 3.0)
    if level < 0:
        return side
    h = d / 2**level
    return max(4, int(round(side / h))) * h


def run_configuration(root: Path, count: int, seed: int, fraction: float, level: int,
                      min_gap: float) -> dict:
    """One configuration (``count`` spheres placed as the scene places them with ``seed``; one
    sphere: the simple cubic array) in Stokesian dynamics: its row for the results file."""
    d = SphereSuspension().diameter
    side = box_side(count, fraction, level, d)
    X = np.full((1, 3), side / 2) if count == 1 else random_positions(count, d, np.full(3, side),
                                                                        min_gap * d, seed)
    start = time.perf_counter()
    u = stokesian.settling_velocities(root, X, side, d / 2)
    return {"count": count, "seed": seed, "fraction": fraction, "level": level, "min_gap": min_gap,
            "box": side, "volume_fraction": count * math.pi / 6.0 * d**3 / side**3,
            "sd": float(u.mean()), "sd_spread": float(u.std()), "wall_s": time.perf_counter() - start,
            "sd_commit": stokesian.COMMIT[:7], **provenance()}


def mean_se(v) -> tuple[float, float]:
    """Mean and standard error of the mean (nan for one value)."""
    v = np.asarray(v, dtype=float)
    return float(v.mean()), float(v.std(ddof=1) / math.sqrt(len(v))) if len(v) > 1 else float("nan")


def fit_size(points: list[tuple[int, float, float]]) -> dict | None:
    """``y(N) = y_inf - c N^(-1/3)`` fitted to ``(N, mean, standard error)`` points (weights:
    1 / standard error^2): ``{"limit", "se", "slope", "counts"}``, None with fewer than 2 points."""
    if len(points) < 2:
        return None
    n, m, se = (np.array(c, dtype=float) for c in zip(*points))
    w = 1.0 / se
    A = np.column_stack([np.ones(len(n)), -n ** (-1 / 3)]) * w[:, None]
    coef, *_ = np.linalg.lstsq(A, m * w, rcond=None)
    cov = np.linalg.inv(A.T @ A)
    return {"limit": float(coef[0]), "se": float(math.sqrt(cov[0, 0])), "slope": float(coef[1]),
            "counts": [int(k) for k in n]}


def size_law(rows: list[dict]) -> dict | None:
    """Stokesian dynamics' ``U(N) = U_inf - c N^(-1/3)`` over the counts (above one sphere) with
    at least 3 configurations, and at least 3 such counts (:func:`fit_size`)."""
    by_n: dict = {}
    for r in rows:
        by_n.setdefault(r["count"], []).append(r["sd"])
    pts = [(n, *mean_se(v)) for n, v in sorted(by_n.items()) if len(v) >= 3 and n > 1]
    return fit_size(pts) if len(pts) >= 3 else None


def array_velocity(phi: float) -> float:
    """The simple cubic array's settling velocity over U_0 (Sangani & Acrivos 1982)."""
    return sangani_acrivos_velocity(3, phi, 3.0 * math.pi, 1.0, 1.0)


def at_fraction(actual: float, nominal: float) -> float:
    """How much faster a suspension at the box's fraction ``actual`` settles than at ``nominal``:
    ``((1 - actual) / (1 - nominal))^n``, Richardson–Zaki's exponent in Stokes flow (n = 5.1; the
    boxes built on the mesh hold the fraction to 3 %)."""
    return ((1.0 - actual) / (1.0 - nominal)) ** garside_al_dibouni(0.0)


def flow_rows() -> list[dict]:
    """The frozen flow runs of study ``hindered_settling`` (newton-krylov, three steps of 0.1 s
    or more, repulsion off), their settling velocity over U_0."""
    path = RESULTS / f"{FLOW}.json"
    rows = json.loads(path.read_text()) if path.is_file() else []
    out = []
    for r in rows:
        st = r["settings"]
        if r["failure"] or not st.get("particles.frozen") or st["repulsion.enabled"] or r["steps"] < 3:
            continue
        out.append({**r, "u": r["settling"] / stokes_velocity(r)})
    return out


def write(rows: list[dict]) -> None:
    """Redraw ``hindered_settling_sd.md`` from all rows and the flow runs' rows."""
    lines = [f"# Stokesian-dynamics reference for hindered settling ({NAME})", "",
             "Townsend's Stokesian dynamics (github.com/Pecnut/stokesian-dynamics, commit "
             f"{stokesian.COMMIT[:7]}; far field to the stresslet, exact two-sphere lubrication), the "
             "spheres placed as `suspension-3d` places them (gaps of at least min gap), each pushed by "
             "the same force, Stokes flow; mean settling velocity over one sphere's Stokes velocity U_0. "
             "Level: the box as the scene builds it at that level (-1: the cube filled exactly). "
             "Reproduce: `python -m fbmbench hindered_settling_sd PATH --counts N --seeds S "
             "--fraction PHI --level L` (`--array`: one sphere per box).", "",
             "| spheres | seed | level | phi (box) | min gap / d | U / U_0 (SD) | spread of the spheres | "
             "wall s | measured |", "|---" * 9 + "|"]
    for r in sorted(rows, key=lambda r: (r["fraction"], r["level"], r["count"], r["seed"])):
        lines.append(f"| {r['count']} | {r['seed'] if r['count'] > 1 else '–'} | {r['level']} | "
                     f"{r['volume_fraction']:.4f} | {r['min_gap']} | {r['sd']:.4f} | {r['sd_spread']:.3f} | "
                     f"{r['wall_s']:.0f} | {r['date']} {r['commit']} |")
    arrays = [r for r in rows if r["count"] == 1]
    if arrays:
        lines += ["", "## One sphere per box", "",
                  "The simple cubic array, against Sangani & Acrivos' (1982) series (exact to the digits "
                  "shown; `fbmflow.scenes.suspension.sangani_acrivos_velocity`).", "",
                  "| phi | U / U_0 (SD) | exact | SD / exact |", "|---|---|---|---|"]
        for r in sorted(arrays, key=lambda r: r["volume_fraction"]):
            exact = array_velocity(r["volume_fraction"])
            lines.append(f"| {r['volume_fraction']:.4f} | {r['sd']:.4f} | {exact:.4f} | "
                         f"{r['sd'] / exact:.3f} |")
    lines += ["", "## Ensembles and the size of box", "",
              "Means +- standard errors over the configurations; the law `U(N) = U_inf - c N^(-1/3)` is "
              "fitted to the exactly filled cubes (level -1).", "",
              "| phi | spheres | configurations | U / U_0 (SD) |", "|---|---|---|---|"]
    laws = {}
    for phi in sorted({r["fraction"] for r in rows}):
        exact = [r for r in rows if r["fraction"] == phi and r["level"] < 0]
        for n in sorted({r["count"] for r in exact}):
            m, se = mean_se([r["sd"] for r in exact if r["count"] == n])
            lines.append(f"| {phi} | {n} | {sum(r['count'] == n for r in exact)} | {m:.4f} +- {se:.4f} |")
        laws[phi] = size_law(exact)
    for phi, law in laws.items():
        if law:
            lines.append(f"\nphi {phi}: U_inf = {law['limit']:.4f} +- {law['se']:.4f} U_0, c = "
                         f"{law['slope']:.4f} (counts {law['counts']}).")
    lines += ["", "## Paired with the flow solver", "",
              "The same configurations in the same boxes: the flow solver's frozen settling velocity "
              "(`python -m fbmbench hindered_settling`, over U_0 at its viscosity) against Stokesian "
              "dynamics', "
              "and the flow solver's ratio to Richardson-Zaki carried to an unbounded suspension by "
              "Stokesian dynamics' own size law (SD-scaled: ratio * U_inf / U_N, U_inf taken from phi "
              "to the box's fraction by (1 - phi)^5.1; +- the configurations' scatter and U_inf's "
              "standard error). At viscosity 0.2 the flow runs carry their inertia (Re_t 0.6): "
              "1 % slower in units of U_0 than in Stokes flow.", "",
              "| level | phi | viscosity | spheres | configurations | flow / SD | ratio to RZ (box) | "
              "unbounded, SD-scaled |", "|---" * 8 + "|"]
    sd = {(r["count"], r["seed"], r["level"], r["fraction"], r["min_gap"]): r for r in rows}
    groups: dict = {}
    for f in flow_rows():
        ref = sd.get((f["count"], f["seed"], f["level"], f["fraction"], f["min_gap"]))
        if ref is None:
            continue
        mu = f["settings"].get("fluid.viscosity", SuspensionFluid().viscosity)
        groups.setdefault((f["level"], f["fraction"], mu, f["count"]), []).append((f, ref))
    for (level, phi, mu, n), pairs in sorted(groups.items()):
        law = laws.get(phi)
        q = [f["u"] / ref["sd"] for f, ref in pairs]
        ratio = [f["ratio"] for f, _ in pairs]
        scaled = [f["ratio"] * law["limit"] * at_fraction(f["volume_fraction"], phi) / ref["sd"]
                  for f, ref in pairs] if law else []
        m, se = mean_se(q)
        rm, rse = mean_se(ratio)
        cell = "–"
        if scaled:  # the configurations' scatter and U_inf's standard error, in quadrature
            sm, sse = mean_se(scaled)
            cell = f"{sm:.3f} +- {sm * math.hypot(sse / sm, law['se'] / law['limit']):.3f}"
        lines.append(f"| {level} | {phi} | {mu:g} | {n} | {len(pairs)} | {m:.3f} +- {se:.3f} | "
                     f"{rm:.3f} +- {rse:.3f} | {cell} |")
    lines += ["", "The paired ratio against the box's size, where it is measured at two counts or more "
              "(boxes within 0.01 of the nominal fraction), fitted as `q_inf - b N^(-1/3)` (two counts: "
              "the line through them): the flow solver's own size law relative to Stokesian "
              "dynamics'. Its limit times Stokesian dynamics' U_inf over Richardson-Zaki (at the "
              "nominal fraction, in U_0) is a third estimate for an unbounded suspension.", "",
              "| level | phi | viscosity | spheres | q_inf | b | SD's U_inf / the flow runs' RZ | "
              "unbounded, paired |",
              "|---" * 8 + "|"]
    trends: dict = {}
    for (level, phi, mu, n), pairs in groups.items():
        if abs(pairs[0][0]["volume_fraction"] - phi) < 0.01 and len(pairs) >= 2:
            q = mean_se([f["u"] / r["sd"] for f, r in pairs])
            trends.setdefault((level, phi, mu), []).append((n, *q))
    for (level, phi, mu), pts in sorted(trends.items()):
        fit, law = fit_size(sorted(pts)), laws.get(phi)
        if fit is None or law is None:
            continue
        f = groups[(level, phi, mu, pts[0][0])][0][0]
        rz = f["terminal_velocity"] / stokes_velocity(f) * (1.0 - phi) ** rz_exponent(f)
        est = fit["limit"] * law["limit"] / rz
        err = est * math.hypot(fit["se"] / fit["limit"], law["se"] / law["limit"])
        lines.append(f"| {level} | {phi} | {mu:g} | {', '.join(str(p[0]) for p in sorted(pts))} | "
                     f"{fit['limit']:.3f} +- {fit['se']:.3f} | {fit['slope']:.3f} | "
                     f"{law['limit'] / rz:.3f} | {est:.3f} +- {err:.3f} |")
    write_text(RESULTS / f"{NAME}.md", "\n".join(lines) + "\n")


def rz_exponent(row: dict) -> float:
    """The Richardson–Zaki exponent a flow run used (from its velocities at the box's fraction)."""
    return math.log(row["richardson_zaki"] / row["terminal_velocity"]) / math.log(1.0 -
                                                                                 row["volume_fraction"])


def run(
    sd: Path,
    *,
    counts: list[int] = (8, 20),
    seeds: list[int] = (0, 1, 2),
    fraction: float = 0.2,
    level: int = 2,
    min_gap: float = 0.02,
    array: bool = False,
    copy: str = str(RUNS / "stokesian-dynamics"),
) -> None:
    """Run each count of spheres from each seed's placement in Stokesian dynamics and record the rows.

    Parameters
    ----------
    sd : checkout of github.com/Pecnut/stokesian-dynamics
    counts : spheres per box
    seeds : the random placements
    fraction : volume fraction
    level : the scene's box at this level; -1: filled exactly
    min_gap : smallest gap, in diameters
    array : one sphere per box (a simple cubic array)
    copy : where to keep the prepared copy (one per process running at a time)
    """
    root = stokesian.prepare(sd, copy)
    stokesian.settling_velocities(root, np.array([[0.0, 0.0, 0.0], [0.5, 0.5, 0.5]]), 1.0, 0.1)  # JIT warm-up
    cases = [(1, 0)] if array else [(n, s) for n in counts for s in seeds]
    for count, seed in cases:
        row = run_configuration(root, count, seed, fraction, level, min_gap)
        print(row, flush=True)
        write(merge_row(NAME, row, lambda a, b: all(a[k] == b[k] for k in
                                                    ("count", "seed", "fraction", "level", "min_gap"))))
