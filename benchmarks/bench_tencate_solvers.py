"""ten-cate's first time steps with the direct solver (PARDISO) against multigrid: time per step,
linear work, peak memory and the agreement of the velocities.

Each solver runs in its own process (the peak resident set is that process's), one after the
other; the scene's defaults otherwise (E4, sharp boundary, Crank–Nicolson, implicit coupling,
``solver.linear_rtol`` 1e-3). The first step includes the JIT compilation of kernels that the
process has not cached yet.

    python benchmarks/bench_tencate_solvers.py --level 0 1 --steps 2

writes benchmarks/results/tencate_solvers.{json,md}.
"""
from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

RESULTS = Path(__file__).parent / "results"


def one(level: int, solver: str, steps: int) -> dict:
    """Run ``steps`` steps in this process: per-step rows and the final velocity maximum."""
    from fbmflow.scenes.registry import load_scene

    scene, params, level = load_scene("ten-cate", level, [f"solver.linear={solver}"])
    setup = scene.build(params, level)
    sim = setup.sim
    rows = []
    for _ in range(steps):
        t0 = time.perf_counter()
        rep = sim.step(setup.dt)
        rows.append(dict(wall_s=time.perf_counter() - t0, newton=rep.newton_iterations,
                         coupling=rep.flow_solves, solves=rep.linear.solves,
                         iterations=rep.linear.iterations, sweeps=rep.linear.sweeps,
                         linear_s=rep.linear.time_s))
    u = sim.flow.split(sim.x)[0]
    return dict(level=level, solver=sim.flow.linear_solver_description, unknowns=sim.flow.n_dofs, steps=rows,
                u_max=float(np.abs(u).max()), settling_velocity=float(-sim.particles.velocity[0, 2]),
                peak_rss_gb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--level", type=int, nargs="+", default=[0, 1])
    ap.add_argument("--steps", type=int, default=2)
    ap.add_argument("--one", nargs=2, metavar=("LEVEL", "SOLVER"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.one:
        print(json.dumps(one(int(args.one[0]), args.one[1], args.steps)))
        return
    runs = []
    for level in args.level:
        for solver in ("direct", "multigrid"):
            out = subprocess.run([sys.executable, __file__, "--steps", str(args.steps), "--one", str(level),
                                  solver], check=True, capture_output=True, text=True).stdout
            runs.append(json.loads(out.strip().splitlines()[-1]))
            print(runs[-1], flush=True)
    (RESULTS / "tencate_solvers.json").write_text(json.dumps(runs, indent=1))
    lines = ["# ten-cate E4: direct (PARDISO) against multigrid, first steps "
             "(benchmarks/bench_tencate_solvers.py)", "",
             "Defaults of the scene (sharp boundary, Crank–Nicolson, dt 0.01 s, implicit coupling, linear "
             "rtol 1e-3; multigrid: FGMRES with V(2,2) cycles of the factored Vanka smoother in single "
             "precision on the Picard hierarchy). Each solver in its own process, one after the other; step "
             "1 includes the set-up (and JIT compilation not yet cached). Iterations: FGMRES steps, one "
             "cycle each.", "",
             "| level | unknowns | solver | step | s | Newton | coupling | solves | iterations | sweeps "
             "| linear s "
             "| peak GB | u_max at the end | rel. to direct |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in runs:
        ref = next(q for q in runs if q["level"] == r["level"])["u_max"]
        for k, s in enumerate(r["steps"]):
            last = k == len(r["steps"]) - 1
            lines.append(f"| {r['level']} | {r['unknowns']} | {r['solver']} | {k + 1} | {s['wall_s']:.1f} | "
                         f"{s['newton']} | {s['coupling']} | {s['solves']} | {s['iterations']} | "
                         f"{s['sweeps']} | "
                         f"{s['linear_s']:.1f} | {r['peak_rss_gb']:.1f} | "
                         + (f"{r['u_max']:.8e} | {abs(r['u_max'] - ref) / ref:.1e} |" if last else " | |"))
    (RESULTS / "tencate_solvers.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
