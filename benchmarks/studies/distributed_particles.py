"""Particle scenes over several processes: the same trajectory, the cycles, the time per step.

Question: do ``mpiexec -n P`` runs of a particle scene (fbmflow.simulation.Simulation on blocks,
multigrid) give one process's particle trajectory, in how many cycles, and is a step of ten
Cate's level 1 faster on two processes than on one process of one or two threads?
Answer: at level 0 with tolerances of 1e-10, 10 steps on 2 and 4 processes follow one process's
trajectory to 5.0e-13 / 2.0e-12 (glowinski-free-fall's velocities, its default sharp boundary)
and 2.2e-10 / 4.3e-10 (ten-cate's, the sharp boundary and the surface force), in 1.00-1.12 times
the cycles per step; with the nodal boundary to 2.0e-14 / 1.9e-12 and 2.7e-10 / 2.2e-10. A ten
Cate level-1 step (quarter box, 278 739 unknowns) at its defaults takes 12.6 s on two processes
of one thread, 12.5 s on one process of two threads and 19.1 s on one of one thread: 1.51x,
short of the 1.8x asked for (13.1 / 13.5 / 18.8 s, 1.43x, before the Newton drift fix; nodal
boundary: 1.46-1.59x); 0.50 GB per process against 0.69 GB. Two one-process runs at once
(rows ``2*1x1``) each take 1.05-1.34x as long as one alone, so two processes cannot beat
1.49-1.80x on this machine; the step on two processes reached 1.30-1.46x in the same runs, the
lower slab's process waiting 2.99 s of a 13.46 s step in the exchanges against the sphere's 0.57
s. On 4 processes (level 0, nodal, 10 steps) 2 x 2 x 1 blocks follow one process to 1.4e-10 in
the velocities in 1.04 times the cycles, 1 x 1 x 4 slabs to 2.2e-10 in 1.00 times. One step at
level 2 (2 012 403 unknowns): the largest of 4 processes peaks at 1.06 GB against 2.71 GB on one
(0.39; nodal boundary 1.10 against 2.94, 0.37).
Measured: 2026-11-30, commit e447e55 (speed-limit, speed-limit-2, speed-limit-3), 6622083+
(blocks-same, blocks-same-slabs) and 6497113 (memory-L2, memory-L2-nodes); 2026-11-29, commit
1c96a0a (tag speed-sharp-2), 585120f (sharp-2d, sharp, speed-sharp), 59e90f9 (same, speed) and
84a4a58 (same-2d, speed2); quoted in docs/validation/several-processes.md, "The sharp
boundary", "Particles", "Blocks in two and three directions", "Two processes on this machine:
what limits them" and "Memory per process at level 2"
Run: python -m fbmbench distributed_particles --rows 1x1 2x1 4x1 --scene ten-cate --level 0 --steps 10
--settings solver.linear=multigrid solver.newton_rtol=1e-10 solver.linear_rtol=1e-10
coupling.tol=1e-10

Every row is one ``mpiexec -n P`` run (``P x T``: P processes of T Numba threads each), one after
the other: the scene at ``level`` with the ``settings`` (``KEY=VALUE``, as ``fbmflow run
--set``), ``steps`` time steps. Rank 0 reports every step's particle positions and velocities,
the cycles per step (every linear solve of the step: Newton's and the implicit coupling's
responses), the seconds per step after the first (which also builds the hierarchies), the
unknowns and the peak resident memory of the largest process. The table gives each row's largest
difference from the trajectory of the 1 x 1 row of the same run (tag, scene, level), relative to
that trajectory's largest value. Oversubscribed rows (more processes times threads than cores)
are marked: their times mean nothing, their trajectories and cycles do.

writes benchmarks/results/distributed_particles.{json,md}; ``--tag`` names the run (rows with
other tags are kept).
"""
from __future__ import annotations

import numpy as np

from studies.distributed_solve import CHILD_TAIL, run_mpiexec, run_rows, speed_ups

CHILD = r"""
import json, resource, sys, time
import numpy as np
import numba
from fbmflow.parallel.blocks import BlockPartition
from fbmflow.scenes.registry import load_scene
args = json.loads(sys.argv[1])
spent = [0.0]  # seconds in the partitions' exchanges and sums, the wait for a neighbour included


def timed(method):
    def wrapper(*a, **k):
        t = time.perf_counter()
        try:
            return method(*a, **k)
        finally:
            spent[0] += time.perf_counter() - t
    return wrapper


for name in ("update_ghosts", "add_ghosts", "dot", "pressure_dot"):
    setattr(BlockPartition, name, timed(getattr(BlockPartition, name)))
scene, params, level = load_scene(args["scene"], args["level"], args["settings"])
sim = scene.build(params, level).sim
comm = sim.comm
times, exchanges, cycles, position, velocity = [], [], [], [], []
for k in range(args["steps"]):
    t0, e0 = time.perf_counter(), spent[0]
    report = sim.step()
    times.append(time.perf_counter() - t0)
    exchanges.append(spent[0] - e0)
    cycles.append(report.linear.iterations)
    position.append(report.position.tolist())
    velocity.append(report.velocity.tolist())
exchange = float(np.mean(exchanges[1:] or exchanges))
result = dict(unknowns=sim.n_dofs, s_per_step=float(np.mean(times[1:] or times)),
              exchange_s_per_step=comm.allgather(exchange) if comm.size > 1 else [exchange],
              cycles_per_step=float(np.mean(cycles)), position=position, velocity=velocity)
""" + CHILD_TAIL


