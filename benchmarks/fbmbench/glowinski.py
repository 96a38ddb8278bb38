"""Glowinski's free fall of a disk against Koblitz et al. (2017): mesh levels and time steps.

Disk d = 0.25 cm, rho_s/rho_f = 1.25, in a closed 2 x 6 cm box (scene ``glowinski-free-fall``).
Reference: Koblitz et al.'s overset-grid curve (``fbmflow.scenes.data.koblitz2017``), peak
5.591 cm/s (Re_max 13.98). Per run: unknowns, wall time, the peak settling velocity and its
deviation from Koblitz et al.'s peak, and the largest deviation of the velocity curve from
theirs after 0.05 s (relative to their peak).

Results: ``benchmarks/results/glowinski.*`` for the scene's defaults (sharp boundary,
Crank–Nicolson with the trapezoidal particle integrator), ``glowinski-be.*`` with backward Euler,
``glowinski-nodes.*`` for the nodal boundary (backward Euler) and ``glowinski-uniform.*`` for
that on a uniform mesh; ``glowinski-tradeoff.png`` draws the error against the wall time.
"""

from __future__ import annotations

import numpy as np

from fbmflow.flow.time_schemes import pressure_lag
from fbmflow.scenes.data import koblitz2017

from .common import (
    RESULTS,
    cpu,
    load_rows,
    merge_row,
    provenance,
    run_scene,
    tradeoff_plot,
    warm_up,
    write_text,
)

SCENE = "glowinski-free-fall"
INTEGRATOR = {"crank-nicolson": "trapezoidal", "backward-euler": "semi-implicit-euler"}
LABELS = {
    "glowinski": "sharp, Crank–Nicolson",
    "glowinski-be": "sharp, backward Euler",
    "glowinski-nodes": "nodal, backward Euler",
    "glowinski-nodes-cn": "nodal, Crank–Nicolson",
    "glowinski-uniform": "nodal, backward Euler, uniform mesh, to 0.5 s",
}
STEMS = ("glowinski", "glowinski-be", "glowinski-nodes", "glowinski-nodes-cn", "glowinski-uniform")


def stem(mesh: str = "graded", boundary: str = "sharp", scheme: str = "crank-nicolson") -> str:
    """The results file of a study."""
    if mesh == "uniform":
        return "glowinski-uniform"
    if boundary == "nodes":
        return "glowinski-nodes" + ("" if scheme == "backward-euler" else "-cn")
    return "glowinski" + ("" if scheme == "crank-nicolson" else "-be")


def curve_deviation(t, v) -> float:
    """Largest ``|v - v_K| / V_MAX`` over Koblitz et al.'s samples with 0.05 s <= t <= the run's
    end (NaN for a run that ends earlier)."""
    ref = koblitz2017.VELOCITY
    ref = ref[(ref[:, 0] >= 0.05) & (ref[:, 0] <= t[-1])]
    if len(ref) == 0:
        return float("nan")
    return float(np.max(np.abs(np.interp(ref[:, 0], t, -np.asarray(v)) - ref[:, 1])) / koblitz2017.V_MAX)


def run(
    level: int,
    dt: float,
    t_end: float = 0.65,
    mesh: str = "graded",
    boundary: str = "sharp",
    scheme: str = "crank-nicolson",
) -> dict:
    """One run of the scene; the result row."""
    warm_up(SCENE, **{"time.t_end": 0.004})
    settings = {
        "time.dt": dt,
        "time.t_end": t_end,
        "time.scheme": scheme,
        "coupling.integrator": INTEGRATOR[scheme],
        "domain.mesh": mesh,
        "fbm.boundary": boundary,
    }
    s = run_scene(SCENE, level, settings)
    q = s["quantities"]
    row = dict(
        level=level,
        cells_per_diameter=2**level,
        n_dofs=s["n_dofs"],
        dt=dt,
        t_end=t_end,
        mesh=mesh,
        boundary=boundary,
        scheme=scheme,
        pressure_lag=pressure_lag(scheme),
        wall_s=s["wall_s"],
        stopped_s=s["stopped_s"],
        cpu_s=s["cpu_s"],
        linear_solver=s["linear_solver"],
        newton=s["newton_iterations"],
        steps=s["steps"],
        max_settling_velocity=q["max_settling_velocity"],
        max_reynolds_number=q["max_reynolds_number"],
        final_y=q["final_position"][1],
        t=q["t"],
        v=q["v"],
        vs_koblitz=q["max_settling_velocity"] / koblitz2017.V_MAX - 1,
        curve_deviation=curve_deviation(q["t"], q["v"]),
        **provenance(),
    )
    print(
        f"glowinski level {level} dt {dt}: {row['n_dofs']} unknowns, {row['wall_s']:.1f} s, "
        f"v_max {row['max_settling_velocity']:.4f} cm/s ({100 * row['vs_koblitz']:+.2f} % vs Koblitz), "
        f"curve {100 * row['curve_deviation']:.2f} %",
        flush=True,
    )
    return row


