"""Glowinski's free fall of a disk: convergence in the mesh level and in the time step.

Run:  python benchmarks/bench_glowinski.py [--levels 2 3 4] [--dts 0.004 0.002 0.001] [--dt-level 3]
      [--mesh graded|uniform]

Writes ``benchmarks/results/glowinski.md``, ``.json`` and ``.png`` (``glowinski-uniform.*`` with
``--mesh uniform``): per run the level, cells
across the diameter, unknowns, time step, wall time (JIT excluded: a short warm-up run first),
maximum settling velocity and Reynolds number, final height, and the relative change of the
maximum settling velocity against the next finer run.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from fbmflow.params import from_dict
from fbmflow.scenes import get_scene

RESULTS = Path(__file__).parent / "results"


def run(scene, level, dt, t_end, mesh="graded"):
    params = from_dict(scene.Params, {"time": {"dt": dt, "t_end": t_end}, "domain": {"mesh": mesh}})
    t0 = time.perf_counter()
    result = scene.run(params, level)
    q = result.quantities
    row = dict(level=level, cells_per_diameter=2**level, n_dofs=result.n_dofs, dt=dt,
               wall_s=time.perf_counter() - t0, newton=result.newton_iterations,
               max_settling_velocity=q["max_settling_velocity"], max_reynolds_number=q["max_reynolds_number"],
               final_y=q["final_position"][1], t=q["t"], v=q["v"])
    print(f"level {level} dt {dt}: {row['n_dofs']} unknowns, {row['wall_s']:.1f} s, "
          f"v_max {row['max_settling_velocity']:.4f} cm/s, Re_max {row['max_reynolds_number']:.3f}, "
          f"y_end {row['final_y']:.4f}", flush=True)
    return row


def table(rows, key):
    lines = [f"| level | cells/D | unknowns | dt s | wall s | v_max cm/s | Re_max | y(t_end) cm | change of v_max vs finer {key} |",
             "|---|---|---|---|---|---|---|---|---|"]
    for a, b in zip(rows, rows[1:] + [None]):
        change = "" if b is None else f"{100 * abs(a['max_settling_velocity'] / b['max_settling_velocity'] - 1):.2f} %"
        lines.append(f"| {a['level']} | {a['cells_per_diameter']} | {a['n_dofs']} | {a['dt']} | {a['wall_s']:.1f} | "
                     f"{a['max_settling_velocity']:.4f} | {a['max_reynolds_number']:.3f} | {a['final_y']:.4f} | {change} |")
    return lines


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--levels", type=int, nargs="+", default=[1, 2, 3])
    ap.add_argument("--dts", type=float, nargs="+", default=[0.004, 0.002, 0.001])
    ap.add_argument("--dt", type=float, default=0.002, help="time step of the mesh study")
    ap.add_argument("--dt-level", type=int, default=2, help="level of the time-step study")
    ap.add_argument("--t-end", type=float, default=0.5)
    ap.add_argument("--mesh", default="graded", choices=("graded", "uniform"),
                    help="graded: uniform cells along the disk's path only (domain.mesh)")
    args = ap.parse_args()
    scene = get_scene("glowinski-free-fall")
    stem = "glowinski" if args.mesh == "graded" else "glowinski-uniform"
    run(scene, 0, 0.002, 0.004)  # JIT warm-up
    RESULTS.mkdir(exist_ok=True)
    mesh_rows, time_rows = [], []

    def save():  # after every run, so that an interrupted study keeps what it measured
        (RESULTS / f"{stem}.json").write_text(json.dumps({"mesh": mesh_rows, "time": time_rows}))

    for lv in args.levels:
        mesh_rows.append(run(scene, lv, args.dt, args.t_end, args.mesh))
        save()
    for dt in args.dts:
        same = [r for r in mesh_rows if r["level"] == args.dt_level and r["dt"] == dt]
        time_rows.append(same[0] if same else run(scene, args.dt_level, dt, args.t_end, args.mesh))
        save()
    time_rows.sort(key=lambda r: -r["dt"])
    lines = ["# Glowinski free fall of a disk (benchmarks/bench_glowinski.py)", "",
             f"Disk d = 0.25 cm, rho_s/rho_f = 1.25, 2 x 6 cm closed channel, {args.mesh} mesh, implicit coupling, "
             "backward Euler; wall time without the JIT compilation.",
             f"Literature: Re_max about 17.3 (Glowinski et al. 2001; Wan & Turek 2006).", "",
             f"## Mesh levels (dt = {args.dt} s)", ""] + table(mesh_rows, "level") + [
             "", f"## Time steps (level {args.dt_level})", ""] + table(time_rows, "dt")
    (RESULTS / f"{stem}.md").write_text("\n".join(lines) + "\n")
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for r in mesh_rows:
        axes[0].plot(r["t"], [-v for v in r["v"]], label=f"level {r['level']} ({r['cells_per_diameter']} cells/D)")
    for r in time_rows:
        axes[1].plot(r["t"], [-v for v in r["v"]], label=f"dt = {r['dt']} s")
    for ax, title in zip(axes, ("mesh", f"time step (level {args.dt_level})")):
        ax.set_xlabel("t [s]"); ax.set_ylabel("settling velocity [cm/s]"); ax.set_title(title); ax.legend()
    fig.tight_layout()
    fig.savefig(RESULTS / f"{stem}.png", dpi=120)


if __name__ == "__main__":
    main()
