"""Glowinski's free fall of a disk: convergence in the mesh level and in the time step (a study of
several runs; the pytest benchmark ``test_glowinski.py`` runs single configurations).

Run:  python benchmarks/bench_glowinski.py [--levels 1 2 3] [--dt 0.002] [--dts 0.004 0.002 0.001]
      [--dt-level 2] [--t-end 0.65] [--mesh graded|uniform] [--boundary sharp|nodes]
      [--scheme crank-nicolson|backward-euler] [--reuse]

Each run's row goes into ``benchmarks/results/glowinski*.json`` (see fbmbench.glowinski) and the
tables and plots are redrawn from all rows there. With ``--reuse`` a configuration already in the
results file is not run again.
"""

from __future__ import annotations

import argparse

from fbmbench import glowinski
from fbmbench.common import load_rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--levels", type=int, nargs="+", default=[1, 2, 3])
    ap.add_argument("--dts", type=float, nargs="+", default=[0.004, 0.002, 0.001])
    ap.add_argument("--dt", type=float, default=0.002, help="time step of the mesh study")
    ap.add_argument("--dt-level", type=int, default=2, help="level of the time-step study")
    ap.add_argument("--t-end", type=float, default=0.65, help="past the peak, before the landing")
    ap.add_argument("--mesh", default="graded", choices=("graded", "uniform"), help="domain.mesh")
    ap.add_argument("--boundary", default="sharp", choices=("sharp", "nodes"), help="fbm.boundary")
    ap.add_argument(
        "--scheme",
        choices=tuple(glowinski.INTEGRATOR),
        help="time.scheme (with the trapezoidal / semi-implicit Euler particle integrator); default: "
        "crank-nicolson for the sharp boundary, backward-euler for the nodal one",
    )
    ap.add_argument("--reuse", action="store_true", help="skip configurations already in the results file")
    args = ap.parse_args(argv)
    scheme = args.scheme or ("crank-nicolson" if args.boundary == "sharp" else "backward-euler")
    runs = [(lv, args.dt) for lv in args.levels] + [(args.dt_level, dt) for dt in args.dts]
    runs = sorted(dict.fromkeys(runs), key=lambda r: (r[0], -r[1]))  # cheapest first, no repeats
    name = glowinski.stem(args.mesh, args.boundary, scheme)
    for level, dt in runs:
        want = dict(
            level=level,
            dt=dt,
            t_end=args.t_end,
            mesh=args.mesh,
            boundary=args.boundary,
            scheme=scheme,
            pressure_lag=glowinski.pressure_lag(scheme),
        )
        if args.reuse and any(glowinski.key(r) == glowinski.key(want) for r in load_rows(name)):
            print(f"level {level} dt {dt}: in results/{name}.json already")
            continue
        glowinski.record(glowinski.run(level, dt, args.t_end, args.mesh, args.boundary, scheme))
    glowinski.write(name, load_rows(name))


if __name__ == "__main__":
    main()
