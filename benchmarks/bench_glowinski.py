"""Glowinski's free fall of a disk: convergence in the mesh level and in the time step.

Run:  python benchmarks/bench_glowinski.py [--levels 2 3 4] [--dts 0.004 0.002 0.001] [--dt-level 3]
      [--mesh graded|uniform] [--boundary sharp|nodes] [--scheme crank-nicolson|backward-euler]
      [--t-end 0.65] [--reuse]

Writes ``benchmarks/results/glowinski.md``, ``.json`` and ``.png`` for the scene's defaults (sharp
fictitious boundary, Crank–Nicolson with the trapezoidal particle integrator; ``glowinski-be.*``
with ``--scheme backward-euler``, backward Euler with semi-implicit Euler), ``glowinski-nodes.*``
with ``--boundary nodes`` and ``glowinski-uniform.*`` with ``--mesh uniform`` (older studies of the
nodal boundary, with backward Euler, that ``--boundary nodes`` picks by default): per run the level, cells
across the diameter, unknowns, time step, wall time (JIT excluded: a short warm-up run first),
maximum settling velocity and Reynolds number, final height, the relative change of the
maximum settling velocity against the next finer run, its deviation from Koblitz et al.'s (2017)
overset-grid peak and the largest deviation of the velocity curve from theirs (relative to their
peak, after the first 0.05 s where the digitised points scatter). A run that fails (the disk
reaching the bottom before ``t_end``) keeps its curve up to its last good step. With ``--reuse``
a run already in the results file (same mesh kind, level, time step and end time) is taken from
there with the wall time and linear solver it was measured with, instead of being run again.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from fbmflow.params import from_dict
from fbmflow.scenes import get_scene
from fbmflow.scenes.data import koblitz2017

RESULTS = Path(__file__).parent / "results"


INTEGRATOR = {"crank-nicolson": "trapezoidal", "backward-euler": "semi-implicit-euler"}  # second / first order


def run(scene, level, dt, t_end, mesh="graded", boundary="sharp", scheme="crank-nicolson"):
    params = from_dict(scene.Params, {"time": {"dt": dt, "t_end": t_end, "scheme": scheme},
                                      "coupling": {"integrator": INTEGRATOR[scheme]},
                                      "domain": {"mesh": mesh}, "fbm": {"boundary": boundary}})
    t0 = time.perf_counter()
    result = scene.run(params, level, stop_on_failure=True)
    q = result.quantities
    row = dict(level=level, cells_per_diameter=2**level, n_dofs=result.n_dofs, dt=dt,
               wall_s=time.perf_counter() - t0, linear_solver=result.linear_solver,
               newton=result.newton_iterations,
               max_settling_velocity=q["max_settling_velocity"], max_reynolds_number=q["max_reynolds_number"],
               final_y=q["final_position"][1], t=q["t"], v=q["v"],
               vs_koblitz=q["max_settling_velocity"] / koblitz2017.V_MAX - 1,
               curve_deviation=curve_deviation(q["t"], q["v"]), failure=result.extra.get("failure"))
    print(f"level {level} dt {dt}: {row['n_dofs']} unknowns, {row['wall_s']:.1f} s, "
          f"v_max {row['max_settling_velocity']:.4f} cm/s, Re_max {row['max_reynolds_number']:.3f}, "
          f"y_end {row['final_y']:.4f}", flush=True)
    return row


def curve_deviation(t, v) -> float:
    """Largest ``|v - v_K| / V_MAX`` over Koblitz et al.'s samples with 0.05 s <= t <= the run's end
    (NaN for a run that ends earlier)."""
    ref = koblitz2017.VELOCITY
    ref = ref[(ref[:, 0] >= 0.05) & (ref[:, 0] <= t[-1])]
    if len(ref) == 0:
        return float("nan")
    return float(np.max(np.abs(np.interp(ref[:, 0], t, -np.asarray(v)) - ref[:, 1])) / koblitz2017.V_MAX)


def table(rows, key):
    lines = [f"| level | cells/D | unknowns | dt s | linear solver | wall s | v_max cm/s | Re_max | y(t_end) cm "
             f"| change of v_max vs finer {key} | v_max vs Koblitz | curve vs Koblitz |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for a, b in zip(rows, rows[1:] + [None]):
        change = "" if b is None else f"{100 * abs(a['max_settling_velocity'] / b['max_settling_velocity'] - 1):.2f} %"
        end = f"{a['final_y']:.4f}" + (" (failed)" if a.get("failure") else "")
        # rows measured before the solver was recorded ran on SuperLU (then the only 2D direct backend)
        lines.append(f"| {a['level']} | {a['cells_per_diameter']} | {a['n_dofs']} | {a['dt']} | "
                     f"{a.get('linear_solver', 'direct (SuperLU)')} | {a['wall_s']:.1f} | "
                     f"{a['max_settling_velocity']:.4f} | {a['max_reynolds_number']:.3f} | {end} | {change} | "
                     f"{100 * a['vs_koblitz']:+.2f} % | {100 * a['curve_deviation']:.2f} % |")
    return lines


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--levels", type=int, nargs="+", default=[1, 2, 3])
    ap.add_argument("--dts", type=float, nargs="+", default=[0.004, 0.002, 0.001])
    ap.add_argument("--dt", type=float, default=0.002, help="time step of the mesh study")
    ap.add_argument("--dt-level", type=int, default=2, help="level of the time-step study")
    ap.add_argument("--t-end", type=float, default=0.65, help="past the peak, before the landing")
    ap.add_argument("--mesh", default="graded", choices=("graded", "uniform"),
                    help="graded: uniform cells along the disk's path only (domain.mesh)")
    ap.add_argument("--boundary", default="sharp", choices=("sharp", "nodes"), help="fbm.boundary")
    ap.add_argument("--scheme", choices=tuple(INTEGRATOR),
                    help="time.scheme, with the trapezoidal (Crank–Nicolson) or semi-implicit Euler (backward "
                         "Euler) particle integrator; default: crank-nicolson for the sharp boundary, "
                         "backward-euler for the nodal one (its stored study)")
    ap.add_argument("--reuse", action="store_true",
                    help="take runs already in the results file instead of running them again")
    args = ap.parse_args()
    scene = get_scene("glowinski-free-fall")
    if args.mesh == "uniform" and (args.boundary == "sharp" or args.scheme == "crank-nicolson"):
        ap.error("the uniform-mesh study is one of the nodal boundary with backward Euler (--boundary nodes)")
    scheme = args.scheme or ("crank-nicolson" if args.boundary == "sharp" else "backward-euler")
    if args.mesh == "uniform":
        stem = "glowinski-uniform"
    elif args.boundary == "nodes":
        stem = "glowinski-nodes" + ("" if scheme == "backward-euler" else "-cn")
    else:
        stem = "glowinski" + ("" if scheme == "crank-nicolson" else "-be")
    run(scene, 0, 0.002, 0.004)  # JIT warm-up
    RESULTS.mkdir(exist_ok=True)
    mesh_rows, time_rows = [], []
    done = []
    if args.reuse and (RESULTS / f"{stem}.json").exists():
        old = json.loads((RESULTS / f"{stem}.json").read_text())
        done = [r for r in old["mesh"] + old["time"]  # runs to this t_end, or failed before it
                if abs(r["t"][-1] - args.t_end) < r["dt"] / 2 or (r.get("failure") and r["t"][-1] < args.t_end)]

    def measured(level, dt):
        """The row of ``level`` and ``dt``: from this invocation, ``--reuse``'d, or run now."""
        for r in mesh_rows + time_rows + done:
            if r["level"] == level and r["dt"] == dt:
                if r in done:
                    print(f"level {level} dt {dt}: reused ({r['wall_s']:.1f} s, v_max {r['max_settling_velocity']:.4f} cm/s)")
                return r
        return run(scene, level, dt, args.t_end, args.mesh, args.boundary, scheme)

    def save():  # after every run, so that an interrupted study keeps what it measured
        (RESULTS / f"{stem}.json").write_text(json.dumps({"mesh": mesh_rows, "time": time_rows}))

    def time_study():
        for dt in args.dts:
            time_rows.append(measured(args.dt_level, dt))
            save()

    for lv in args.levels:  # cheapest first: the time-step study right after its level
        mesh_rows.append(measured(lv, args.dt))
        save()
        if lv == args.dt_level:
            time_study()
    if args.dt_level not in args.levels:
        time_study()
    time_rows.sort(key=lambda r: -r["dt"])
    lines = [f"# Glowinski free fall of a disk, {args.boundary} fictitious boundary (benchmarks/bench_glowinski.py)", "",
             f"Disk d = 0.25 cm, rho_s/rho_f = 1.25, 2 x 6 cm closed channel, {args.mesh} mesh, {args.boundary} "
             f"fictitious boundary, implicit coupling, {scheme} with the {INTEGRATOR[scheme]} particle integrator; "
             "wall time without the JIT compilation (runs measured with other jobs beside them).",
             f"References: Koblitz et al. (2017), overset grid: v_max {koblitz2017.V_MAX:.3f} cm/s "
             f"(Re_max {koblitz2017.RE_MAX:.2f}); Glowinski et al. (2001) and Wan & Turek (2006): Re_max about 17.3. "
             "'curve vs Koblitz': largest |v - v_Koblitz| / v_max,Koblitz for t >= 0.05 s.", "",
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
    for ax in axes:
        ax.plot(*koblitz2017.VELOCITY.T, "k.", ms=3, label="Koblitz et al. 2017")
    for ax, title in zip(axes, ("mesh", f"time step (level {args.dt_level})")):
        ax.set_xlabel("t [s]"); ax.set_ylabel("settling velocity [cm/s]"); ax.set_title(title); ax.legend()
    fig.tight_layout()
    fig.savefig(RESULTS / f"{stem}.png", dpi=120)


if __name__ == "__main__":
    main()