KEY = ("level", "dt", "t_end", "mesh", "boundary", "scheme", "pressure_lag")


def key(row: dict) -> tuple:
    return tuple(row.get(k, 0.0 if k == "pressure_lag" else None) for k in KEY)


def record(row: dict) -> list[dict]:
    """Merge ``row`` into its results file and redraw that study's table and plots."""
    name = stem(row["mesh"], row["boundary"], row["scheme"])
    rows = merge_row(name, row, lambda a, b: key(a) == key(b))
    write(name, rows)
    plot_tradeoff()
    return rows


def _code(row: dict) -> str:
    """Rows of Crank–Nicolson runs from before the pressure's force was lagged half a step
    (docs/method.md) record no lag."""
    return "pressure unlagged" if row["scheme"] == "crank-nicolson" and not row.get("pressure_lag") else ""


def groups(rows: list[dict]) -> tuple[dict, dict]:
    """``(mesh, time)``: rows by (dt, t_end, code) over levels, and by (level, t_end, code) over
    time steps where a level has several."""
    mesh: dict = {}
    times: dict = {}
    for r in rows:
        mesh.setdefault((r["dt"], r["t_end"], _code(r)), []).append(r)
        times.setdefault((r["level"], r["t_end"], _code(r)), []).append(r)
    mesh = {
        k: sorted(v, key=lambda r: r["level"])
        for k, v in sorted(mesh.items(), key=lambda kv: (kv[0][2], -kv[0][0]))
    }
    times = {k: sorted(v, key=lambda r: -r["dt"]) for k, v in sorted(times.items()) if len(v) > 1}
    return mesh, times


