"""Drafting, kissing and tumbling (Uhlmann's set-up): convergence in the mesh level, compared with
Koblitz et al. (2017).

Run:  python benchmarks/bench_dkt.py [--levels 1 2] [--setup uhlmann]
      [--reference ../shared/reference-data/koblitz2017-dkt-basilisk]

Per level: cells per diameter, unknowns, wall time, ``t_kiss``, ``t_tumble``, their errors
against the times read off Koblitz et al.'s curves (0.175 s and 0.26 s, uhlmann only), the
closest approach, and the change of ``t_tumble`` against the next finer level. The plot puts
the streamwise positions (distance from the top wall over d, against t / t_ref) over the
digitised curves when the reference folder is there. Writes ``benchmarks/results/dkt.md``,
``.json`` and ``.png``; the json is written after every run.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from fbmflow.params import from_dict
from fbmflow.scenes import get_scene
from fbmflow.scenes.dkt import SETUPS

RESULTS = Path(__file__).parent / "results"
REFERENCE = Path(__file__).resolve().parents[2] / "shared" / "reference-data" / "koblitz2017-dkt-basilisk"
T_REF = 0.01801  # s, d / u_ref of the uhlmann set-up (the reference folder's README)


def run(scene, setup: str, level: int) -> dict:
    params = from_dict(scene.Params, {"case": {"setup": setup}})
    t0 = time.perf_counter()
    result = scene.run(params, level)
    q = result.quantities
    row = {"level": level, "cells_per_diameter": q["cells_per_diameter"], "n_dofs": result.n_dofs,
           "wall_s": time.perf_counter() - t0, **{k: v for k, v in q.items() if not isinstance(v, list)},
           "series": {k: v for k, v in q.items() if isinstance(v, list)}}
    print(f"level {level}: {row['n_dofs']} unknowns, {row['wall_s']:.0f} s, t_kiss {row['t_kiss']}, "
          f"t_tumble {row['t_tumble']}", flush=True)
    return row


def fmt(v, spec=".3f"):
    return "—" if v is None else format(v, spec)


def report(rows, setup, reference: Path):
    lines = [f"# Drafting, kissing, tumbling ({setup})", "",
             f"Command: `python benchmarks/bench_dkt.py --setup {setup} --levels "
             f"{' '.join(str(r['level']) for r in rows)}`; 2-core machine, implicit coupling, hard "
             "contact (skin one cell), backward Euler.", "",
             "| level | cells/d | unknowns | wall s | t_kiss s | error | t_tumble s | error | "
             "closest centres / d | t_tumble change vs finer |", "|---|---|---|---|---|---|---|---|---|---|"]
    for k, r in enumerate(rows):
        change = None
        if k + 1 < len(rows) and r["t_tumble"] and rows[k + 1]["t_tumble"]:
            change = abs(r["t_tumble"] - rows[k + 1]["t_tumble"]) / rows[k + 1]["t_tumble"]
        lines.append(f"| {r['level']} | {r['cells_per_diameter']:.0f} | {r['n_dofs']} | {r['wall_s']:.0f} | "
                     f"{fmt(r['t_kiss'])} | {fmt(r.get('t_kiss_error'), '+.1%')} | {fmt(r['t_tumble'])} | "
                     f"{fmt(r.get('t_tumble_error'), '+.1%')} | {r['min_distance_over_d']:.3f} | "
                     f"{fmt(change, '.1%')} |")
    if setup == "uhlmann":
        lines += ["", "Reference times read off Koblitz et al. (2017), Fig. 10c (digitised, see the "
                  "reference folder's README): kiss at about 0.175 s, tumble at about 0.26 s."]
    (RESULTS / "dkt.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    s = SETUPS[setup]
    d, top = s["d"], s["box"][1]
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for k, r in enumerate(rows):
        t = np.array(r["series"]["t"]) / T_REF
        for who, style in (("leading", "-"), ("trailing", "--")):
            ax.plot(t, (top - np.array(r["series"][f"y_{who}"])) / d, style, c=f"C{k}",
                    label=f"level {r['level']} ({r['cells_per_diameter']:.0f} cells/d), {who}")
    if setup == "uhlmann" and reference.is_dir():
        for who in ("leading", "trailing"):
            data = np.loadtxt(reference / f"Koblitz2017-fig10c-{who}-particle.csv")
            ax.plot(data[:, 0], -data[:, 1], "k.", ms=3, label=f"Koblitz et al. 2017, {who}" if who == "leading" else None)
    ax.set_xlabel("t / t_ref")
    ax.set_ylabel("distance from the top wall / d")
    ax.invert_yaxis()
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(RESULTS / "dkt.png", dpi=120)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--levels", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--setup", default="uhlmann", choices=sorted(SETUPS))
    ap.add_argument("--reference", type=Path, default=REFERENCE)
    args = ap.parse_args(argv)
    scene = get_scene("dkt-2d")
    RESULTS.mkdir(exist_ok=True)
    rows = []
    for level in args.levels:
        rows.append(run(scene, args.setup, level))
        (RESULTS / "dkt.json").write_text(json.dumps(rows))
    report(rows, args.setup, args.reference)


if __name__ == "__main__":
    main()
