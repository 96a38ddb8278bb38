"""Cost of a time step against the particle count at a fixed mesh (issue 29, item 1).

Run:  python benchmarks/bench_particle_scaling.py [--counts 10 100 1000]
      [--couplings explicit stabilised implicit]
      [--level 2] [--diameter 0.03] [--steps 6] [--label after] [--max-response-gb 2.0]

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

import argparse
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

RESULTS = Path(os.environ.get("FBMFLOW_BENCH_RESULTS", Path(__file__).resolve().parent / "results"))
SCENE = "sedimentation-2d"
#: functions whose cumulative time the breakdown names where they exist (file suffix, function)
NAMED = [("coupling/schemes.py", "advance", "coupling scheme (all of the step but contact)"),
         ("simulation.py", "flow_and_forces", "flow solves with their forces"),
         ("flow/navier_stokes.py", "solve", "Newton solves"),
         ("simulation.py", "rigid_responses", "lifting responses with their forces"),
         ("simulation.py", "own_stiffness", "own stiffness (stabilised coupling)"),
         ("flow/navier_stokes.py", "lifting_response", "lifting responses (flow)"),
         ("simulation.py", "_forces", "hydrodynamic forces"),
         ("simulation.py", "_response_forces", "hydrodynamic forces of the responses"),
         ("coupling/indicator.py", "node_owner", "node owner"),
         ("coupling/indicator.py", "rigid_body_constraints", "rigid-body constraints"),
         ("coupling/indicator.py", "rigid_liftings", "rigid liftings"),
         ("simulation.py", "integrate", "particle integration and contact"),
         ("contact/contact_set.py", "advance", "contact")]


def one(count: int, coupling: str, level: int, diameter: float, steps: int) -> dict:
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
            "max_rss_gb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6,
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
             "Command: `python benchmarks/bench_particle_scaling.py` (options in the rows below); 2-core "
             "machine shared with other jobs, every run under `nice -n 19`. Each row: one child process, "
             "the median of the timed steps after the first (the first from rest and the profiled one "
             "left out; rows without a median: the last timed step); `outside` is the "
             "step's wall time less `StepReport.linear.time_s`. Runs of different versions were made one "
             "after the other, not at once.", ""]
    for label in sorted({r["label"] for r in rows}):
        first = next(r for r in rows if r["label"] == label)
        lines.append(f"- `{label}`: {first['date']}, level {first['level']}, diameter "
                     f"{first['diameter']} cm, {first['n_steps']} timed steps, {first.get('note', '')}")
    lines += [""] + table(rows) + ["", "## Profile of one step (cProfile, the step after the timed ones)", ""]
    for r in sorted(rows, key=lambda r: (r["label"], r["coupling"], r["count"])):
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


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--counts", type=int, nargs="+", default=[10, 100, 1000])
    ap.add_argument("--couplings", nargs="+", default=["explicit", "stabilised", "implicit"],
                    choices=["explicit", "stabilised", "implicit"])
    ap.add_argument("--level", type=int, default=2)
    ap.add_argument("--diameter", type=float, default=0.03, help="disk diameter [cm]")
    ap.add_argument("--steps", type=int, default=6, help="timed steps (then one profiled step); the table "
                    "gives the median of all but the first")
    ap.add_argument("--label", default="current", help="version label of this run's rows")
    ap.add_argument("--note", default="", help="a note on this run (the commit, the machine's load)")
    ap.add_argument("--max-response-gb", type=float, default=2.0,
                    help="skip implicit runs whose dense lifting responses exceed this [GB]")
    ap.add_argument("--one", nargs=2, metavar=("COUPLING", "COUNT"), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.one:
        row = one(int(args.one[1]), args.one[0], args.level, args.diameter, args.steps)
        print("ROW " + json.dumps(row))
        return
    path = RESULTS / "particle_scaling.json"
    rows = json.loads(path.read_text()) if path.exists() else []
    skipped = []
    for coupling in args.couplings:
        for count in args.counts:
            if coupling == "implicit" and response_gb(count, args.level) > args.max_response_gb:
                skipped.append(f"implicit, {count} disks (dense lifting responses "
                               f"{response_gb(count, args.level):.1f} GB > --max-response-gb)")
                print(skipped[-1], flush=True)
                continue
            cmd = [sys.executable, __file__, "--one", coupling, str(count), "--level", str(args.level),
                   "--diameter", repr(args.diameter), "--steps", str(args.steps)]
            out = subprocess.run(cmd, capture_output=True, text=True)
            found = [line for line in out.stdout.splitlines() if line.startswith("ROW ")]
            if out.returncode != 0 or not found:
                sys.stderr.write(out.stderr[-3000:])
                raise SystemExit(f"{coupling}, {count} disks failed (exit {out.returncode})")
            row = json.loads(found[-1][4:])
            row.update(label=args.label, date=str(date.today()), n_steps=args.steps, note=args.note,
                       measured_step=args.steps - 1, skipped=skipped)
            timed = row["steps"][1:args.steps] or row["steps"][:1]
            row["median"] = {key: float(statistics.median(t[key] for t in timed)) for key in
                             ("wall_s", "linear_s", "outside_s", "contact_s")}
            row["median"]["flow_solves"] = timed[-1]["flow_solves"]
            s = row["median"]
            print(f"{coupling:8s} {count:5d} disks: step {s['wall_s']:.2f} s, linear {s['linear_s']:.2f} s, "
                  f"outside {s['outside_s']:.2f} s ({s['outside_s'] / s['wall_s']:.0%}), "
                  f"peak {row['max_rss_gb']:.2f} GB", flush=True)
            rows = [r for r in rows if (r["label"], r["coupling"], r["count"]) != (args.label, coupling,
                                                                                    count)]
            rows.append(row)
            write(rows)
    for r in rows:
        if r["label"] == args.label:
            r["skipped"] = skipped
    write(rows)


if __name__ == "__main__":
    main()
