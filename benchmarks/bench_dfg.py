"""DFG 2D-1 and 3D-1Z with the cylinder as a fixed fictitious boundary: accuracy against cost
per level (the pytest benchmark ``test_dfg.py`` runs the same configurations one by one).

Run:  python benchmarks/bench_dfg.py [--scene dfg-2d-1] [--levels 1 2 3 4] [--solver direct]
      python benchmarks/bench_dfg.py --scene dfg-3d-1z --levels 1 2 3

Each level's row goes into ``benchmarks/results/<scene>.json`` (see fbmbench.dfg); the table,
``<scene>.png`` and ``<scene>-tradeoff.png`` are redrawn from all rows there.
"""

from __future__ import annotations

import argparse

from fbmbench import dfg


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="dfg-2d-1", choices=dfg.SCENES)
    ap.add_argument("--levels", type=int, nargs="+", default=[1, 2, 3, 4])
    ap.add_argument("--solver", default="direct", choices=("direct", "multigrid", "auto"))
    args = ap.parse_args(argv)
    for level in args.levels:
        dfg.record(args.scene, dfg.run(args.scene, level, args.solver))


if __name__ == "__main__":
    main()
