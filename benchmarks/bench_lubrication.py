"""The lubrication correction against Brenner's exact Stokes drag: a sphere approaching a plane
wall and two equal spheres approaching each other, at several meshes and gaps (the set-up is in
fbmbench.lubrication).

Run:  python benchmarks/bench_lubrication.py [--cells 4 6 8] [--walls rigid free]
      [--gaps 10 3 1 ...] [--range-cells R] [--min-gap-cells M] [--resolved-cells S]
      [--pair-offsets 0 0.25 0.5] [--pair-gaps 0.1 0.02]

Each flow's row goes into ``benchmarks/results/lubrication.json``; ``lubrication.md`` and
``lubrication.png`` are redrawn from all rows there with the correction of the given range,
cut-off and resolved gap (by default the package's: ``contact.lubrication_range_cells``,
``lubrication_min_gap_cells`` and ``lubrication_resolved_cells``). ``--pair-offsets`` adds
flows of two fictitious spheres at 6 cells/d whose midplane lies that many cells above a mesh
plane (``--walls`` with no value and ``--cells`` with none run only these).
"""

from __future__ import annotations

import argparse

from fbmbench import lubrication

from fbmflow.contact.settings import ContactParams


def main(argv=None):
    defaults = ContactParams()
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cells", type=int, nargs="*", default=[4, 6, 8], help="cells per diameter")
    ap.add_argument("--walls", nargs="*", default=["rigid", "free"], choices=("rigid", "free"),
                    help="rigid: sphere towards a wall; free: two spheres towards each other")
    ap.add_argument("--gaps", type=float, nargs="+", default=list(lubrication.GAPS), help="gaps h / a")
    ap.add_argument("--range-cells", type=float, default=defaults.lubrication_range_cells,
                    help="range of the correction [cells]")
    ap.add_argument("--min-gap-cells", type=float, default=defaults.lubrication_min_gap_cells,
                    help="cut-off gap of the correction [cells]")
    ap.add_argument("--resolved-cells", type=float, default=defaults.lubrication_resolved_cells,
                    help="gap down to which the flow carries the film force [cells]")
    ap.add_argument("--solver", default="auto", help="linear solver (auto, multigrid, direct, pardiso)")
    ap.add_argument("--pair-offsets", type=float, nargs="*", default=[],
                    help="also two fictitious spheres at 6 cells/d, midplane this many cells off a mesh "
                    "plane")
    ap.add_argument("--pair-gaps", type=float, nargs="+", default=[0.1, 0.02], help="gaps h / a of the pairs")
    ap.add_argument("--table-only", action="store_true", help="redraw the table and plot from the rows")
    args = ap.parse_args(argv)
    rows = []
    if not args.table_only:
        for wall in args.walls:
            for cells in args.cells:
                rows += lubrication.run(cells, wall, args.gaps, args.solver)
        if args.pair_offsets:
            rows += lubrication.run_pairs(6, args.pair_gaps, args.pair_offsets)
    lubrication.record(rows, {"range": args.range_cells, "min_gap": args.min_gap_cells,
                              "resolved": args.resolved_cells})


if __name__ == "__main__":
    main()
