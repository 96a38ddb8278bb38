"""Drafting, kissing and tumbling of two disks (Uhlmann's set-up, scene ``dkt-2d``) against the
times read off Koblitz et al.'s (2017) curves: kiss at about 0.175 s, tumble at about 0.26 s.

Per level: cells per diameter, unknowns, wall time, ``t_kiss``, ``t_tumble``, their errors, the
closest approach and the change of ``t_tumble`` against the next finer level. The plot puts the
streamwise positions over the digitised curves of the shared reference folder when it is there.
Results: ``benchmarks/results/dkt.md``, ``.json``, ``.png`` and ``dkt-tradeoff.png``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .common import RESULTS, ROOT, cpu, merge_row, provenance, run_scene, tradeoff_plot, warm_up, write_text

SCENE = "dkt-2d"
REFERENCE = ROOT.parent / "shared" / "reference-data" / "koblitz2017-dkt-basilisk"
T_REF = 0.01801  # s, d / u_ref of the uhlmann set-up (the reference folder's README)


def run(level: int, setup: str = "uhlmann") -> dict:
    """One run; the row (the series under ``series``)."""
    warm_up(SCENE, 1, **{"case.setup": setup, "time.t_end": 0.004})
    s = run_scene(SCENE, level, {"case.setup": setup})
    q = s["quantities"]
    row = {
        "level": level,
        "setup": setup,
        "cells_per_diameter": q["cells_per_diameter"],
        "n_dofs": s["n_dofs"],
        "wall_s": s["wall_s"],
        "stopped_s": s["stopped_s"],
        "cpu_s": s["cpu_s"],
        "steps": s["steps"],
        "linear_solver": s["linear_solver"],
        **{k: v for k, v in q.items() if not isinstance(v, list)},
        "series": {k: v for k, v in q.items() if isinstance(v, list)},
        **provenance(),
    }
    print(
        f"dkt level {level}: {row['n_dofs']} unknowns, {row['wall_s']:.0f} s, t_kiss {row['t_kiss']}, "
        f"t_tumble {row['t_tumble']}",
        flush=True,
    )
    return row


def record(row: dict) -> list[dict]:
    rows = merge_row(
        "dkt", row, lambda a, b: (a["level"], a.get("setup", "uhlmann")) == (b["level"], b["setup"])
    )
    write(rows)
    return rows


def fmt(v, spec=".3f"):
    return "—" if v is None else format(v, spec)


def write(rows: list[dict], reference: Path = REFERENCE) -> None:
    rows = sorted((r for r in rows if r.get("setup", "uhlmann") == "uhlmann"), key=lambda r: r["level"])
    lines = [
        "# Drafting, kissing, tumbling (uhlmann)",
        "",
        "Scene `dkt-2d`, the scene's defaults: implicit coupling, hard contact (skin one cell), backward "
        "Euler. Wall time of the run on a 2-core machine without the JIT compilation, other jobs beside "
        "(upper bounds). Reproduce a row: `python -m fbmbench dkt --levels L`, or "
        "`python -m pytest benchmarks -k dkt`.",
        "",
        "| level | cells/d | unknowns | wall s | CPU s | t_kiss s | error | t_tumble s | error | "
        "closest centres / d | t_tumble change vs finer | measured |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for k, r in enumerate(rows):
        change = None
        if k + 1 < len(rows) and r["t_tumble"] and rows[k + 1]["t_tumble"]:
            change = abs(r["t_tumble"] - rows[k + 1]["t_tumble"]) / rows[k + 1]["t_tumble"]
        lines.append(
            f"| {r['level']} | {r['cells_per_diameter']:.0f} | {r['n_dofs']} | {r['wall_s']:.0f} | "
            f"{cpu(r)} | "
            f"{fmt(r['t_kiss'])} | {fmt(r.get('t_kiss_error'), '+.1%')} | {fmt(r['t_tumble'])} | "
            f"{fmt(r.get('t_tumble_error'), '+.1%')} | {r['min_distance_over_d']:.3f} | "
            f"{fmt(change, '.1%')} | {r.get('date', 'earlier session')} {r.get('commit', '')} |"
        )
    lines += [
        "",
        "Reference times read off Koblitz et al. (2017), Fig. 10c (digitised, see the reference "
        "folder's README): kiss at about 0.175 s, tumble at about 0.26 s.",
    ]
    write_text(RESULTS / "dkt.md", "\n".join(lines) + "\n")
    plot(rows, reference)
    curves = {
        "t_kiss": [
            (
                r["wall_s"],
                abs(r["t_kiss_error"]) if r.get("t_kiss_error") is not None else None,
                f"{r['cells_per_diameter']:.0f}/d",
            )
            for r in rows
        ],
        "t_tumble": [
            (
                r["wall_s"],
                abs(r["t_tumble_error"]) if r.get("t_tumble_error") is not None else None,
                f"{r['cells_per_diameter']:.0f}/d",
            )
            for r in rows
        ],
    }
    tradeoff_plot(
        RESULTS / "dkt-tradeoff.png",
        curves,
        "|t / t_Koblitz - 1|",
        "DKT: kissing and tumbling times against cost (labels: cells per diameter)",
    )


def plot(rows: list[dict], reference: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from fbmflow.scenes.dkt import SETUPS

    d, top = SETUPS["uhlmann"]["d"], SETUPS["uhlmann"]["box"][1]
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for k, r in enumerate(rows):
        t = np.array(r["series"]["t"]) / T_REF
        for who, style in (("leading", "-"), ("trailing", "--")):
            ax.plot(
                t,
                (top - np.array(r["series"][f"y_{who}"])) / d,
                style,
                c=f"C{k}",
                label=f"level {r['level']} ({r['cells_per_diameter']:.0f} cells/d), {who}",
            )
    if reference.is_dir():
        for who in ("leading", "trailing"):
            data = np.loadtxt(reference / f"Koblitz2017-fig10c-{who}-particle.csv")
            ax.plot(
                data[:, 0],
                -data[:, 1],
                "k.",
                ms=3,
                label=f"Koblitz et al. 2017, {who}" if who == "leading" else None,
            )
    ax.set_xlabel("t / t_ref")
    ax.set_ylabel("distance from the top wall / d")
    ax.invert_yaxis()
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(RESULTS / "dkt.png", dpi=120)
    plt.close(fig)
