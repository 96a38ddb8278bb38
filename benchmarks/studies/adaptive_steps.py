"""Adaptive time steps (``time.adaptive``) on Glowinski's settling disk: does the coupled scheme
stay consistent when the step changes, and what does a tolerance buy against a fixed step?

Question: (1) with steps that vary from one to the next, does the peak settling velocity stay
where constant steps of the same mean put it, per time scheme and particle integrator? (2) at
level 1, how do the peak, the steps and the rejected steps of adaptive runs compare with fixed
steps?
Answer: steps that alternate 0.5 / 1.5 ms raise the peak to 0.4 s by 4.2 % over constant 1 ms
steps with the scenes' Crank–Nicolson and trapezoidal integrator, 0.2 % with Crank–Nicolson and
semi-implicit Euler, -0.6 % with backward Euler (the trapezoidal rule pairs two mid-step pressure
forces); so with the default pair the adaptive peak does not converge as the tolerance tightens
(5.8752 / 5.8294 / 5.9093 cm/s at 3e-3 / 1e-3 / 3e-4, fixed 1 ms: 5.8267), and is no cheaper
than the fixed step the scene chooses (benchmarks/results/adaptive_steps.md).
Measured: 2026-11-28, commit 8ed94f1; quoted in docs/validation/converged-answers.md.
Run: python -m fbmbench adaptive_steps --part tolerance

(and ``--part variable``.) ``variable``: ``glowinski-free-fall`` at level 1 to t = 0.4 s in steps
of 1 ms, of 0.5 and 1.5 ms in turn ("alternating"), and of ten 0.5 ms then ten 1.5 ms steps in
turn ("blocks"), per scheme pair. ``tolerance``: the scene at level 1 to its end with ``time.adaptive`` at each tolerance,
and with fixed steps. Rows go to ``benchmarks/results/adaptive_steps.json``; the table to
``adaptive_steps.md``.
"""
from __future__ import annotations

import time
from typing import Literal

from fbmbench.common import RESULTS, load_rows, merge_row, provenance, write_text

from fbmflow.config import from_dict
from fbmflow.scenes.registry import load_scene

SCHEMES = (("crank-nicolson", "trapezoidal"), ("crank-nicolson", "semi-implicit-euler"),
           ("backward-euler", "trapezoidal"))
