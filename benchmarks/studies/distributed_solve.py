"""One time step's linear solve over several processes, against processes and threads.

Question: how do the cycles per solve, the seconds per solve and the peak memory per process of
the distributed multigrid (fbmflow.solvers.distributed) change from 1 to 2 and 4 processes, and
is one process with two threads or two processes with one thread each faster on this machine?
Answer: the ten Cate level-1 box (1 076 643 unknowns, 4 levels) takes 14 cycles on 1, 2 and 4
processes alike. Two processes of one thread solve it 1.49-1.88x faster than one process of one
thread (two runs in turn: 35.3 / 37.7 s against 56.0 / 70.7 s; 1.66x in a third run), and
1.06-1.07x faster than one process of two threads (37.3 / 40.5 s). The peak per process falls
from 1.51 GB to 0.93 GB on 2 and 0.60 GB on 4 processes (0.39 of one process's; 0.31 without the
0.20 GB every process holds for Python, NumPy, SciPy and the Numba kernels).
Measured: 2026-11-29, commit d7dfcd3; quoted in docs/validation/several-processes.md, "One
linear solve over processes"
Run: python -m fbmbench distributed_solve --rows 2x1 1x2 1x1 2x1 1x2 1x1 --level 1

Every row is one ``mpiexec -n P`` run (``P x T``: P processes of T Numba threads each), one
after the other: the ten Cate box at ``level`` (its graded mesh, walls all round, no particle:
the fluid part of a step's system), the Oseen system of a backward-Euler step (``dt``, water-
glycerol E4's density and viscosity) linearised at a swirl about the box's axis of 0.1 m/s at 5
cm from it, a random right-hand side (the same for every row), solved to ``rtol``. Rank 0
reports the set-up (slab levels, systems, smoothers, the coarsest factorisation) and solve
seconds, the cycles, the unknowns and the peak resident memory of the largest process and the
sum over processes. Oversubscribed rows (more processes times threads than cores) are marked:
their times mean nothing, their cycles and memory do.

writes benchmarks/results/distributed_solve.{json,md}; ``--tag`` names the run (rows with other
tags are kept).
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

from studies.thread_scaling import RESULTS, commit, machine

#: the start of a child run: every process reads its arguments, joins the world and builds the
#: ten Cate box at the level asked for, walls all round
CHILD_HEAD = r"""
import json, resource, sys, time
import numpy as np
import numba
from fbmflow.flow import Dirichlet, NoSlip
from fbmflow.parallel import world
from fbmflow.scenes.tencate import TenCate
args = json.loads(sys.argv[1])
comm = world()
mesh = TenCate.mesh(args["level"], "full")
boundary = {t: NoSlip() for t in mesh.tags}
"""
#: its end: rank 0 prints the body's ``result`` with the processes, threads and peak memory
CHILD_TAIL = r"""
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 / 1e9
peaks = comm.allgather(peak) if comm.size > 1 else [peak]
if comm.rank == 0:
    print(json.dumps(dict(result, processes=comm.size, threads=numba.get_num_threads(),
                          peak_gb_max=max(peaks), peak_gb_sum=sum(peaks))))
"""
CHILD = CHILD_HEAD + r"""
from fbmflow.flow.blocks import BlockFlowLevels
from fbmflow.solvers.distributed import DistributedMultigrid
comm.Barrier() if comm.size > 1 else None
t0 = time.perf_counter()
slabs = BlockFlowLevels(mesh, boundary, True, comm, min_cells=64)
x = slabs.levels[0].space.V.coordinates
c = x - np.array([0.05, 0.05, 0.08])
u = np.concatenate([-c[:, 1], c[:, 0], 0.0 * c[:, 2]]) * (0.1 / 0.05)
system = slabs.systems(u, m=1.0 / args["dt"], a=1.0, rho=1250.0, mu=0.0373, convection=True)
solver = DistributedMultigrid(system, rtol=args["rtol"])
setup = time.perf_counter() - t0
fine = slabs.partitions[0]
unknowns = comm.allreduce(int(fine.owned.sum()))
b = fine.local(np.random.default_rng(11).standard_normal(unknowns))
t1 = time.perf_counter()
_, _, report = solver.solve(b[:system.n_u], b[system.n_u:])
result = dict(unknowns=unknowns, levels=len(solver.levels) + 1, setup_s=setup,
              solve_s=time.perf_counter() - t1, cycles=report.iterations, converged=report.converged)
