"""DFG 2D-1 and 3D-1Z with the cylinder as a fixed fictitious boundary: accuracy against cost
per level.

Run:  python benchmarks/bench_dfg.py [--scene dfg-2d-1] [--levels 1 2 3 4] [--solver direct]
      python benchmarks/bench_dfg.py --scene dfg-3d-1z --levels 1 2 3

Writes ``benchmarks/results/<scene>.md``, ``.json`` and ``.png``: level, cells across the
diameter, unknowns, wall time, C_D, C_L, dp and their relative errors against the reference values
(the JIT warm-up at level 0 is not timed).
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from fbmflow.params import from_dict
from fbmflow.scenes import get_scene
from fbmflow.solvers.linear import PARDISO_MIN_UNKNOWNS_2D

RESULTS = Path(__file__).parent / "results"


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="dfg-2d-1", choices=("dfg-2d-1", "dfg-3d-1z"))
    ap.add_argument("--levels", type=int, nargs="+", default=[1, 2, 3, 4])
    ap.add_argument("--solver", default="direct", choices=("direct", "multigrid", "auto"))
    args = ap.parse_args()
    scene = get_scene(args.scene)
    ref = scene.reference
    params = from_dict(scene.Params, {"solver": {"linear": args.solver}})
    scene.run(params, 0)  # JIT warm-up
    rows = []
    for level in args.levels:
        t0 = time.perf_counter()
        result = scene.run(params, level)
        wall = time.perf_counter() - t0
        q = result.quantities
        rows.append(dict(level=level, cells_per_diameter=q["cells_per_diameter"], n_dofs=result.n_dofs,
                         wall_s=wall, newton=result.newton_iterations, linear_solver=result.linear_solver,
                         **{k: q[k] for k in ("drag_coefficient", "lift_coefficient", "pressure_difference")},
                         **{k + "_error": q[k + "_error"] for k in ref}))
        r = rows[-1]
        print(f"level {level}: {r['cells_per_diameter']:.1f} cells/D, {r['n_dofs']} unknowns, {wall:.1f} s, "
              f"C_D {r['drag_coefficient']:.4f} ({100 * r['drag_coefficient_error']:.2f} %), "
              f"C_L {r['lift_coefficient']:.4f}, dp {r['pressure_difference']:.4f} "
              f"({100 * r.get('pressure_difference_error', float('nan')):.2f} %)", flush=True)
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / f"{args.scene}.json").write_text(json.dumps(rows, indent=1))
    solvers = " / ".join(sorted({r["linear_solver"] for r in rows}))
    refs = ", ".join(f"{k} = {v}" for k, v in ref.items())
    lines = [f"# {scene.description} (benchmarks/bench_dfg.py)", "",
             f"Linear solver: {solvers} (PARDISO, when installed, in 3D and from {PARDISO_MIN_UNKNOWNS_2D} unknowns in 2D). Reference {refs}. Wall time includes assembly, all Newton "
             "steps and the force evaluation, not the JIT compilation.", "",
             "| level | cells/D | unknowns | wall s | Newton | C_D | err C_D | C_L | dp | err dp |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    lines += [f"| {r['level']} | {r['cells_per_diameter']:.1f} | {r['n_dofs']} | {r['wall_s']:.1f} | {r['newton']} | "
              f"{r['drag_coefficient']:.4f} | {100 * r['drag_coefficient_error']:.2f} % | {r['lift_coefficient']:.4f} | "
              f"{r['pressure_difference']:.4f} | {_percent(r.get('pressure_difference_error'))} |" for r in rows]
    (RESULTS / f"{args.scene}.md").write_text("\n".join(lines) + "\n")
    plot(rows, args.scene, RESULTS / f"{args.scene}.png")


def _percent(value) -> str:
    return "–" if value is None else f"{100 * value:.2f} %"


def plot(rows, name, path):
    """Drag error against cells per diameter and against wall time (the user's trade)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import NullFormatter

    fig, (a, b) = plt.subplots(1, 2, figsize=(9, 3.6))
    err = [100 * r["drag_coefficient_error"] for r in rows]
    cells = [r["cells_per_diameter"] for r in rows]
    a.loglog(cells, err, "o-")
    a.set_xticks(cells, [f"{c:g}" for c in cells])
    a.xaxis.set_minor_formatter(NullFormatter())
    a.set(xlabel="cells per diameter", ylabel="|C_D error| (%)", title=name)
    b.loglog([r["wall_s"] for r in rows], err, "s-")
    for r, e in zip(rows, err):
        b.annotate(f"level {r['level']}", (r["wall_s"], e), textcoords="offset points", xytext=(4, 4), fontsize=8)
    b.set(xlabel="wall time (s)", ylabel="|C_D error| (%)", title="accuracy against cost")
    for ax in (a, b):
        ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


if __name__ == "__main__":
    main()
