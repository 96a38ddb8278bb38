"""Time steps of a flow over several processes, against processes and threads.

Question: is a time step of the ten Cate box's flow faster on two processes of one thread each
than on one process of one or two threads (fbmflow.flow.blocks.BlockNavierStokesProblem), and how
do its cycles and memory per process change?
Answer: at level 1 (the full box, 1 076 643 unknowns, no sphere) a step takes 80.5 / 83.6 s on
two processes of one thread, 84.2 / 85.6 s on one process of two threads and 151.9 / 153.7 s on
one process of one thread (two runs in turn): 1.84-1.89x faster than one thread and 1.02-1.05x
faster than two threads, with 21 cycles per step in every row; 0.93 GB per process against
1.50 GB.
Measured: 2026-11-29, commit 9c93049 (src as at 67c9f99); quoted in
docs/validation/several-processes.md, "Time steps"
Run: python -m fbmbench distributed_step --rows 2x1 1x2 1x1 2x1 1x2 1x1 --level 1

Every row is one ``mpiexec -n P`` run (``P x T``: P processes of T Numba threads each), one after
the other: the ten Cate box at ``level`` (its graded mesh) with E4's fluid and no sphere, its lid
(the upper face) moving at 0.1 m/s from rest, fractional-step-theta steps of ``dt`` with the ten
Cate scene's Newton settings (a residual reduction of 1e-6, chord steps, linear steps to 1e-3).
The first step (which also builds the hierarchies) is left out; the next ``steps`` are timed.
Rank 0 reports the seconds and cycles per step, the unknowns and the peak resident memory of
the largest process and the sum over processes. Oversubscribed rows (more processes times
threads than cores) are marked: their times mean nothing.

writes benchmarks/results/distributed_step.{json,md}; ``--tag`` names the run (rows with other
tags are kept).
"""
from __future__ import annotations

from studies.distributed_solve import CHILD_HEAD, CHILD_TAIL, run_mpiexec, run_rows, speed_ups

CHILD = CHILD_HEAD + r"""
from fbmflow.flow.blocks import BlockNavierStokesProblem
from fbmflow.flow.time_schemes import advance
from fbmflow.solvers import NewtonSettings
boundary["zmax"] = Dirichlet((0.1, 0.0, 0.0))
newton = NewtonSettings(rtol=1e-6, linear_rtol=1e-3, reuse_jacobian=True)
flow = BlockNavierStokesProblem(mesh, 0.0373, boundary, comm, density=1250.0, newton=newton)
x, t, times, cycles = flow.zero_state(), 0.0, [], []
for k in range(1 + args["steps"]):
    before = flow.linear_work.iterations
    t0 = time.perf_counter()
    x, _ = advance(flow, x, t, args["dt"], "fractional-step-theta")
    t += args["dt"]
    if k:
        times.append(time.perf_counter() - t0)
        cycles.append(flow.linear_work.iterations - before)
times = comm.allreduce(np.array(times)) / comm.size if comm.size > 1 else np.array(times)
result = dict(unknowns=comm.allreduce(int(flow.partition.owned.sum())), s_per_step=float(np.mean(times)),
              cycles_per_step=float(np.mean(cycles)))
""" + CHILD_TAIL


def table(rows: list[dict]) -> str:
    lines = ["# Time steps of a flow over processes (python -m fbmbench distributed_step)", "",
             "One `mpiexec -n P` run per row, one after the other, nothing else running. Speed-up: the "
             "mean seconds per step of the 1 x 1 rows of the same run (tag) over this row's; `*`: more "
             "processes times threads than cores (the times mean nothing).", "",
             "| tag | machine | tree | level | unknowns | P x T | s / step | cycles / step | speed-up | "
             "peak GB (largest process) | peak GB (all) | command |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r, speedup in zip(rows, speed_ups(rows, "s_per_step")):
        over = "*" if r["processes"] * r["threads"] > r["cores"] else ""
        lines.append(f"| {r['tag']} | {r['machine']} | {r['tree']} | {r['level']} | {r['unknowns']} | "
                     f"{r['processes']} x {r['threads']}{over} | {r['s_per_step']:.2f} | "
                     f"{r['cycles_per_step']:.1f} | {speedup} | {r['peak_gb_max']:.2f} | "
                     f"{r['peak_gb_sum']:.2f} | `{r['command']}` |")
    return "\n".join(lines) + "\n"


def run(*, rows: list[str] = ("2x1", "1x2", "1x1"), level: int = 1, dt: float = 0.01, steps: int = 2,
        tag: str = "dev") -> None:
    """Time ``steps`` steps after the first, once per row.

    Parameters
    ----------
    rows : ``PxT``: P processes of T Numba threads each, one run per row in this order
    level : the ten Cate mesh's level
    dt : the time step [s]
    steps : the steps timed after the first
    tag : this run's name in the results (rows with other tags are kept)
    """
    def measure(processes, threads):
        args = dict(level=level, dt=dt, steps=steps)
        return dict(run_mpiexec(CHILD, args, processes, threads), level=level)

    run_rows("distributed_step", rows, measure, table, tag, f"--level {level} --dt {dt} --steps {steps}")