PATTERNS = {"constant": lambda k: 0.001, "alternating": lambda k: 0.0005 if k % 2 == 0 else 0.0015,
            "blocks": lambda k: 0.0005 if (k // 10) % 2 == 0 else 0.0015}


def _scene(settings: dict):
    scene, defaults, _ = load_scene("glowinski-free-fall")
    return scene, from_dict(type(defaults), settings)


def variable(scheme: str, integrator: str, pattern: str, t_end: float = 0.4) -> dict:
    """The peak settling velocity to ``t_end`` with steps of ``pattern``."""
    scene, params = _scene({"time": {"dt": 0.001, "scheme": scheme}, "coupling": {"integrator": integrator}})
    sim = scene.build(params, 1).sim
    t0, k, peak = time.perf_counter(), 0, 0.0
    while sim.t < t_end - 1e-12:
        sim.step(PATTERNS[pattern](k))
        k += 1
        peak = max(peak, -float(sim.particles.velocity[0, -1]))
    return dict(part="variable", scheme=scheme, integrator=integrator, pattern=pattern, t_end=t_end, steps=k,
                u_max=peak, wall_s=time.perf_counter() - t0, **provenance())


def tolerance(value: float) -> dict:
    """The scene at level 1 with adaptive steps at tolerance ``value``, or fixed steps of ``-value``
    seconds when it is negative."""
    settings = {"time": {"adaptive": True, "tolerance": value}} if value > 0 else {"time": {"dt": -value}}
    scene, params = _scene(settings)
    t0 = time.perf_counter()
    result = scene.run(params, 1)
    q = result.quantities
    return dict(part="tolerance", tolerance=value if value > 0 else None, dt=-value if value < 0 else None,
                steps=result.steps, u_max=q["max_settling_velocity"], time_step=q["time_step"],
                smallest=q.get("time_step_smallest"), largest=q.get("time_step_largest"),
                rejected=q.get("rejected_steps", 0), courant=q["courant_number"],
                wall_s=time.perf_counter() - t0, **provenance())


def run(*, part: Literal["variable", "tolerance"] = "variable", tolerances: list[float] = (1e-2, 1e-3, 3e-4),
        fixed: list[float] = (0.002, 0.001)) -> None:
    """One part of the study; one row per run.

    Parameters
    ----------
    part : variable (steps that change) or tolerance (adaptive runs against fixed steps)
    tolerances : time.tolerance values of the adaptive runs
    fixed : the fixed steps [s] to compare with
    """
    if part == "variable":
        for scheme, integrator in SCHEMES:
            for pattern in PATTERNS:
                row = variable(scheme, integrator, pattern)
                print(f"{scheme} + {integrator}, {pattern}: u_max {row['u_max']:.5f}", flush=True)
                merge_row("adaptive_steps", row, lambda r, s: all(
                    r.get(k) == s.get(k) for k in ("part", "scheme", "integrator", "pattern")))
    else:
        for value in list(tolerances) + [-dt for dt in fixed]:
            row = tolerance(value)
            print(f"tolerance {row['tolerance']} dt {row['dt']}: u_max {row['u_max']:.5f}, "
                  f"{row['steps']} steps, {row['rejected']} rejected, {row['wall_s']:.0f} s", flush=True)
            merge_row("adaptive_steps", row, lambda r, s: all(
                r.get(k) == s.get(k) for k in ("part", "tolerance", "dt")))
    write(load_rows("adaptive_steps"))


def write(rows: list[dict]) -> None:
    lines = ["# Adaptive time steps on Glowinski's settling disk (adaptive_steps)", "",
             "Level 1 (2 cells per diameter across the disk's path), the scene's defaults otherwise. Wall "
             "time on the 2-core machine, other jobs beside some runs (upper bounds). Reproduce: `python -m "
             "fbmbench adaptive_steps --part variable` / `--part tolerance`.", "",
             "## Steps that vary: peak settling velocity to t = 0.4 s", "",
             "| time scheme | particle integrator | step pattern | u_max cm/s | vs constant 1 ms "
             "| measured |",
             "|---|---|---|---|---|---|"]
    variable_rows = [r for r in rows if r["part"] == "variable"]
    for r in variable_rows:
        base = [b for b in variable_rows if (b["scheme"], b["integrator"], b["pattern"])
                == (r["scheme"], r["integrator"], "constant")]
        change = f"{100 * (r['u_max'] / base[0]['u_max'] - 1):+.2f} %" if base else ""
        lines.append(f"| {r['scheme']} | {r['integrator']} | {r['pattern']} | {r['u_max']:.4f} | {change} | "
                     f"{r['date']} {r['commit']} |")
    lines += ["", "## Adaptive against fixed steps, to the scene's end", "",
              "| stepping | tolerance | dt s (mean; range) | accepted | rejected | Courant | u_max cm/s | wall s "
              "| measured |", "|---|---|---|---|---|---|---|---|---|"]
    tolerance_rows = [r for r in rows if r["part"] == "tolerance"]
    for r in sorted(tolerance_rows, key=lambda r: (r["tolerance"] is None, -(r["tolerance"] or 0))):
        if r["tolerance"] is None:
            kind, tol, dt = "fixed", "", f"{r['dt']:g}"
        else:
            kind, tol = "adaptive", f"{r['tolerance']:g}"
            dt = f"{r['time_step']:.3g} ({r['smallest']:.2g} to {r['largest']:.2g})"
        lines.append(f"| {kind} | {tol} | {dt} | {r['steps']} | {r['rejected']} | {r['courant']:.2f} | "
                     f"{r['u_max']:.4f} | {r['wall_s']:.0f} | {r['date']} {r['commit']} |")
    write_text(RESULTS / "adaptive_steps.md", "\n".join(lines) + "\n")
