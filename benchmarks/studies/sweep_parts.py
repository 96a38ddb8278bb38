"""Where a time step's smoothing goes, part by part and level by level, against threads.

Question: which parts of the factored Vanka smoother's sweeps keep a time step from running twice
as fast on two threads as on one, and does dynamic scheduling of a phase's groups help?
Answer: ten Cate level 1 (278 739 unknowns, 12 x 12 x 64 cells), this 2-core machine, the second
step: the step took 25.24 s on 1 thread and 14.48 s on 2 (1.74x). The fine level's slab phases
(16 groups of 98-144 patches each) 14.26 / 7.58 s (1.88x), the coarse level's 1.71 / 0.93 s
(1.84x); the agglomerated patches at the sphere (3 920 phases of about two patches each, 70
colours per sweep) 1.17 / 0.75 s (1.56x), the other agglomerated ones 0.58 / 0.36 s (1.60x); the
interface and far patches under 0.06 s each. Handing a phase's groups out one at a time (chunk 1)
gave 8.10 s on 2 threads against 7.58 s: no help. An earlier run of the same code an hour before,
by hand, gave the fine phases 11.80 / 7.84 s (1.50x): this machine's two cores scale the sweeps by
1.5-1.9x from one hour to the next, a compute-bound loop by 1.91x.
Measured: 2026-11-29, commit 8e498bb; quoted in
docs/validation/multigrid-with-fictitious-boundaries.md, "Threads"
Run: python -m fbmbench sweep_parts --threads 2 1 --chunks 0 1

Each configuration (threads, chunk size) runs in its own process: the scene is built, ``warm``
steps are taken, then one step with every call of
:meth:`~fbmflow.solvers.vanka.FactoredVankaSmoother.sweep_phases` and
:meth:`~fbmflow.solvers.vanka.FactoredVankaSmoother.update` timed and summed by level (its cells)
and part: ``main`` (the slab phases), ``interface`` (the cell patches at a fictitious boundary,
swept again), ``interface merged`` (the agglomerated ones there, in colours), ``merged`` (all
agglomerated patches, in colours), ``far`` (the far-reaching patches, one after the other).
A chunk size of 0 is Numba's static split of a phase's groups between the threads; 1 hands them
out one at a time (``numba.parallel_chunksize``).

writes benchmarks/results/sweep_parts.{json,md}: the rows of this run; ``--tag`` names the run
(rows with other tags are kept).
"""
from __future__ import annotations

import json
from pathlib import Path

from studies.thread_scaling import commit, machine, run_child

RESULTS = Path(__file__).resolve().parents[1] / "results"

CHILD = r"""
import collections, json, sys, time
import numba
from fbmflow.scenes.registry import load_scene
from fbmflow.cores import FREE_CORES
from fbmflow.solvers import vanka
args = json.loads(sys.argv[1])
FREE_CORES.threads = lambda limit: limit  # the count asked for, whatever other processes do
scene, params, level = load_scene(args["scene"], args["level"], args["overrides"])
setup = scene.build(params, level)
for _ in range(args["warm"]):
    setup.sim.step(setup.dt)
parts = collections.defaultdict(lambda: [0.0, 0, 0])
sweep, update = vanka.FactoredVankaSmoother.sweep_phases, vanka.FactoredVankaSmoother.update

def part(self, phases):
    if any(phases is p for p, _ in self.sweeps):
        return "main"
    return {id(self.interface_phases): "interface", id(self.interface_merged_phases): "interface merged",
            id(self.merged_phases): "merged"}.get(id(phases), "other")

def timed_sweep(self, phases, b, x):
    t = time.perf_counter()
    with numba.parallel_chunksize(args["chunk"]):
        sweep(self, phases, b, x)
    p = parts[(self.n_cells, part(self, phases))]
    p[0] += time.perf_counter() - t
    p[1] += len(phases)
    p[2] += sum(int(g[-1] - g[0]) for g, _ in phases)

def timed_update(self, patches, b, x, omega=None):
    t = time.perf_counter()
    update(self, patches, b, x, omega)
    p = parts[(self.n_cells, "far")]
    p[0] += time.perf_counter() - t
    p[1] += 1
    p[2] += int(patches.size)

vanka.FactoredVankaSmoother.sweep_phases, vanka.FactoredVankaSmoother.update = timed_sweep, timed_update
t = time.perf_counter()
setup.sim.step(setup.dt)
step = time.perf_counter() - t
print(json.dumps(dict(threads=numba.get_num_threads(), step_s=step, unknowns=int(setup.sim.flow.n_dofs),
                      parts=[dict(cells=c, part=k, s=v[0], phases=v[1], patches=v[2])
                             for (c, k), v in sorted(parts.items()) if v[2]])))
"""


def one(threads: int, chunk: int, scene: str, level: int, overrides: list[str], warm: int) -> dict:
    """One process at ``threads`` Numba threads and group chunk size ``chunk``."""
    args = dict(scene=scene, level=level, overrides=overrides, warm=warm, chunk=chunk)
    return run_child(CHILD, args, threads, what=f"{threads} threads, chunk {chunk}")[0]


def table(rows: list[dict]) -> str:
    """The rows as Markdown: one line per process and part."""
    lines = ["# A time step's smoothing by part and level (python -m fbmbench sweep_parts)", "",
             "One process per configuration, one after the other, nothing else running; seconds summed "
             "over the timed step. `chunk`: 0 Numba's static split of a phase's groups, 1 one group at "
             "a time.", "",
             "| tag | machine | scene | level | unknowns | commit | threads | chunk | step s | level cells | "
             "part | phases | patches | s |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        for p in r["parts"]:
            lines.append(f"| {r['tag']} | {r['machine']} | {r['scene']} | {r['level']} | {r['unknowns']} | "
                         f"{r['commit']} | {r['threads']} | {r['chunk']} | {r['step_s']:.2f} | "
                         f"{p['cells']} | {p['part']} | {p['phases']} | {p['patches']} | {p['s']:.3f} |")
    return "\n".join(lines) + "\n"


def run(*, threads: list[int] = (2, 1), chunks: list[int] = (0,), scene: str = "ten-cate", level: int = 1,
        overrides: list[str] = (), warm: int = 1, tag: str = "dev") -> None:
    """Time one step's smoothing by part at every thread count and chunk size.

    Parameters
    ----------
    threads : Numba thread counts, one process each
    chunks : chunk sizes of a phase's groups (0: static), one process each
    scene : the scene
    level : its level
    overrides : ``KEY=VALUE`` parameter overrides
    warm : steps taken before the timed one
    tag : this run's name in the results (rows with other tags are kept)
    """
    path = RESULTS / "sweep_parts.json"
    kept = [r for r in json.loads(path.read_text()) if r["tag"] != tag] if path.exists() else []
    rows = []
    for k in threads:
        for chunk in chunks:
            r = one(k, chunk, scene, level, list(overrides), warm)
            rows.append(dict(r, tag=tag, machine=machine(), scene=scene, level=level, commit=commit(),
                             chunk=chunk))
            main = sum(p["s"] for p in r["parts"] if p["part"] == "main")
            print(f"{k} threads, chunk {chunk}: step {r['step_s']:.2f} s, slab phases {main:.2f} s",
                  flush=True)
    RESULTS.mkdir(exist_ok=True)
    path.write_text(json.dumps(kept + rows, indent=1))
    (RESULTS / "sweep_parts.md").write_text(table(kept + rows))
