"""Linear solvers on the built-in scenes: one row per scene, level and solver.

Question: which linear solver (SuperLU, PARDISO, multigrid) is cheapest in time and memory on
each built-in scene, and how many multigrid cycles does a solve take?
Answer: in 3D multigrid, the only one that fits or 2-6x faster at a quarter of the memory or
less; in 2D multigrid and PARDISO lead by turns (rerun at 3eeb731, the cavity rows at 1ea3655):
cavity-2d Re 400 / 1000, level 3 (45 570 unknowns), 3.8 / 5.4 s against SuperLU's 7.3 / 10.5 s
and PARDISO's 7.0 / 3.9 s, 2.4 / 2.5 cycles per solve; channel-3d level 4 38.8 s at 3.6 GB
(PARDISO > 24 GB); dfg-3d-1z level 3 57.0 s at 2.3 GB against PARDISO's 110.4 s at 8.1 GB;
ten-cate E4 level 1 8.1 s per step at 1.4 GB against PARDISO's 46.5 s at 10.3 GB, level 2 44.8 s
per step at 8.3 GB; benchmarks/results/solver_table.md.
Measured: 2026-11-26, commit 1ea3655; quoted in docs/validation/multigrid-with-fictitious-boundaries.md
Run: python -m fbmbench solver_table

For every case (a steady scene solved to its end, or the first steps of a particle scene) and
every solver (SuperLU, PARDISO when installed, multigrid with the scene's settings) one process
runs the case and reports: unknowns, Newton iterations, linear solves, multigrid cycles per
solve, matvec-equivalents per solve (linear time over the time of one product with the fine
system), seconds per solve, per step (particle scenes) or in all (steady scenes), and the
process's peak resident memory. The processes run one after the other; the JIT-compiled kernels
come from the Numba cache (run once before to fill it). Combinations that cannot run here are
listed with the reason (SuperLU's fill in 3D above a few 10^4 unknowns; PARDISO's memory).

    python -m fbmbench solver_table                  # every case
    python -m fbmbench solver_table --cases cavity-re400 channel-3d-4
    python -m fbmbench solver_table --cases cavity-re400 --busy 1   # beside a busy process

writes benchmarks/results/solver_table.{json,md} (rows of cases not run are kept from the last
file).
"""
from __future__ import annotations

import json
import resource
import subprocess
import sys
import time
import weakref
from pathlib import Path

BENCHMARKS = Path(__file__).resolve().parents[1]
RESULTS = BENCHMARKS / "results"
#: name -> (scene, level, overrides, steps; None: a steady scene run to its end)
CASES = {
    "cavity-re400": ("cavity-2d", 3, ["fluid.re=400"], None),
    "cavity-re1000": ("cavity-2d", 3, ["fluid.re=1000"], None),
    "channel-3d-4": ("channel-3d", 4, [], None),
    "dfg-3d-1z-3": ("dfg-3d-1z", 3, [], None),
    "ten-cate-1": ("ten-cate", 1, [], 3),
    "ten-cate-2": ("ten-cate", 2, [], 2),
}
SOLVERS = ("superlu", "pardiso", "multigrid")
#: every solver a row may name: the default ones and multigrid on Numba's thread count as set
#: (``solver.multigrid.threads = "fixed"``; "multigrid" takes the cores other processes leave)
KNOWN = SOLVERS + ("multigrid-fixed",)
#: combinations not run, with the reason (measured or estimated on this 24 GB machine)
_SUPERLU_3D = ("SuperLU in 3D: 16 s per factorisation at 64 547 unknowns in nested-dissection order, "
               "growing as n^2.45 (about 7 min at 250 000)")
SKIP = {
    ("channel-3d-4", "superlu"): _SUPERLU_3D,
    ("dfg-3d-1z-3", "superlu"): _SUPERLU_3D,
    ("ten-cate-1", "superlu"): _SUPERLU_3D,
    ("ten-cate-2", "superlu"): _SUPERLU_3D,
    ("channel-3d-4", "pardiso"): "PARDISO: more than the machine's 24 GB (487 000 unknowns)",
    ("ten-cate-2", "pardiso"): "PARDISO: more than the machine's 24 GB (2.1 M unknowns)",
}


