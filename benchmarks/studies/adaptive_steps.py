"""Adaptive time steps (``time.adaptive``) on Glowinski's settling disk: does the coupled scheme
stay consistent when the step changes, and what does a tolerance buy against a fixed step?

Question: (1) with steps that vary from one to the next, does the settling velocity stay where
constant steps of the same mean put it, per time scheme, particle integrator and pressure
pairing? (2) how do the peak, the steps and the rejected steps of adaptive runs compare with
fixed steps?
Answer: at level 2, steps that alternate 0.5 / 1.5 ms move the velocity curve by up to 4.0 %
from constant 1 ms steps with the trapezoidal integrator's two-step mean of pressure forces, 1.2 %
with the step's own pressure force (the midpoint rule, which adaptive runs now take), 1.5 % with
semi-implicit Euler; the adaptive peaks scatter by -0.7 to +1.7 % about the fixed steps' limit
(about 5.551 cm/s) whatever the tolerance or the Courant cap (5.6076 / 5.6478 / 5.5978 at 3e-3 /
1e-3 / 3e-4; 5.5121 at 1e-3 with max_courant 0.2; fixed 2 / 1 / 0.5 ms: 5.6120 / 5.5811 /
5.5663): the node crossings' first-order error, which the path estimate does not see
(benchmarks/results/adaptive_steps.md).
Measured: 2026-11-28, commit b5d4b58; quoted in docs/validation/converged-answers.md, "Adaptive time steps".
Run: python -m fbmbench adaptive_steps --part variable --level 2

(and ``--part tolerance --level 2 --tolerances 0.003 0.001 0.0003 --fixed 0.004 0.002 0.001
0.0005``, ``--tolerances 0.001 --max-courant 0.2``.)
``variable``: ``glowinski-free-fall`` at ``level`` to ``t_end`` in steps of 1 ms, of 0.5 and 1.5
ms in turn ("alternating"), and of ten 0.5 ms then ten 1.5 ms steps in turn ("blocks"), per
scheme pair and pressure pairing. ``tolerance``: the scene at ``level`` to its end with
``time.adaptive`` at each tolerance, and with fixed steps. Rows go to
``benchmarks/results/adaptive_steps.json``; the table to ``adaptive_steps.md``.
"""
from __future__ import annotations

import time
from typing import Literal

import numpy as np
from fbmbench.common import RESULTS, load_rows, merge_row, provenance, write_text

from fbmflow.config import from_dict
from fbmflow.scenes.registry import load_scene

