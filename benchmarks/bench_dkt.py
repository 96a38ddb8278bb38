"""Drafting, kissing and tumbling (Uhlmann's set-up): convergence in the mesh level against
Koblitz et al. (2017) (the pytest benchmark ``test_dkt.py`` runs the same levels one by one).

Run:  python benchmarks/bench_dkt.py [--levels 1 2]

Each level's row goes into ``benchmarks/results/dkt.json`` (see fbmbench.dkt); ``dkt.md``,
``dkt.png`` (positions over the digitised curves of the shared reference folder, when present)
and ``dkt-tradeoff.png`` are redrawn from all rows there.
"""

from __future__ import annotations

import argparse

from fbmbench import dkt


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--levels", type=int, nargs="+", default=[1, 2])
    args = ap.parse_args(argv)
    for level in args.levels:
        dkt.record(dkt.run(level))


if __name__ == "__main__":
    main()
