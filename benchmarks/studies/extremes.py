"""Many particles at the extremes: density ratios near 1 and of 10, and a dense packing resting on
the bottom (issue 29), in ``sedimentation-2d``.

Question: do 100 disks in ``sedimentation-2d`` stay stable and free of overlap at density
ratios 1.01 and 10 and as a dense packing resting on the floor?
Answer: yes: no run blew up and none overlapped (ratio 1.01 at level 2: mean speed 0.017 cm/s
at the end, 546 s; ratio 10: disks reach 22 cm/s and land at the contact distance, 857 s; the
packing at spacing 1.4 d, level 1, skin 0.5 cells rests after 1 s at 0.0045 cm/s, 628 s; at
spacing 1.2 d with a skin of one cell it overlaps 0.69 r in its second step, then settles)
(benchmarks/results/extremes.md).
Measured: 2026-11-26, commit b1617f9; quoted in docs/validation/many-particles-at-the-extremes.md
Run: python -m fbmbench extremes

The packing at level 1: ``python -m fbmbench extremes --cases packed --level 1 --set
contact.skin_cells=0.5``.

Cases (each the scene's defaults but for the keys named):

* ``ratio-1.01``: ``particles.density = 1.01`` (the fluid's is 1): almost neutrally buoyant
  disks, where an explicit coupling would be unstable (added mass); 0.2 s.
* ``ratio-10``: ``particles.density = 10``: fast disks, hard landings; 0.2 s.
* ``packed``: 100 disks on a lattice of spacing 1.4 diameters from the bottom
  (``particles.spacing = 1.4``, ``bottom = 0``, ``top = 0.3``; the gaps just above the contact skin
  at level 2): a dense packing that settles onto the floor and must rest there for 1 s. At
  level 1 (skin 0.5 d) add ``--set contact.skin_cells=0.5``.

Per run: steps, wall time, whether it finished, the largest overlap (over the radius) in the
first and in the second half of the run (overlap must not grow), the largest speed of the mean
vertical velocity over the last tenth of the run, and the lowest and highest centre. A run that
fails (NaN, Newton) is a row with its failure. Results: ``benchmarks/results/extremes.md`` and
``.json``.
"""
from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
from fbmbench.common import (
    RESULTS,
    RUNS,
    RunFailed,
    merge_row,
    parse_settings,
    provenance,
    run_scene,
    slug,
    warm_up,
    write_text,
)

SCENE = "sedimentation-2d"
CASES = {
    "ratio-1.01": {"particles.density": 1.01, "time.t_end": 0.2},
    "ratio-10": {"particles.density": 10.0, "time.t_end": 0.2},
    "packed": {"particles.spacing": 1.4, "particles.bottom": 0.0, "particles.top": 0.3, "time.t_end": 1.0},
}


def run_case(case: str, level: int) -> dict:
    settings = CASES[case]
    row = {"case": case, "level": level, "settings": settings, **provenance()}
    # the scheme and Newton tolerances these results were measured with
    cli = {**settings, "coupling.scheme": "implicit", "solver.newton_rtol": 1e-10, "solver.linear_rtol": 1e-8}
    try:
        s = run_scene(SCENE, level, cli)
    except RunFailed as error:  # what the run left on disk tells how far it came
        with h5py.File(Path(RUNS / slug(SCENE, level, cli)) / "run.h5") as h:
            t = h["t"][:]
        return {**row, "failure": str(error), "t_reached": float(t[-1]), "steps": len(t) - 1}
    q = s["quantities"]
    t, overlap, v = (np.array(q[k]) for k in ("t", "overlap", "mean_velocity"))
    half, tail = t >= t[-1] / 2, t >= 0.9 * t[-1]
    return {**row, "failure": "", "t_reached": float(t[-1]), "steps": s["steps"], "wall_s": s["wall_s"],
            "n_dofs": s["n_dofs"], "overlap_first_half": float(overlap[~half].max()),
            "overlap_second_half": float(overlap[half].max()),
            "late_mean_speed": float(np.abs(v[tail]).max()),
            "min_height": q["min_height"], "max_height": q["max_height"],
            "cells_per_diameter": q["cells_per_diameter"]}


def write(rows: list[dict]) -> None:
    lines = ["# Many particles at the extremes (extremes)", "",
             "`sedimentation-2d` (100 disks, d = 0.1 cm, fluid density 1, mu = 0.1 g/(cm s), implicit "
             "coupling, hard contact with a skin of one cell), the keys in 'settings' changed. Overlap: the "
             "largest overlap of two disks or a disk and a wall over the radius (0: none) in the first and "
             "the second half of the run. 'late speed': the largest |mean vertical velocity| over the last "
             "tenth of the run. Reproduce: `python -m fbmbench extremes --cases CASE --level L`.", "",
             "| case | level | settings | unknowns | steps | t reached s | wall s | overlap 1st half | "
             "overlap 2nd half | late speed cm/s | lowest / highest centre cm | failure | measured |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in sorted(rows, key=lambda r: (r["case"], r["level"])):
        settings = ", ".join(f"{k}={v}" for k, v in r["settings"].items())
        if r["failure"]:
            lines.append(f"| {r['case']} | {r['level']} | {settings} | | {r['steps']} | "
                         f"{r['t_reached']:.3f} | | | "
                         f"| | | {r['failure']} | {r['date']} {r['commit']} |")
            continue
        lines.append(
            f"| {r['case']} | {r['level']} | {settings} | {r['n_dofs']} | {r['steps']} | "
            f"{r['t_reached']:.3f} | "
            f"{r['wall_s']:.0f} | {r['overlap_first_half']:.2g} | {r['overlap_second_half']:.2g} | "
            f"{r['late_mean_speed']:.3g} | {r['min_height']:.3f} / {r['max_height']:.3f} | – | "
            f"{r['date']} {r['commit']} |")
    write_text(RESULTS / "extremes.md", "\n".join(lines) + "\n")


def run(*, cases: list[str] = tuple(CASES), level: int = 2, t_end: float | None = None,
        set: list[str] = ()) -> None:
    """Run each case and record its row.

    Parameters
    ----------
    cases : the cases (ratio-1.01, ratio-10, packed)
    level : mesh level (2: the scene's default, 4 cells/d)
    t_end : final time instead of the case's
    set : more scene settings, KEY=VALUE each
    """
    unknown = [c for c in cases if c not in CASES]
    if unknown:
        raise SystemExit(f"extremes: no case {', '.join(unknown)}; cases: {', '.join(CASES)}")
    extra = parse_settings(list(set))
    for settings in CASES.values():
        settings.update(extra)
        if t_end is not None:
            settings["time.t_end"] = t_end
    warm_up(SCENE, **{"particles.count": 4, "time.t_end": 0.01})
    for case in cases:
        row = run_case(case, level)
        print({k: v for k, v in row.items() if k != "settings"}, flush=True)
        write(merge_row("extremes", row, lambda a, b: (a["case"], a["level"], a["settings"]) ==
                        (b["case"], b["level"], b["settings"])))

