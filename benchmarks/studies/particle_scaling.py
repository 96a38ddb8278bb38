"""Cost of a time step against the particle count at a fixed mesh (issue 29, item 1).

Question: does the time of a step outside the linear solves grow at most linearly from 10 to
1000 particles at a fixed mesh, and is it at most 20 % of the step at 1000 particles?
Answer: yes, with the stabilised coupling (label "stabilised (89f5b87)", sedimentation-2d level
2, 141 762 unknowns, median of steps 2-6): steps of 0.99 / 1.01 / 1.20 s at 10 / 100 / 1000
disks, 0.16 / 0.16 / 0.23 s of them outside the solves, a share of 16 / 16 / 19 %, 0.07 ms per
added disk (0.18 ms at the session's base 5d85a4a); benchmarks/results/particle_scaling.md.
Measured: 2026-11-27, commit ef072bf; quoted in docs/validation/many-particles.md, "Cost against the particle
count"
Run: python -m fbmbench particle_scaling --couplings stabilised

All options: ``python -m fbmbench particle_scaling [--counts 10 100 1000]
[--couplings explicit stabilised implicit] [--level 2] [--diameter 0.03] [--steps 6]
[--label after] [--note TEXT] [--max-response-gb 2.0]``; docs/validation/'s rows were made with
``--couplings stabilised --label "stabilised (89f5b87)"`` (the base with ``PYTHONPATH`` on its
checkout).

Scene: ``sedimentation-2d`` at ``--level`` (default 2, the scene's default: 80 x 160 cells,
141 762 unknowns) with ``particles.count`` disks of ``particles.diameter`` cm (default 0.03: the
largest that lets 1000 disks fit the scene's lattice in the upper half of the box; 1.2 cells per
diameter at level 2), hard contact and repulsion as the scene has them, the nodal boundary and
the volume force (the scene's defaults), and the coupling scheme from ``--couplings``. Each
(coupling, count) runs in a child process of its own (its peak memory is its own): one untimed
step of 10 disks first (the Numba kernels loaded from the cache and the first-call costs paid),
then a fresh simulation with ``count`` disks takes ``--steps`` timed steps and one more under
cProfile for the breakdown.

Per step: the wall time, the time inside the linear solves (``StepReport.linear.time_s``: Newton
steps and the implicit coupling's lifting responses, factorisations included) and the rest
("outside"), with the share of the step outside the solves. The implicit coupling stores the
flow's response to every rigid degree of freedom (3 per disk, dense over all unknowns); a count
whose responses would exceed ``--max-response-gb`` is skipped and said so.

Target (issue 29): at a fixed mesh the time outside the linear solves grows at most linearly from
10 to 1000 particles and is at most 20 % of the step at 1000 particles. The table gives the
outside time per added particle between successive counts (linear growth: it does not grow).

Results: ``benchmarks/results/particle_scaling.json`` (a list of rows; a new run replaces the
rows of its label, coupling and count and keeps the others, so that runs of two versions of the
code, one after the other, sit side by side) and ``particle_scaling.md``.
"""
from __future__ import annotations

import cProfile
import io
import json
import os
import pstats
import resource
import statistics
import subprocess
import sys
import time
from datetime import date
from pathlib import Path

BENCHMARKS = Path(__file__).resolve().parents[1]
RESULTS = Path(os.environ.get("FBMFLOW_BENCH_RESULTS", BENCHMARKS / "results"))
SCENE = "sedimentation-2d"
COUPLINGS = ("explicit", "stabilised", "implicit")
#: functions whose cumulative time the breakdown names where they exist (file suffix, function);
#: the coupled system's (coupling/system.py) were Simulation's (simulation.py) in the rows
#: measured before 017045c, its ``forces`` then ``_forces``
NAMED = [("coupling/schemes.py", "advance", "coupling scheme (all of the step but contact)"),
         ("coupling/system.py", "flow_and_forces", "flow solves with their forces"),
         ("flow/navier_stokes.py", "solve", "Newton solves"),
         ("coupling/system.py", "rigid_responses", "lifting responses with their forces"),
         ("coupling/system.py", "own_stiffness", "own stiffness (stabilised coupling)"),
         ("flow/navier_stokes.py", "lifting_response", "lifting responses (flow)"),
         ("coupling/system.py", "forces", "hydrodynamic forces"),
         ("coupling/system.py", "_response_forces", "hydrodynamic forces of the responses"),
         ("coupling/indicator.py", "node_owner", "node owner"),
         ("coupling/indicator.py", "rigid_body_constraints", "rigid-body constraints"),
         ("coupling/indicator.py", "rigid_liftings", "rigid liftings"),
         ("coupling/system.py", "integrate", "particle integration and contact"),
         ("contact/contact_set.py", "advance", "contact")]


