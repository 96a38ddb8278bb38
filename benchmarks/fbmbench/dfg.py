"""DFG 2D-1 and 3D-1Z (Schäfer & Turek 1996): steady flow around a cylinder that is a fixed
fictitious boundary, Re = 20; drag, lift and pressure difference against the reference values
per mesh level.

Results: ``benchmarks/results/<scene>.md``, ``.json``, ``.png`` (drag error against cells per
diameter and against wall time) and ``<scene>-tradeoff.png``.
"""

from __future__ import annotations

from fbmflow.scenes.registry import load_scene

from .common import (
    RESULTS,
    cpu,
    merge_row,
    percent,
    provenance,
    run_scene,
    tradeoff_plot,
    warm_up,
    write_text,
)

SCENES = ("dfg-2d-1", "dfg-3d-1z")
QUANTITIES = ("drag_coefficient", "lift_coefficient", "pressure_difference")
#: each scene's mesh as the rows record it: dfg-2d-1's is ``centred`` (the cylinder's centre on a
#: node at every level, fbmflow.scenes.dfg.centred_axis) since 2026-11-28; rows from before it
#: ran on the uniform ``box``
MESH = {"dfg-2d-1": "centred", "dfg-3d-1z": "graded"}
OLD_MESH = {"dfg-2d-1": "box", "dfg-3d-1z": "graded"}


def run(scene: str, level: int, solver: str = "direct", boundary: str | None = None) -> dict:
    """One steady solve (``boundary``: fbm.boundary, None: the scene's default); the row."""
    settings = {"solver.linear": solver, **({"fbm.boundary": boundary} if boundary else {})}
    warm_up(scene, 1, **settings)  # (level 0, one cell per diameter, may not converge)
    s = run_scene(scene, level, settings)
    q = s["quantities"]
    row = dict(
        level=level,
        mesh=MESH[scene],
        solver=solver,
        boundary=s["params"]["fbm"]["boundary"],
        cells_per_diameter=q["cells_per_diameter"],
        n_dofs=s["n_dofs"],
        wall_s=s["wall_s"],
        stopped_s=s["stopped_s"],
        cpu_s=s["cpu_s"],
        newton=s["newton_iterations"],
        linear_solver=s["linear_solver"],
        **{k: q[k] for k in QUANTITIES},
        **{k + "_error": q.get(k + "_error") for k in QUANTITIES},
        **provenance(),
    )
    print(
        f"{scene} level {level}: {row['n_dofs']} unknowns, {row['wall_s']:.1f} s, "
        f"C_D {row['drag_coefficient']:.4f} ({percent(row['drag_coefficient_error'])}), "
        f"C_L {row['lift_coefficient']:+.4f}, dp {percent(row['pressure_difference_error'])}",
        flush=True,
    )
    return row


def _key(scene: str, r: dict) -> tuple:
    """Rows from before the boundary was recorded ran the nodal one."""
    return r["level"], r.get("solver", "direct"), r.get("boundary", "nodes"), mesh(scene, r)


def mesh(scene: str, r: dict) -> str:
    """The mesh a row ran on (:data:`MESH`)."""
    return r.get("mesh", OLD_MESH[scene])


def record(scene: str, row: dict) -> list[dict]:
    rows = merge_row(scene, row, lambda a, b: _key(scene, a) == _key(scene, b))
    write(scene, rows)
    return rows


