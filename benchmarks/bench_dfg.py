"""DFG 2D-1 with the cylinder as a fixed fictitious boundary: accuracy against cost per level.

Run:  python benchmarks/bench_dfg.py [--levels 1 2 3 4] [--solver direct]

Writes ``benchmarks/results/dfg-2d-1.md`` and ``.json``: level, cells across the diameter,
unknowns, wall time, C_D, C_L, dp and their relative errors against the reference values.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from fbmflow.params import from_dict
from fbmflow.scenes import get_scene
from fbmflow.scenes.dfg import REFERENCE

RESULTS = Path(__file__).parent / "results"


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--levels", type=int, nargs="+", default=[1, 2, 3, 4])
    ap.add_argument("--solver", default="direct", choices=("direct", "multigrid", "auto"))
    args = ap.parse_args()
    scene = get_scene("dfg-2d-1")
    params = from_dict(scene.Params, {"solver": {"linear": args.solver}})
    scene.run(params, 0)  # JIT warm-up
    rows = []
    for level in args.levels:
        t0 = time.perf_counter()
        result = scene.run(params, level)
        wall = time.perf_counter() - t0
        q = result.quantities
        rows.append(dict(level=level, cells_per_diameter=q["cells_per_diameter"], n_dofs=result.n_dofs,
                         wall_s=wall, newton=result.newton_iterations,
                         **{k: q[k] for k in REFERENCE}, **{k + "_error": q[k + "_error"] for k in REFERENCE}))
        r = rows[-1]
        print(f"level {level}: {r['cells_per_diameter']:.1f} cells/D, {r['n_dofs']} unknowns, {wall:.1f} s, "
              f"C_D {r['drag_coefficient']:.4f} ({100 * r['drag_coefficient_error']:.2f} %), "
              f"C_L {r['lift_coefficient']:.4f}, dp {r['pressure_difference']:.4f} "
              f"({100 * r['pressure_difference_error']:.2f} %)", flush=True)
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "dfg-2d-1.json").write_text(json.dumps(rows, indent=1))
    lines = ["# DFG 2D-1, cylinder as a fixed fictitious boundary (benchmarks/bench_dfg.py)", "",
             f"Linear solver: {args.solver}. Reference C_D = {REFERENCE['drag_coefficient']}, "
             f"C_L = {REFERENCE['lift_coefficient']}, dp = {REFERENCE['pressure_difference']}.", "",
             "| level | cells/D | unknowns | wall s | Newton | C_D | err C_D | C_L | dp | err dp |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    lines += [f"| {r['level']} | {r['cells_per_diameter']:.1f} | {r['n_dofs']} | {r['wall_s']:.1f} | {r['newton']} | "
              f"{r['drag_coefficient']:.4f} | {100 * r['drag_coefficient_error']:.2f} % | {r['lift_coefficient']:.4f} | "
              f"{r['pressure_difference']:.4f} | {100 * r['pressure_difference_error']:.2f} % |" for r in rows]
    (RESULTS / "dfg-2d-1.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