""" + CHILD_TAIL


def run_mpiexec(code: str, args: dict, processes: int, threads: int, copies: int = 1) -> dict:
    """Run ``code`` (reading ``json.loads(sys.argv[1])``, rank 0 printing a JSON line last) under
    ``mpiexec -n processes`` at ``threads`` Numba threads and one BLAS thread each: that JSON.
    ``copies > 1``: as many independent runs at the same time, each with its own ``mpiexec``;
    the slowest copy's JSON (the largest ``s_per_step``, else the last), with every copy's
    ``s_per_step`` as ``copy_s_per_step``."""
    mpiexec = shutil.which("mpiexec", path=str(Path(sys.executable).parent)) or shutil.which("mpiexec")
    if mpiexec is None:
        raise SystemExit("this study needs mpiexec: pip install -e \".[mpi]\"")
    env = dict(os.environ, NUMBA_NUM_THREADS=str(threads), OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    runs = [subprocess.Popen([mpiexec, "-n", str(processes), sys.executable, "-c", code, json.dumps(args)],
                             env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
            for _ in range(copies)]
    results = []
    for run in runs:
        out, err = run.communicate()
        if run.returncode != 0:
            raise RuntimeError(f"{processes} x {threads} failed:\n{err[-3000:]}")
        results.append(json.loads(out.strip().splitlines()[-1]))
    if copies == 1:
        return results[0]
    slowest = max(results, key=lambda r: r.get("s_per_step", 0.0))
    return dict(slowest, copy_s_per_step=[r.get("s_per_step") for r in results])


def speed_ups(rows: list[dict], seconds: str) -> list[str]:
    """Per row, the mean ``seconds`` of the 1 x 1 rows of its run (tag) over its own ("" where the
    run has none), with ``*`` beside its processes times threads where they exceed the cores;
    rows of several copies at once are not 1 x 1 rows."""
    alone: dict = {}
    for r in rows:
        if r["processes"] == 1 and r["threads"] == 1 and r.get("copies", 1) == 1:
            alone.setdefault(r["tag"], []).append(r[seconds])
    return [f"{sum(alone[r['tag']]) / len(alone[r['tag']]) / r[seconds]:.2f}" if r["tag"] in alone else ""
            for r in rows]


def run_rows(name: str, rows: list[str], measure, table, tag: str, options: str) -> list[dict]:
    """Measure every ``PxT`` row in turn (``measure(processes, threads) -> dict``), writing
    ``benchmarks/results/NAME.{json,md}`` (``table(rows) -> str``) after each, the rows of other
    tags kept; ``options``: the study's command-line options beside ``--rows``. A row ``N*PxT``
    runs ``N`` copies at once (``measure(processes, threads, copies=N)``, for studies that take
    it)."""
    RESULTS.mkdir(exist_ok=True)
    path = RESULTS / f"{name}.json"
    kept = [r for r in json.loads(path.read_text()) if r["tag"] != tag] if path.exists() else []
    done = []
    for row in rows:
        many, _, shape = row.rpartition("*")
        copies = int(many) if many else 1
        processes, threads = (int(v) for v in shape.split("x"))
        r = measure(processes, threads, **({"copies": copies} if copies > 1 else {}))
        r.update(tag=tag, machine=machine(), cores=os.cpu_count(), tree=commit(), copies=copies,
                 command=f"python -m fbmbench {name} --rows {repr(row) if copies > 1 else row} {options}")
        figures = ", ".join(f"{k} {v:.3g}" for k, v in r.items() if isinstance(v, float))
        print(f"{row}: {figures}", flush=True)
        done.append(r)
        path.write_text(json.dumps(kept + done, indent=1))
        (RESULTS / f"{name}.md").write_text(table(kept + done))
    return done


def table(rows: list[dict]) -> str:
    lines = ["# One step's linear solve over processes (python -m fbmbench distributed_solve)", "",
             "One `mpiexec -n P` run per row, one after the other, nothing else running. Speed-up: the "
             "mean solve seconds of the 1 x 1 rows of the same run (tag) over this row's; `*`: more "
             "processes times threads than cores (the times mean nothing).", "",
             "| tag | machine | tree | level | unknowns | P x T | levels | cycles | set-up s | solve s | "
             "speed-up | peak GB (largest process) | peak GB (all) | command |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r, speedup in zip(rows, speed_ups(rows, "solve_s")):
        over = "*" if r["processes"] * r["threads"] > r["cores"] else ""
        lines.append(f"| {r['tag']} | {r['machine']} | {r['tree']} | {r['level']} | {r['unknowns']} | "
                     f"{r['processes']} x {r['threads']}{over} | {r['levels']} | {r['cycles']} | "
                     f"{r['setup_s']:.1f} | {r['solve_s']:.1f} | {speedup} | {r['peak_gb_max']:.2f} | "
                     f"{r['peak_gb_sum']:.2f} | `{r['command']}` |")
    return "\n".join(lines) + "\n"


def run(*, rows: list[str] = ("1x1", "1x2", "2x1", "4x1"), level: int = 1, dt: float = 0.01,
        rtol: float = 1e-8, tag: str = "dev") -> None:
    """Solve once per row.

    Parameters
    ----------
    rows : ``PxT``: P processes of T Numba threads each, one run per row in this order
    level : the ten Cate mesh's level
    dt : the backward-Euler step [s]
    rtol : the residual reduction per solve
    tag : this run's name in the results (rows with other tags are kept)
    """
    def measure(processes, threads):
        return dict(run_mpiexec(CHILD, dict(level=level, dt=dt, rtol=rtol), processes, threads), level=level)

    run_rows("distributed_solve", rows, measure, table, tag, f"--level {level} --dt {dt} --rtol {rtol}")