def run_case(case: str, solver: str) -> dict:
    """Run ``case`` with ``solver`` in this process; the row's figures."""
    import numba
    import numpy as np

    import fbmflow.flow.navier_stokes as ns
    import fbmflow.solvers.direct as direct
    from fbmflow.scenes.registry import load_scene

    scene_name, level, overrides, steps = CASES[case]
    multigrid = solver.startswith("multigrid")
    if not multigrid:
        backend = solver
        direct.auto_backend = lambda dim, n: backend  # the direct backend of this row
    reports, newton, problems = [], [], []
    last_system = [None]  # a weak reference: the row does not keep a system the problem has freed
    init, solve_newton = ns.NavierStokesProblem.__init__, ns.solve_newton

    def hooked_init(self, *args, **kwargs):  # every flow problem reports its linear solves
        init(self, *args, **kwargs)

        def counted(report, system, problem=self):
            reports.append(report)
            last_system[0] = weakref.ref(system)
            if not problems or problems[-1] is not problem:
                problems.append(problem)

        self.on_linear_solve = counted

    def counted_newton(*args, **kwargs):
        x, report = solve_newton(*args, **kwargs)
        newton.append(report.iterations)
        return x, report

    ns.NavierStokesProblem.__init__ = hooked_init
    ns.solve_newton = counted_newton
    scene, params, level = load_scene(scene_name, level,
                                      [f"solver.linear={'multigrid' if multigrid else 'direct'}"]
                                      + (["solver.multigrid.threads=fixed"] * (solver == "multigrid-fixed"))
                                      + overrides)
    t0 = time.perf_counter()
    step_times = []
    if steps is None:
        scene.run(params, level)
    else:
        setup = scene.build(params, level)
        for _ in range(steps):
            t1 = time.perf_counter()
            setup.sim.step(setup.dt)
            step_times.append(time.perf_counter() - t1)
    total = time.perf_counter() - t0
    problem = problems[-1]
    system = last_system[0]()  # the last system solved, which the problem still holds
    if system is None:
        raise RuntimeError(f"{case}: the last linear system solved is gone; no matvec to compare with")
    x = np.random.default_rng(0).standard_normal(system.n_u + system.n_p)
    times = []
    for _ in range(3):
        t1 = time.perf_counter()
        system.apply(x)
        times.append(time.perf_counter() - t1)
    matvec = float(np.median(times))
    linear_s = sum(r.wall_time_s for r in reports)
    per_step = step_times[1:] or step_times
    cycles = sum(r.iterations for r in reports)
    return dict(case=case, scene=scene_name, level=level, overrides=overrides, solver=solver,
                description=problem.linear_solver_description
                + (", threads fixed" if solver == "multigrid-fixed" else ""), unknowns=problem.n_dofs,
                newton=sum(newton), solves=len(reports),
                cycles_per_solve=cycles / len(reports) if multigrid else None,
                matvec_per_solve=linear_s / len(reports) / matvec, s_per_solve=linear_s / len(reports),
                total_s=total, steps=steps, s_per_step=float(np.mean(per_step)) if per_step else None,
                first_step_s=step_times[0] if step_times else None,
                peak_gb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 / 1e9,
                threads=numba.get_num_threads())