SCHEMES = (("crank-nicolson", "trapezoidal"), ("crank-nicolson", "semi-implicit-euler"))
#: how the trapezoidal integrator pairs the pressure forces: the mean of two steps' (constant
#: steps) or the step's own (the midpoint rule, which adaptive runs take)
PAIRINGS = ("two-step mean", "midpoint")
PATTERNS = {"constant": lambda k: 0.001, "alternating": lambda k: 0.0005 if k % 2 == 0 else 0.0015,
            "blocks": lambda k: 0.0005 if (k // 10) % 2 == 0 else 0.0015}


def _scene(settings: dict):
    scene, defaults, _ = load_scene("glowinski-free-fall")
    return scene, from_dict(type(defaults), settings)


def variable(scheme: str, integrator: str, pattern: str, pairing: str = "two-step mean", level: int = 2,
             t_end: float = 0.25) -> dict:
    """The settling velocity to ``t_end`` with steps of ``pattern`` (its curve, the peak and the
    end value); ``pairing`` "midpoint": a simulation made for adaptive steps (the trapezoidal
    integrator then takes each step's own pressure force), stepped by the pattern."""
    time_settings = {"dt": 0.001, "scheme": scheme, "adaptive": pairing == "midpoint"}
    scene, params = _scene({"time": time_settings, "coupling": {"integrator": integrator}})
    sim = scene.build(params, level).sim
    t0, k, curve = time.perf_counter(), 0, []
    while sim.t < t_end - 1e-12:
        sim.step(PATTERNS[pattern](k))
        k += 1
        curve.append((sim.t, -float(sim.particles.velocity[0, -1])))
    t, v = np.array(curve).T
    return dict(part="variable", scheme=scheme, integrator=integrator, pairing=pairing, pattern=pattern,
                level=level, t_end=t_end, steps=k, u_max=float(v.max()), u_end=float(v[-1]), t=t.tolist(),
                settling_velocity=v.tolist(), wall_s=time.perf_counter() - t0, **provenance())


def curve_change(row: dict, base: dict, after: float = 0.05) -> float:
    """Largest relative change of ``row``'s settling velocity from ``base``'s over ``base``'s
    times after ``after`` seconds (``row`` interpolated linearly)."""
    t, v = np.array(base["t"]), np.array(base["settling_velocity"])
    keep = t > after
    return float(np.max(np.abs(np.interp(t[keep], row["t"], row["settling_velocity"]) / v[keep] - 1.0)))


def tolerance(value: float, level: int = 1, max_courant: float = 0.5) -> dict:
    """The scene at ``level`` with adaptive steps at tolerance ``value`` (steps of at most
    ``max_courant`` cells), or fixed steps of ``-value`` seconds when it is negative."""
    settings = ({"time": {"adaptive": True, "tolerance": value, "max_courant": max_courant}} if value > 0
                else {"time": {"dt": -value}})
    scene, params = _scene(settings)
    t0 = time.perf_counter()
    result = scene.run(params, level)
    q = result.quantities
    return dict(part="tolerance", level=level, tolerance=value if value > 0 else None,
                max_courant=max_courant if value > 0 else None,
                dt=-value if value < 0 else None, pairing="midpoint" if value > 0 else "two-step mean",
                steps=result.steps, u_max=q["max_settling_velocity"], time_step=q["time_step"],
                smallest=q.get("time_step_smallest"), largest=q.get("time_step_largest"),
                rejected=q.get("rejected_steps", 0), courant=q["courant_number"],
                wall_s=time.perf_counter() - t0, **provenance())


def run(*, part: Literal["variable", "tolerance"] = "variable", tolerances: list[float] = (1e-2, 1e-3, 3e-4),
        fixed: list[float] = (0.002, 0.001), level: int = 2, t_end: float = 0.25,
        patterns: list[str] = tuple(PATTERNS), max_courant: float = 0.5) -> None:
    """One part of the study; one row per run.

    Parameters
    ----------
    part : variable (steps that change) or tolerance (adaptive runs against fixed steps)
    tolerances : time.tolerance values of the adaptive runs
    fixed : the fixed steps [s] to compare with
    level : the mesh level
    t_end : the variable part's end [s] (the tolerance part runs to the scene's end)
    patterns : the variable part's step patterns
    max_courant : the adaptive runs' time.max_courant
    """
    if part == "variable":
        runs = [(scheme, integrator, pairing) for scheme, integrator in SCHEMES
                for pairing in (PAIRINGS if integrator == "trapezoidal" else PAIRINGS[:1])]
        for scheme, integrator, pairing in runs:
            for pattern in patterns:
                row = variable(scheme, integrator, pattern, pairing, level, t_end)
                print(f"{scheme} + {integrator} ({pairing}), {pattern}: u_max {row['u_max']:.5f}, "
                      f"{row['wall_s']:.0f} s", flush=True)
                merge_row("adaptive_steps", row, lambda r, s: r["part"] == s["part"] and r.get("pattern") ==
                          s.get("pattern") and _variable_key(r) == _variable_key(s))
    else:
        for value in list(tolerances) + [-dt for dt in fixed]:
            row = tolerance(value, level, max_courant)
            print(f"tolerance {row['tolerance']} dt {row['dt']}: u_max {row['u_max']:.5f}, "
                  f"{row['steps']} steps, {row['rejected']} rejected, {row['wall_s']:.0f} s", flush=True)
            keys = (("part", 1), ("tolerance", 1), ("dt", 1), ("level", 1), ("max_courant", None))
            merge_row("adaptive_steps", row, lambda r, s: all(
                r.get(k, d if k != "max_courant" or not r["tolerance"] else 0.5) == s[k] for k, d in keys))
    write(load_rows("adaptive_steps"))


def _variable_key(r: dict) -> tuple:
    return r.get("level", 1), r["t_end"], r["scheme"], r["integrator"], r.get("pairing", "two-step mean")


def write(rows: list[dict]) -> None:
    lines = ["# Adaptive time steps on Glowinski's settling disk (adaptive_steps)", "",
             "The scene's defaults but the steps (level 1: 2 cells per diameter across the disk's path, "
             "level 2, the default: 4). Wall time on the 2-core machine, other jobs beside some runs (upper "
             "bounds). Reproduce: `python -m fbmbench adaptive_steps --part variable [--level L]` / `--part "
             "tolerance`.", "",
             "## Steps that vary: the settling velocity", "",
             "Steps of 1 ms ('constant'), of 0.5 and 1.5 ms in turn ('alternating') and ten 0.5 ms then ten "
             "1.5 ms steps in turn ('blocks'), the same mean. Pressure pairing of the trapezoidal "
             "integrator: the mean of two steps' pressure forces (fixed steps) or the step's own (the "
             "midpoint rule, which adaptive runs take). 'curve': the largest change of the settling "
             "velocity from the constant steps' after t = 0.05 s.", "",
             "| level | time scheme | particle integrator | pressure pairing | step pattern | to t s "
             "| u_max cm/s | vs constant | u at the end | vs constant | curve | measured |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    variable_rows = sorted((r for r in rows if r["part"] == "variable"), key=_variable_key)
    for r in variable_rows:
        base = [b for b in variable_rows
                if _variable_key(b) == _variable_key(r) and b["pattern"] == "constant"]
        b = base[0] if base else None
        change = f"{100 * (r['u_max'] / b['u_max'] - 1):+.2f} %" if b else ""
        end, end_change, curve = "", "", ""
        if "u_end" in r:
            end = f"{r['u_end']:.4f}"
            end_change = f"{100 * (r['u_end'] / b['u_end'] - 1):+.2f} %" if b else ""
            curve = f"{100 * curve_change(r, b):.2f} %" if b else ""
        lines.append(f"| {r.get('level', 1)} | {r['scheme']} | {r['integrator']} | "
                     f"{r.get('pairing', 'two-step mean') if r['integrator'] == 'trapezoidal' else ''} | "
                     f"{r['pattern']} | {r['t_end']:g} | {r['u_max']:.4f} | {change} | {end} | "
                     f"{end_change} | {curve} | {r['date']} {r['commit']} |")
    lines += ["", "## Adaptive against fixed steps, to the scene's end", "",
              "Crank–Nicolson and the trapezoidal integrator; its pressure pairing as in the first "
              "table.", "",
              "| level | stepping | pressure pairing | tolerance | dt s (mean; range) | accepted | rejected "
              "| Courant | u_max cm/s | wall s | measured |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    tolerance_rows = [r for r in rows if r["part"] == "tolerance"]
    for r in sorted(tolerance_rows, key=lambda r: (r.get("level", 1), r["tolerance"] is None,
                                                   -(r.get("max_courant") or 0.5), -(r["tolerance"] or 0),
                                                   r["dt"] or 0)):
        if r["tolerance"] is None:
            kind, tol, dt = "fixed", "", f"{r['dt']:g}"
        else:
            kind, tol = f"adaptive, max_courant {r.get('max_courant', 0.5):g}", f"{r['tolerance']:g}"
            dt = f"{r['time_step']:.3g} ({r['smallest']:.2g} to {r['largest']:.2g})"
        lines.append(f"| {r.get('level', 1)} | {kind} | {r.get('pairing', 'two-step mean')} | {tol} | {dt} | "
                     f"{r['steps']} | {r['rejected']} | {r['courant']:.2f} | {r['u_max']:.4f} | "
                     f"{r['wall_s']:.0f} | {r['date']} {r['commit']} |")
    write_text(RESULTS / "adaptive_steps.md", "\n".join(lines) + "\n")