def write(scene: str, rows: list[dict]) -> None:
    rows = sorted(rows, key=lambda r: (mesh(scene, r) != MESH[scene], r.get("boundary", "nodes"),
                                       r.get("solver", "direct"), r["level"]))
    the_scene = load_scene(scene)[0]
    refs = ", ".join(f"{k} = {v}" for k, v in the_scene.reference.items())
    lines = [
        f"# {the_scene.description} ({scene})",
        "",
        f"Reference {refs} (docstring of fbmflow.scenes.dfg). Wall time of the run on a 2-core machine "
        "(assembly, all Newton "
        "steps and the force evaluation, not the JIT compilation); PARDISO, when installed, takes 3D "
        "systems and 2D ones from 40 000 unknowns. Reproduce a row: `python -m fbmbench dfg "
        f"--scene {scene} --levels L`, or `python -m pytest benchmarks -k {scene.replace('-', '_')}`. "
        "Mesh: the scene's (" + MESH[scene] + "), or the one it had when the row was measured "
        "(docstring of fbmbench.dfg.MESH).",
        "",
        "| mesh | boundary | level | cells/D | unknowns | linear solver | wall s | CPU s | Newton "
        "| C_D | err C_D | C_L | err C_L | dp | err dp | measured |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    lines += [
        f"| {mesh(scene, r)} | {r.get('boundary', 'nodes')} | {r['level']} | {r['cells_per_diameter']:.1f} | "
        f"{r['n_dofs']} | {r['linear_solver']} | "
        f"{r['wall_s']:.1f} | {cpu(r)} | "
        f"{r['newton']} | {r['drag_coefficient']:.4f} | {percent(r['drag_coefficient_error'], '.2f')} | "
        f"{r['lift_coefficient']:+.4f} | "
        f"{signed(r['lift_coefficient'], the_scene.reference['lift_coefficient'])} | "
        f"{r['pressure_difference']:.4f} | "
        f"{percent(r.get('pressure_difference_error'), '.2f')} | {r.get('date', 'earlier session')} "
        f"{r.get('commit', '')} |"
        for r in rows
    ]
    write_text(RESULTS / f"{scene}.md", "\n".join(lines) + "\n")
    plot(scene, rows)
    curves = {}
    for r in rows:
        label = (f"{scene}, {mesh(scene, r)} mesh, {r.get('boundary', 'nodes')}, "
                 f"{r.get('solver', 'direct')} solver")
        curves.setdefault(label, []).append(
            (r["wall_s"], abs(r["drag_coefficient_error"]), f"{r['cells_per_diameter']:g}/D")
        )
    tradeoff_plot(
        RESULTS / f"{scene}-tradeoff.png",
        curves,
        "|C_D error|",
        f"{scene}: drag against cost (labels: cells per diameter)",
    )


def signed(value: float, reference: float) -> str:
    """The relative error with its sign, or 'wrong sign'."""
    if value * reference <= 0:
        return "wrong sign"
    return f"{100 * (value / reference - 1):+.1f} %"


def plot(scene: str, rows: list[dict]) -> None:
    """Drag error against cells per diameter and against wall time."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import NullFormatter

    rows = [r for r in rows if r.get("solver", "direct") == "direct"] or rows
    fig, (a, b) = plt.subplots(1, 2, figsize=(9, 3.6))
    for kind, boundary in sorted({(mesh(scene, r), r.get("boundary", "nodes")) for r in rows}):
        these = [r for r in rows if (mesh(scene, r), r.get("boundary", "nodes")) == (kind, boundary)]
        err = [100 * abs(r["drag_coefficient_error"]) for r in these]
        cells = [r["cells_per_diameter"] for r in these]
        label = f"{kind} mesh, {boundary} boundary"
        a.loglog(cells, err, "o-", label=label)
        a.set_xticks(cells, [f"{c:g}" for c in cells])
        b.loglog([r["wall_s"] for r in these], err, "s-", label=label)
        for r, e in zip(these, err):
            b.annotate(
                f"level {r['level']}", (r["wall_s"], e), textcoords="offset points", xytext=(4, 4), fontsize=8
            )
    a.xaxis.set_minor_formatter(NullFormatter())
    a.set(xlabel="cells per diameter", ylabel="|C_D error| (%)", title=scene)
    a.legend(fontsize=8)
    b.set(xlabel="wall time (s)", ylabel="|C_D error| (%)", title="accuracy against cost")
    for ax in (a, b):
        ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(RESULTS / f"{scene}.png", dpi=120)
    plt.close(fig)
