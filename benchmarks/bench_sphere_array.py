"""Stokes flow through a simple cubic array of fixed spheres: the drag estimators of the sharp
fictitious boundary against the exact drag, per mesh (the pytest benchmark
``test_sphere_array.py`` runs the same meshes one by one; the set-up is in fbmbench.sphere_array).

Run:  python benchmarks/bench_sphere_array.py [--cells 4 6 8 12 16]

Each mesh's row goes into ``benchmarks/results/sphere_array.json``; ``sphere_array.md`` and
``sphere_array-tradeoff.png`` are redrawn from all rows there.
"""

from __future__ import annotations

import argparse

from fbmbench import sphere_array


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--cells", type=int, nargs="+", default=[4, 6, 8, 12, 16], help="cells per diameter (even)"
    )
    args = ap.parse_args(argv)
    for cells in args.cells:
        sphere_array.record(sphere_array.run(cells))


if __name__ == "__main__":
    main()
