"""ten-cate's first time steps with the direct solver (PARDISO) against multigrid: time per step,
linear work, peak memory and the agreement of the velocities.

Question: how do the direct solver (PARDISO) and multigrid compare on ten-cate E4's first steps
in time per step, linear work and peak memory, and do their velocities agree?
Answer: at level 1 (278 739 unknowns) multigrid takes 9.3 / 8.7 / 8.8 s per step at 1.4 GB,
PARDISO 38 / 48 / 44 s at 10.3 GB, with u_max the same to 2.0e-6 relative; a step is 3-4 linear
solves of about 3 cycles each (level 0: 3.3 / 3.1 / 2.2 s against 6.0 / 5.5 / 2.8 s, 2.3e-8);
benchmarks/results/tencate_solvers.md.
Measured: 2026-11-26, commit 7643e9e; quoted in docs/validation/multigrid-with-fictitious-boundaries.md
Run: python -m fbmbench tencate_solvers --level 0 1 --steps 3

Each solver runs in its own process (the peak resident set is that process's), one after the
other; the scene's defaults otherwise (E4, sharp boundary, Crank–Nicolson, implicit coupling,
``solver.linear_rtol`` 1e-3). The first step includes the JIT compilation of kernels that the
process has not cached yet.

    python -m fbmbench tencate_solvers --level 0 1 --steps 2

writes benchmarks/results/tencate_solvers.{json,md}.
"""
from __future__ import annotations

import json
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

BENCHMARKS = Path(__file__).resolve().parents[1]
RESULTS = BENCHMARKS / "results"


def measure(level: int, solver: str, steps: int) -> dict:
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
                peak_rss_gb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 / 1e9)


def run(*, level: list[int] = (0, 1), steps: int = 2, one: list[str] = ()) -> None:
    """Each level with each solver in a child process of its own; the table of their steps.

    Parameters
    ----------
    level : mesh levels
    steps : time steps per run
    one : internal: run one configuration (LEVEL SOLVER) in this process
    """
    if one:
        print(json.dumps(measure(int(one[0]), one[1], steps)))
        return
    runs = []
    for lv in level:
        for solver in ("direct", "multigrid"):
            out = subprocess.run([sys.executable, "-m", "fbmbench", "tencate_solvers", "--steps", str(steps),
                                  "--one", str(lv), solver], check=True, capture_output=True, text=True,
                                 cwd=BENCHMARKS).stdout
            runs.append(json.loads(out.strip().splitlines()[-1]))
            print(runs[-1], flush=True)
    (RESULTS / "tencate_solvers.json").write_text(json.dumps(runs, indent=1))
    lines = ["# ten-cate E4: direct (PARDISO) against multigrid, first steps "
             "(python -m fbmbench tencate_solvers)", "",
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