def measure(count: int, coupling: str, level: int, diameter: float, steps: int) -> dict:
    """Time ``steps`` steps and profile one more of ``count`` disks; the row of the results."""
    import numpy as np

    from fbmflow.config import from_dict
    from fbmflow.scenes import get_scene

    scene = get_scene(SCENE)

    def build(n: int):
        params = from_dict(scene.Params, {"particles": {"count": n, "diameter": diameter},
                                          "coupling": {"scheme": coupling}})
        return scene.build(params, level).sim

    build(10).step()  # kernels from the Numba cache, first-call costs: not timed
    t0 = time.perf_counter()
    sim = build(count)
    setup = time.perf_counter() - t0
    rows = []
    for k in range(steps + 1):
        profile = cProfile.Profile() if k == steps else None
        t0 = time.perf_counter()
        if profile is not None:
            profile.enable()
        rep = sim.step()
        if profile is not None:
            profile.disable()
        wall = time.perf_counter() - t0
        contact = rep.contact
        rows.append({"wall_s": wall, "linear_s": rep.linear.time_s, "outside_s": wall - rep.linear.time_s,
                     "linear_solves": rep.linear.solves, "flow_solves": rep.flow_solves,
                     "newton_iterations": rep.newton_iterations,
                     "contact_s": 0.0 if contact is None else contact.detect_s + contact.solve_s,
                     "profiled": profile is not None})
    stats = pstats.Stats(profile, stream=io.StringIO())
    named, top, own = {}, [], []
    for (path, _, func), (cc, nc, tt, ct, _) in stats.stats.items():
        path = path.replace(os.sep, "/")
        for suffix, name, label in NAMED:
            if path.endswith("fbmflow/" + suffix) and func == name:
                named[label] = {"cum_s": ct, "calls": nc}
        where = path.split("/fbmflow/")[-1] if "/fbmflow/" in path else path.split("/")[-1]
        entry = {"function": f"{where}:{func}" if where != "~" else func, "cum_s": ct, "self_s": tt,
                 "calls": nc}
        own.append(entry)
        if "/fbmflow/" in path:
            top.append(entry)
    top.sort(key=lambda r: -r["cum_s"])
    own.sort(key=lambda r: -r["self_s"])
    p = sim.particles
    return {"coupling": coupling, "count": count, "level": level, "diameter": diameter,
            "unknowns": int(sim.x.size), "setup_s": setup, "steps": rows,
            "profile": {"named": named, "top": top[:25], "own": own[:12],
                        "calls": int(sum(v[1] for v in stats.stats.values()))},
            "max_rss_gb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 / 1e9,
            "checksum": {"mean_velocity": float(p.velocity[:, -1].mean()),
                         "position_sum": float(np.sum(p.position))}}


def response_gb(count: int, level: int) -> float:
    """Memory of the implicit coupling's dense lifting responses [GB]: 3 per disk, one value per
    unknown (the scene's 20 2^L x 40 2^L cells: 2 (2 n_x + 1)(2 n_y + 1) velocities, 3 pressures
    per cell)."""
    nx, ny = 20 * 2**level, 40 * 2**level
    unknowns = 2 * (2 * nx + 1) * (2 * ny + 1) + 3 * nx * ny
    return 3 * count * unknowns * 8 / 1e9


def table(rows: list[dict]) -> list[str]:
    lines = ["| version | coupling | disks | unknowns | step [s] | linear solves [s] | outside [s] | "
             "outside share | outside per added disk [ms] | contact [s] | flow solves | peak memory [GB] |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    rows = sorted(rows, key=lambda r: (r["label"], r["coupling"], r["count"]))
    previous = {}
    for r in rows:
        s = r.get("median") or r["steps"][r["measured_step"]]
        key = (r["label"], r["coupling"])
        growth = ""
        if key in previous:
            n0, out0 = previous[key]
            growth = f"{1e3 * (s['outside_s'] - out0) / (r['count'] - n0):.2f}"
        previous[key] = (r["count"], s["outside_s"])
        lines.append(f"| {r['label']} | {r['coupling']} | {r['count']} | {r['unknowns']} | "
                     f"{s['wall_s']:.2f} | {s['linear_s']:.2f} | {s['outside_s']:.2f} | "
                     f"{s['outside_s'] / s['wall_s']:.0%} | "
                     f"{growth} | {s['contact_s']:.2f} | {s['flow_solves']} | {r['max_rss_gb']:.2f} |")
    return lines


def write(rows: list[dict]) -> None:
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "particle_scaling.json").write_text(json.dumps(rows, indent=1))
    lines = ["# Cost of a step against the particle count (sedimentation-2d, fixed mesh)", "",
             "Command: `python -m fbmbench particle_scaling` (options in the rows below); 2-core "
             "machine shared with other jobs, every run under `nice -n 19`. Each row: one child process, "
             "the median of the timed steps after the first (the first from rest and the profiled one "
             "left out; rows without a median: the last timed step); `outside` is the "
             "step's wall time less `StepReport.linear.time_s`. Runs of different versions were made one "
             "after the other, not at once.", ""]
    for label in sorted({r["label"] for r in rows}):
        first = next(r for r in rows if r["label"] == label)
        lines.append(f"- `{label}`: {first['date']}, level {first['level']}, diameter "
                     f"{first['diameter']} cm, {first['n_steps']} timed steps, {first.get('note', '')}")
    lines += [""] + table(rows) + [""]
    # rows measured before 2026-11-28 lost their profiles: they named functions and files since
    # moved (solvers/linear.py, Simulation's coupling methods); a new run profiles its step again
    profiled = sorted((r for r in rows if "profile" in r),
                      key=lambda r: (r["label"], r["coupling"], r["count"]))
    if profiled:
        lines += ["## Profile of one step (cProfile, the step after the timed ones)", ""]
    for r in profiled:
        prof = r["profile"]
        last = r["steps"][-1]
        lines.append(f"**{r['label']}, {r['coupling']}, {r['count']} disks** ({prof['calls']} function "
                     f"calls; step {last['wall_s']:.2f} s, linear {last['linear_s']:.2f} s)")
        lines.append("")
        lines.append("| part | cumulative [s] | calls |")
        lines.append("|---|---|---|")
        for label, v in prof["named"].items():
            lines.append(f"| {label} | {v['cum_s']:.3f} | {v['calls']} |")
        lines.append("")
        own = prof.get("own") or sorted(prof["top"], key=lambda t: -t["self_s"])
        lines.append("Largest own times: " + ", ".join(f"`{t['function']}` {t['self_s']:.2f} s ({t['calls']})"
                                                     for t in own[:8]))
        lines.append("")
    skipped = sorted({(r["label"], s) for r in rows for s in r.get("skipped", [])})
    if skipped:
        lines += ["Skipped: " + "; ".join(f"{label}: {s}" for label, s in skipped), ""]
    (RESULTS / "particle_scaling.md").write_text("\n".join(lines) + "\n")