def table(rows: list[dict], versus: str | None) -> list[str]:
    """Markdown rows; ``versus`` names what the change column compares (None: no comparison)."""
    lines = [
        f"| level | cells/D | unknowns | dt s | linear solver | wall s | CPU s | v_max cm/s | Re_max "
        "| y(t_end) cm "
        f"| {'change of v_max vs finer ' + versus if versus else 'change of v_max'} "
        "| v_max vs Koblitz | curve vs Koblitz | measured |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for a, b in zip(rows, rows[1:] + [None]):
        change = (
            ""
            if b is None or versus is None
            else f"{100 * abs(a['max_settling_velocity'] / b['max_settling_velocity'] - 1):.2f} %"
        )
        end = f"{a['final_y']:.4f}" + (" (failed)" if a.get("failure") else "")
        # rows measured before the solver was recorded ran on SuperLU (then the only 2D direct backend)
        lines.append(
            f"| {a['level']} | {a['cells_per_diameter']} | {a['n_dofs']} | {a['dt']} | "
            f"{a.get('linear_solver', 'direct (SuperLU)')} | {a['wall_s']:.1f} | {cpu(a)} | "
            f"{a['max_settling_velocity']:.4f} | {a['max_reynolds_number']:.3f} | {end} | {change} | "
            f"{100 * a['vs_koblitz']:+.2f} % | {100 * a['curve_deviation']:.2f} % | "
            f"{a.get('date', 'earlier session')} {a.get('commit', '')} |"
        )
    return lines


def write(name: str, rows: list[dict]) -> None:
    """``results/<name>.md`` and ``.png`` from all rows of that study."""
    if not rows:
        return
    r0 = rows[0]
    scheme = r0["scheme"]
    mesh_groups, time_groups = groups(rows)
    lines = [
        f"# Glowinski free fall of a disk, {r0['boundary']} fictitious boundary ({name})",
        "",
        f"Disk d = 0.25 cm, rho_s/rho_f = 1.25, 2 x 6 cm closed channel, {r0['mesh']} mesh, {r0['boundary']} "
        f"fictitious boundary, implicit coupling, {scheme} with the {INTEGRATOR[scheme]} particle "
        "integrator. "
        "Wall time of the run without the JIT compilation, on a 2-core machine with other jobs beside most "
        "runs (upper bounds). Reproduce a row: `python -m fbmbench glowinski --levels L --dt DT "
        "--t-end T` (plus `--boundary`, `--scheme`, `--mesh` for the other studies), or the pytest "
        "benchmark `python -m pytest benchmarks -k glowinski`.",
        f"References: Koblitz et al. (2017), overset grid: v_max {koblitz2017.V_MAX:.3f} cm/s "
        f"(Re_max {koblitz2017.RE_MAX:.2f}); Glowinski et al. (2001) and Wan & Turek (2006): "
        "Re_max about 17.3. "
        "'curve vs Koblitz': largest |v - v_Koblitz| / v_max,Koblitz for t >= 0.05 s. 'pressure unlagged': "
        "Crank–Nicolson runs from before the particle's pressure force was taken half a step back "
        "(docs/method.md); the other rows ran today's scheme.",
    ]
    shown = []
    for (dt, t_end, code), group in mesh_groups.items():
        if len(group) > 1:
            lines += ["", f"## Mesh levels (dt = {dt} s, t_end = {t_end} s{', ' + code if code else ''})", ""]
            lines += table(group, "level")
            shown += group
    for (level, t_end, code), group in time_groups.items():
        lines += ["", f"## Time steps (level {level}, t_end = {t_end} s{', ' + code if code else ''})", ""]
        lines += table(group, "dt")
        shown += group
    others = sorted((r for r in rows if not any(r is s for s in shown)), key=lambda r: (r["level"], -r["dt"]))
    if others:
        lines += ["", "## Other runs", ""] + table(others, None)
    write_text(RESULTS / f"{name}.md", "\n".join(lines) + "\n")
    plot_curves(name, mesh_groups, time_groups)


def plot_curves(name: str, mesh_groups: dict, time_groups: dict) -> None:
    """The settling velocity over Koblitz et al.'s: the mesh study and the time-step study with the
    most runs (today's scheme first)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    def pick(g):
        return max(g.items(), key=lambda kv: (kv[0][2] == "", len(kv[1]))) if g else None

    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for ax, chosen, what in ((axes[0], pick(mesh_groups), "mesh"), (axes[1], pick(time_groups), "time step")):
        if chosen is None:
            ax.set_visible(False)
            continue
        (a, t_end, code), rows = chosen
        for r in rows:
            label = (
                f"level {r['level']} ({r['cells_per_diameter']} cells/D)"
                if what == "mesh"
                else f"dt = {r['dt']} s"
            )
            ax.plot(r["t"], [-v for v in r["v"]], label=label)
        ax.plot(*koblitz2017.VELOCITY.T, "k.", ms=3, label="Koblitz et al. 2017")
        where = f"dt {a} s" if what == "mesh" else f"level {a}"
        ax.set(
            xlabel="t [s]",
            ylabel="settling velocity [cm/s]",
            title=f"{what} ({where}{', ' + code if code else ''})",
        )
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(RESULTS / f"{name}.png", dpi=120)
    plt.close(fig)


def plot_tradeoff() -> None:
    """``glowinski-tradeoff.png``: |v_max vs Koblitz| against the wall time over the mesh levels,
    one line per study and time step with at least two levels."""
    curves = {}
    for name in STEMS:
        mesh_groups, _ = groups(load_rows(name))
        for (dt, t_end, code), rows in mesh_groups.items():
            if len(rows) > 1:
                label = f"{LABELS[name]}, dt {dt} s{', ' + code if code else ''}"
                curves[label] = [
                    (r["wall_s"], abs(r["vs_koblitz"]), f"{r['cells_per_diameter']}/D") for r in rows
                ]
    tradeoff_plot(
        RESULTS / "glowinski-tradeoff.png",
        curves,
        "|v_max / v_max,Koblitz - 1|",
        "Glowinski free fall: peak settling velocity against cost (labels: cells per diameter)",
    )
