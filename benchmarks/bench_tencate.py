"""ten Cate et al. (2002): a sphere settling in a closed box, against the experiment, per case
and mesh level (the study behind the pytest benchmark ``test_tencate.py``).

Run:  python benchmarks/bench_tencate.py [--cases E1 E2 E3 E4] [--levels 0 1] [--dt 0.01]
      [--set KEY=VALUE ...] [--checkpoint-every 10] [--runs out/bench]

Each run's row goes into ``benchmarks/results/tencate.json`` (see fbmbench.tencate) and the table
and plots are redrawn from all rows there. A configuration already in the results file is not run
again. A run checkpoints into its own folder under ``--runs`` and the same command continues an
interrupted one (a level-1 case takes 40 min to 3 h on 2 cores); its wall time sums the pieces.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", nargs="+", default=["E1", "E2", "E3", "E4"], choices=("E1", "E2", "E3", "E4"))
    ap.add_argument("--levels", type=int, nargs="+", default=[0, 1])
    ap.add_argument("--dt", type=float, default=0.01)
    ap.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="further scene parameters, e.g. fbm.force=surface",
    )
    ap.add_argument(
        "--runs", type=Path, default=None, help="where the runs keep their checkpoints (out/bench)"
    )
    ap.add_argument("--checkpoint-every", type=int, default=10, help="steps between checkpoints (>= 1)")
    args = ap.parse_args(argv)
    if args.checkpoint_every < 1:
        ap.error(f"--checkpoint-every must be at least 1, got {args.checkpoint_every}")
    if args.runs is not None:
        os.environ["FBMFLOW_BENCH_RUNS"] = str(args.runs.resolve())
    from fbmbench import tencate
    from fbmbench.common import load_rows

    from fbmflow.config import parse_value

    settings = {}
    for item in args.set:
        key, sep, value = item.partition("=")
        if not sep:
            ap.error(f"--set expects KEY=VALUE, got {item!r}")
        settings[key.strip()] = parse_value(value.strip())
    for case in args.cases:
        for level in args.levels:
            want = {
                "case": case,
                "level": level,
                "dt": args.dt,
                "settings": settings,
                "pressure_lag": tencate.scheme_lag(settings),
                "newton_rtol": settings.get("solver.newton_rtol", tencate.DEFAULT_RTOL),
            }
            done = [r for r in load_rows("tencate") if tencate.same_run(r, want)]
            if done:
                print(
                    f"{case} level {level} dt {args.dt}: in results/tencate.json already "
                    f"({tencate.solver(done[0])})"
                )
                continue
            tencate.record(tencate.run(case, level, args.dt, settings, args.checkpoint_every))
    tencate.write(load_rows("tencate"))


if __name__ == "__main__":
    sys.exit(main())