def run(*, counts: list[int] = (10, 100, 1000), couplings: list[str] = COUPLINGS, level: int = 2,
        diameter: float = 0.03, steps: int = 6, label: str = "current", note: str = "",
        max_response_gb: float = 2.0, one: list[str] = ()) -> None:
    """Each (coupling, count) in a child process of its own; the rows into the results.

    Parameters
    ----------
    counts : numbers of disks
    couplings : coupling schemes (explicit, stabilised, implicit)
    level : mesh level of the scene
    diameter : disk diameter [cm]
    steps : timed steps (then one profiled step); the table gives the median of all but the first
    label : version label of this run's rows
    note : a note on this run (the commit, the machine's load)
    max_response_gb : skip implicit runs whose dense lifting responses exceed this [GB]
    one : internal: run one configuration (COUPLING COUNT) in this process
    """
    unknown = [c for c in couplings if c not in COUPLINGS]
    if unknown:
        raise SystemExit(f"--couplings: unknown {unknown}; choose from {list(COUPLINGS)}")
    if one:
        row = measure(int(one[1]), one[0], level, diameter, steps)
        print("ROW " + json.dumps(row))
        return
    path = RESULTS / "particle_scaling.json"
    rows = json.loads(path.read_text()) if path.exists() else []
    skipped = []
    for coupling in couplings:
        for count in counts:
            if coupling == "implicit" and response_gb(count, level) > max_response_gb:
                skipped.append(f"implicit, {count} disks (dense lifting responses "
                               f"{response_gb(count, level):.1f} GB > --max-response-gb)")
                print(skipped[-1], flush=True)
                continue
            cmd = [sys.executable, "-m", "fbmbench", "particle_scaling", "--one", coupling, str(count),
                   "--level", str(level), "--diameter", repr(diameter), "--steps", str(steps)]
            out = subprocess.run(cmd, capture_output=True, text=True, cwd=BENCHMARKS)
            found = [line for line in out.stdout.splitlines() if line.startswith("ROW ")]
            if out.returncode != 0 or not found:
                sys.stderr.write(out.stderr[-3000:])
                raise SystemExit(f"{coupling}, {count} disks failed (exit {out.returncode})")
            row = json.loads(found[-1][4:])
            row.update(label=label, date=str(date.today()), n_steps=steps, note=note,
                       measured_step=steps - 1, skipped=skipped)
            timed = row["steps"][1:steps] or row["steps"][:1]
            row["median"] = {key: float(statistics.median(t[key] for t in timed)) for key in
                             ("wall_s", "linear_s", "outside_s", "contact_s")}
            row["median"]["flow_solves"] = timed[-1]["flow_solves"]
            s = row["median"]
            print(f"{coupling:8s} {count:5d} disks: step {s['wall_s']:.2f} s, linear {s['linear_s']:.2f} s, "
                  f"outside {s['outside_s']:.2f} s ({s['outside_s'] / s['wall_s']:.0%}), "
                  f"peak {row['max_rss_gb']:.2f} GB", flush=True)
            rows = [r for r in rows if (r["label"], r["coupling"], r["count"]) != (label, coupling, count)]
            rows.append(row)
            write(rows)
    for r in rows:
        if r["label"] == label:
            r["skipped"] = skipped
    write(rows)
