"""Periodic suspensions (issue 29, item 3): the settling velocity of periodic arrays against Sangani &
Acrivos' exact series, and of random suspensions of spheres against Richardson & Zaki.

Question: how close does the settling velocity of a periodic array of disks or spheres come to
Sangani & Acrivos' (1982) series, and that of a few random spheres to Richardson & Zaki?
Answer: periodic arrays within 0.1 % (disks, 16 cells/d, fractions 0.05-0.2; -5.3 / -6.5 % at
4 cells/d, the error halving per level) and within 2.7 % (spheres, 4 cells/d; -0.3 / -3.7 % at
8 cells/d and fractions 0.1 / 0.2); 8 random spheres settle 25 / 39 / 45 % below Richardson-Zaki at
fractions 0.05 / 0.1 / 0.2 in dynamic runs with the repulsion (benchmarks/results/suspension.md;
study hindered_settling's frozen configurations qualify these).
Measured: 2026-11-26, commit 919af18; quoted in docs/validation/periodic-suspensions.md
Run: python -m fbmbench suspension

Usage: python -m fbmbench suspension [--cases array-2d array-3d random-3d] [--levels 2 3]
[--fractions 0.05 0.1 0.2] [--count 8] [--t-end T] [--set KEY=VALUE ...]

Cases (``suspension-2d`` / ``suspension-3d``, their defaults but for the keys named):

* ``array-2d``, ``array-3d``: one particle in the periodic box (a square / simple cubic array),
  ``fluid.viscosity = 1`` (Re about 0.02 / 0.05: Stokes flow), 0.6 s in steps of 0.02 s; the
  settling velocity averaged over the second half against Sangani & Acrivos (1982).
* ``random-3d``: ``--count`` spheres at random (the scene's viscosity 0.2, Re_t 0.6), against
  Richardson & Zaki with Garside & Al-Dibouni's exponent and Schiller & Naumann's terminal
  velocity (see :mod:`fbmflow.scenes.suspension`).

Per run: volume fraction of the box as built, cells per diameter, unknowns, steps, wall time (the
JIT warm-up excluded), the mean settling velocity over the second half of the run, the
reference and the error. Results: ``benchmarks/results/suspension.md`` and ``.json``.
"""
from __future__ import annotations

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

ARRAY = {"particles.count": 1, "fluid.viscosity": 1.0, "time.t_end": 0.6, "time.dt": 0.02}
CASES = {"array-2d": ("suspension-2d", ARRAY, "array_velocity"),
         "array-3d": ("suspension-3d", ARRAY, "array_velocity"),
         "random-3d": ("suspension-3d", {"time.t_end": 0.6, "time.dt": 0.01}, "richardson_zaki")}


def run_case(case: str, level: int, fraction: float, extra: dict) -> dict:
    """The row of one run of ``case`` at ``level`` and ``fraction``."""
    scene, base, reference = CASES[case]
    settings = {**base, "particles.volume_fraction": fraction, **extra}
    row = {"case": case, "level": level, "fraction": fraction, "settings": settings, **provenance()}
    try:
        s = run_scene(scene, level, settings)
    except RunFailed as error:
        return {**row, "failure": str(error)}
    q = s["quantities"]
    ref = q[reference]
    out = {**row, "failure": "", "volume_fraction": q["volume_fraction"],
           "cells_per_diameter": q["cells_per_diameter"], "n_dofs": s["n_dofs"], "steps": s["steps"],
           "wall_s": s["wall_s"], "settling": q["mean_settling_velocity"], "reference": ref,
           "error": q["mean_settling_velocity"] / ref - 1.0, "max_overlap": q["max_overlap"]}
    for key in ("terminal_velocity", "terminal_reynolds", "rz_exponent"):
        if key in q:
            out[key] = q[key]
    out["array"] = q["array_velocity"]
    return out


def write(rows: list[dict]) -> None:
    lines = ["# Periodic suspensions (suspension)", "",
             "Settling velocity relative to the mixture (whose mean volume flux is held at zero), averaged "
             "over the second half of the run. `array-*`: one particle per periodic box, Stokes flow "
             "(viscosity 1 g/(cm s)), against Sangani & Acrivos (1982). `random-3d`: spheres placed at "
             "random, viscosity 0.2 g/(cm s), against Richardson-Zaki V_t (1 - phi)^n (V_t: "
             "Schiller-Naumann; n: Garside & Al-Dibouni at Re_t); 'array' is the periodic array's velocity "
             "at the same fraction and viscosity (Stokes flow). "
             "d = 0.1 cm, rho_s = 1.5, rho_f = 1 g/cm^3; sharp boundary, surface force, implicit coupling, "
             "repulsion. Wall time without the JIT warm-up, on the 2-core machine. Reproduce: "
             "`python -m fbmbench suspension --cases CASE --levels L --fractions PHI`.", "",
             "| case | level | cells/d | phi (box) | unknowns | steps | wall s | settling cm/s | "
             "reference cm/s | error | array cm/s | max overlap / r | failure | measured |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    def order(r):
        return r["case"], r["fraction"], r["level"], r["settings"].get("particles.count", 0)

    for r in sorted(rows, key=order):
        if r["failure"]:
            lines.append(f"| {r['case']} | {r['level']} | | {r['fraction']} | | | | | | | | {r['failure']} "
                         f"| {r['date']} {r['commit']} |")
            continue
        count = r["settings"].get("particles.count", 1)
        case = r["case"] + (f" ({count} spheres)" if r["case"] == "random-3d" else "")
        lines.append(f"| {case} | {r['level']} | {r['cells_per_diameter']:.0f} | "
                     f"{r['volume_fraction']:.4f} | {r['n_dofs']} | {r['steps']} | {r['wall_s']:.0f} | "
                     f"{r['settling']:.4g} | {r['reference']:.4g} | {100 * r['error']:+.1f} % | "
                     f"{r['array']:.4g} | {r['max_overlap']:.2g} | – | "
                     f"{r['date']} {r['commit']} |")
    write_text(RESULTS / "suspension.md", "\n".join(lines) + "\n")


def run(
    *,
    cases: list[str] = tuple(CASES),
    levels: list[int] = (2, 3),
    fractions: list[float] = (0.05, 0.1, 0.2),
    count: int = 8,
    t_end: float = None,
    set: list[str] = (),
) -> None:
    """Run each case at each fraction and level and record the rows.

    Parameters
    ----------
    cases : the cases, of array-2d array-3d random-3d
    levels : 2^L cells per diameter
    fractions : volume fractions
    count : spheres of the random-3d case
    t_end : final time instead of the case's
    set : more scene settings KEY=VALUE
    """
    unknown = [c for c in cases if c not in CASES]
    if unknown:
        raise SystemExit(f"--cases: {unknown} not among {', '.join(CASES)}")
    extra = parse_settings(set)
    if t_end is not None:
        extra["time.t_end"] = t_end
    for case in cases:
        scene = CASES[case][0]
        warm_up(scene, **{"particles.count": 1, "time.t_end": 0.02, "time.dt": 0.01})
        more = dict(extra, **({"particles.count": count} if case == "random-3d" else {}))
        for fraction in fractions:
            for level in levels:
                row = run_case(case, level, fraction, more)
                print({k: v for k, v in row.items() if k != "settings"}, flush=True)
                write(merge_row("suspension", row, lambda a, b: (a["case"], a["level"], a["settings"]) ==
                                (b["case"], b["level"], b["settings"])))