def differences(rows: list[dict]) -> list[str]:
    """Per row, ``position / velocity``: the largest difference from the 1 x 1 row of its run
    (tag, scene, level), relative to that row's largest value ("" where there is none)."""
    alone = {(r["tag"], r["scene"], r["level"]): r for r in rows
             if r["processes"] == 1 and r["threads"] == 1 and r.get("copies", 1) == 1}
    out = []
    for r in rows:
        one = alone.get((r["tag"], r["scene"], r["level"]))
        if one is None or len(one["position"]) != len(r["position"]):
            out.append("")
            continue
        figures = []
        for key in ("position", "velocity"):
            a, b = np.array(one[key]), np.array(r[key])
            figures.append(f"{np.abs(b - a).max() / np.abs(a).max():.1e}")
        out.append(" / ".join(figures))
    return out


def table(rows: list[dict]) -> str:
    lines = ["# Particle scenes over processes (python -m fbmbench distributed_particles)", "",
             "One `mpiexec -n P` run per row, one after the other, nothing else running. Difference: the "
             "largest difference of the particles' positions / velocities over the steps from the 1 x 1 "
             "row of the same run (tag, scene, level), relative to that row's largest value. Speed-up: the "
             "mean seconds per step (after the first) of the 1 x 1 rows of the same tag over this row's; "
             "`*`: more processes times threads than cores (the times mean nothing). `N at once`: N "
             "independent runs at the same time, each one's seconds, the slowest one's other figures: N "
             "times its speed-up is what "
             "N processes could reach on this machine if dividing the work cost nothing. Exchanges: the "
             "seconds per step (after the first; each process's) in the halo exchanges and the sums of "
             "the slabs, the wait for the slower neighbour included.", "",
             "| tag | machine | tree | scene | level | unknowns | P x T | steps | difference | "
             "cycles / step | s / step | exchanges s / step | speed-up | peak GB (largest process) | "
             "command |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r, difference, speedup in zip(rows, differences(rows), speed_ups(rows, "s_per_step")):
        copies = r.get("copies", 1)
        over = "*" if copies * r["processes"] * r["threads"] > r["cores"] else ""
        at_once = f", {copies} at once" if copies > 1 else ""
        seconds = " / ".join(f"{v:.2f}" for v in r.get("copy_s_per_step", [r["s_per_step"]]))
        exchange = " / ".join(f"{e:.2f}" for e in np.atleast_1d(r.get("exchange_s_per_step", [])))
        lines.append(f"| {r['tag']} | {r['machine']} | {r['tree']} | {r['scene']} | {r['level']} | "
                     f"{r['unknowns']} | {r['processes']} x {r['threads']}{at_once}{over} | "
                     f"{len(r['position'])} | {difference} | {r['cycles_per_step']:.1f} | "
                     f"{seconds} | {exchange} | {speedup} | "
                     f"{r['peak_gb_max']:.2f} | `{r['command']}` |")
    return "\n".join(lines) + "\n"


def run(*, rows: list[str] = ("1x1", "2x1", "4x1"), scene: str = "ten-cate", level: int = 0, steps: int = 10,
        settings: list[str] = ("fbm.boundary=nodes", "solver.linear=multigrid"), tag: str = "dev") -> None:
    """Run ``steps`` steps of ``scene`` once per row.

    Parameters
    ----------
    rows : ``PxT``: P processes of T Numba threads each, one run per row in this order;
        ``N*PxT``: N such runs at once (``2*1x1``: the machine's own limit on two processes)
    scene : a particle scene's name
    level : its level
    steps : the time steps of every row
    settings : the scene's settings, ``KEY=VALUE`` as ``fbmflow run --set``
    tag : this run's name in the results (rows with other tags are kept)
    """
    settings = list(settings)

    def measure(processes, threads, copies=1):
        args = dict(scene=scene, level=level, steps=steps, settings=settings)
        return dict(run_mpiexec(CHILD, args, processes, threads, copies), scene=scene, level=level)

    run_rows("distributed_particles", rows, measure, table, tag,
             f"--scene {scene} --level {level} --steps {steps} --settings {' '.join(settings)}")