def table(rows: list[dict]) -> str:
    lines = ["# Linear solvers on the built-in scenes (python -m fbmbench solver_table)", "",
             "One process per row, one after the other. Steady scenes: the whole run (cavity: continuation "
             "in Re from 100); particle scenes: the first steps (s per step: the mean over the steps after "
             "the first, which includes the set-up). Cycles: FGMRES iterations, one multigrid cycle each. "
             "Matvec-equivalents: linear time per solve over one product with the fine system.", "",
             "Busy: other processes running a pure-Python loop beside the case.", "",
             "Threads: Numba's thread count (blank: rows measured before it was recorded, at the "
             "machine's default, 2 here). Bytes / unknown: the peak over the unknowns.", "",
             "| case | scene | level | unknowns | solver | busy | threads | Newton | solves | cycles / solve "
             "| matvec-eq / solve "
             "| s / solve | s / step | total s | peak GB | bytes / unknown |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if "skipped" in r:
            lines.append(f"| {r['case']} | {r['scene']} | {r['level']} | | {r['solver']} | "
                         f"{r.get('busy', 0)} | | "
                         f"not run: {r['skipped']} | | | | | | | | |")
            continue
        cyc = f"{r['cycles_per_solve']:.1f}" if r["cycles_per_solve"] is not None else ""
        step = f"{r['s_per_step']:.1f}" if r["s_per_step"] else ""
        lines.append(f"| {r['case']} | {r['scene']} | {r['level']} | {r['unknowns']} | {r['description']} | "
                     f"{r.get('busy', 0)} | {r.get('threads', '')} | {r['newton']} | {r['solves']} | {cyc} | "
                     f"{r['matvec_per_solve']:.0f} | {r['s_per_solve']:.2f} | "
                     f"{step} | {r['total_s']:.1f} | {r['peak_gb']:.1f} | "
                     f"{r['peak_gb'] * 1e9 / r['unknowns']:.0f} |")
    return "\n".join(lines) + "\n"


def run(*, cases: list[str] = tuple(CASES), solvers: list[str] = SOLVERS, busy: int = 0,
        one: list[str] = ()) -> None:
    """Each case with each solver in a child process of its own; the rows into the results.

    Parameters
    ----------
    cases : cases to run (cavity-re400, cavity-re1000, channel-3d-4, dfg-3d-1z-3, ten-cate-1,
        ten-cate-2)
    solvers : solvers to run (superlu, pardiso, multigrid, multigrid-fixed)
    busy : run each case beside this many busy processes (a pure-Python loop each; they share the
        2 cores)
    one : internal: run one configuration (CASE SOLVER) in this process
    """
    for option, given, known in (("cases", cases, list(CASES)), ("solvers", solvers, list(KNOWN))):
        unknown = [g for g in given if g not in known]
        if unknown:
            raise SystemExit(f"--{option}: unknown {unknown}; choose from {known}")
    if one:
        print(json.dumps(run_case(*one)))
        return
    from fbmflow.solvers.direct import pardiso_available
    path = RESULTS / "solver_table.json"
    old = json.loads(path.read_text()) if path.exists() else []
    rows = {(r["case"], r["solver"], r.get("busy", 0)): r for r in old}
    for case in cases:
        for solver in solvers:
            scene, level = CASES[case][:2]
            reason = SKIP.get((case, solver)) or (None if solver != "pardiso" or pardiso_available()
                                                   else "PARDISO not installed")
            key = case, solver, busy
            if reason:
                rows[key] = dict(case=case, scene=scene, level=level, solver=solver, busy=busy,
                                 skipped=reason)
                continue
            loops = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(busy)]
            try:
                command = [sys.executable, "-m", "fbmbench", "solver_table", "--one", case, solver]
                proc = subprocess.run(command, capture_output=True, text=True, cwd=BENCHMARKS)
            finally:
                for p in loops:
                    p.kill()
            if proc.returncode:
                rows[key] = dict(case=case, scene=scene, level=level, solver=solver, busy=busy,
                                 skipped=f"failed: {proc.stderr.strip().splitlines()[-1][:120]}")
            else:
                rows[key] = dict(json.loads(proc.stdout.strip().splitlines()[-1]), busy=busy)
            print(rows[key], flush=True)
    ordered = [rows[k] for k in sorted(rows, key=lambda k: (list(CASES).index(k[0]), k[2],
                                                           KNOWN.index(k[1])))]
    path.write_text(json.dumps(ordered, indent=1))
    (RESULTS / "solver_table.md").write_text(table(ordered))
