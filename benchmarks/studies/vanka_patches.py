"""The factored Vanka smoother's patches: what the component Schur patches save in memory and
sweep time, and what reading the scalar rows from the velocity block costs.

Question: cells at a symmetry plane have unit rows in one velocity component, so their ``d``
rows are no one scalar row; solved through the Schur complement of their ``d`` component blocks
instead of an LU of the whole block, how much memory do the local factors need, and how fast is
a sweep? And is a sweep slower when it reads the scalar rows from the velocity block (float64)
instead of a float32 copy (as before eb765b3)?
Answer: ten Cate level 1 (278 739 unknowns), the last system of the first step: 1 425 of the
9 130 cell patches of the fine level are such cells (its two mirror planes); their factors go
from 7 225 to 2 851 values each, the fine level's factors from 92.5 to 67.6 MB (332 -> 242
bytes per unknown). Four sweeps, 12 timings each in turn in one process: 0.299 against 0.312 s
(median) on 2 threads, 0.562 against 0.582 s on 1 (b7e7028; at 67f4d95 0.397 / 0.393 s on 2
threads, within the repeats' spread of 0.31-0.40 s, and 0.578 / 0.604 s on 1); one sweep's
result differs by 4.8e-8 relative (the single-precision factors' rounding). The scalar rows
read from the velocity block in float64 instead of a float32 copy (37 MB, 134 bytes per
unknown): 0.578 against 0.565 s on 1 thread (2 % slower), 0.397 against 0.392 s on 2.
Measured: 2026-11-28, commit 67f4d95 (the first comparison also at b7e7028); quoted in
docs/validation/multigrid-with-fictitious-boundaries.md, "Memory"
Run: python -m fbmbench vanka_patches --threads 2 1 --repeats 12

The scene is built at ``level`` and one time step taken; the last linear system it solved (its
Picard preconditioner where it has one) gets two factored Vanka smoothers, with and without the
component blocks (``FactoredVankaSmoother(component_blocks=...)``), and a third that is the
first with a float32 copy of the scalar rows in its operator. For each thread count
(``numba.set_num_threads``) four sweeps of each are timed in turn, ``repeats`` times.

writes benchmarks/results/vanka_patches.{json,md}: the rows of this run with the machine;
``--tag`` names the run (rows with other tags are kept).
"""
from __future__ import annotations

import copy
import json
import time
from pathlib import Path

from studies.smoother_threads import last_system
from studies.thread_scaling import machine

BENCHMARKS = Path(__file__).resolve().parents[1]
RESULTS = BENCHMARKS / "results"
VARIANTS = {"component blocks": True, "LU of the whole block": False}


def table(rows: list[dict]) -> str:
    lines = ["# The factored Vanka smoother's patches (python -m fbmbench vanka_patches)", "",
             "One process per tag. `patches`: cells through one scalar block's Schur complement / "
             "through the `d` component blocks' / by an LU of the whole block (and agglomerated "
             "patches); `factors`: the fine level's stored factors; sweep: four sweeps, the median "
             "and best of the repeats in turn; `difference`: of one sweep's result from the "
             "other variant's, relative to its largest entry.", "",
             "| tag | machine | scene | level | unknowns | variant | patches 1 / d / LU | factors MB | "
             "bytes / unknown | threads | 4 sweeps s, median (best) | difference |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['tag']} | {r['machine']} | {r['scene']} | {r['level']} | {r['unknowns']} | "
                     f"{r['variant']} | {r['patches']} | {r['factors_mb']:.1f} | "
                     f"{r['bytes_per_unknown']:.0f} | "
                     f"{r['threads']} | {r['median_s']:.3f} ({r['best_s']:.3f}) | {r['difference']:.1e} |")
    return "\n".join(lines) + "\n"


def run(*, threads: list[int] = (2, 1), scene: str = "ten-cate", level: int = 1, repeats: int = 12,
        tag: str = "dev") -> None:
    """Build both smoothers on one system and time their sweeps in turn.

    Parameters
    ----------
    threads : Numba thread counts (at most the process's NUMBA_NUM_THREADS)
    scene : the scene
    level : its level
    repeats : timings per variant and thread count, in turn
    tag : this run's name in the results (rows with other tags are kept)
    """
    import numba
    import numpy as np

    from fbmflow.solvers.vanka import FactoredVankaSmoother

    system = last_system(scene, level)
    smoothers = {name: FactoredVankaSmoother(system, component_blocks=on) for name, on in VARIANTS.items()}
    block = system.A
    if hasattr(block, "scalar_rows"):  # a VelocityBlock: the scalar rows copied, as before eb765b3
        copied = copy.copy(smoothers["component blocks"])
        op = list(copied.op)
        op[1:4] = block.scalar_rows(op[0], np.float32)  # the rows of the nodes op[0] marks
        copied.op = tuple(op)
        smoothers["component blocks, scalar rows copied in float32"] = copied
    n = system.n_u + system.n_p
    b = np.random.default_rng(0).standard_normal(n)
    once = {}
    for name, smoother in smoothers.items():
        once[name] = np.zeros(n)
        smoother.smooth(b, once[name], 1)
    first, second = once["component blocks"], once["LU of the whole block"]
    difference = float(np.abs(first - second).max() / np.abs(second).max())
    RESULTS.mkdir(exist_ok=True)
    path = RESULTS / "vanka_patches.json"
    kept = [r for r in json.loads(path.read_text()) if r["tag"] != tag] if path.exists() else []
    rows, where = [], machine()
    for k in threads:
        numba.set_num_threads(k)
        times = {name: [] for name in smoothers}
        for _ in range(repeats):
            for name, smoother in smoothers.items():
                x = np.zeros(n)
                t0 = time.perf_counter()
                smoother.smooth(b, x, 4)
                times[name].append(time.perf_counter() - t0)
        for name, smoother in smoothers.items():
            cells = smoother.blocks[:smoother.blocks.size - smoother.merged.size]
            kinds = (f"{(cells == 1).sum()} / {(cells > 1).sum()} / {(cells == 0).sum()} "
                     f"({smoother.merged.size})")
            row = dict(tag=tag, machine=where, scene=scene, level=level, unknowns=int(n), variant=name,
                       patches=kinds, factors_mb=smoother.store.nbytes / 1e6,
                       bytes_per_unknown=smoother.store.nbytes / n, threads=k,
                       median_s=float(np.median(times[name])), best_s=float(np.min(times[name])),
                       difference=difference)
            rows.append(row)
            print(f"{name}, {k} threads: {row['median_s']:.3f} s ({row['best_s']:.3f}) for 4 sweeps, "
                  f"patches {kinds}, factors {row['factors_mb']:.1f} MB", flush=True)
    rows = kept + rows
    path.write_text(json.dumps(rows, indent=1))
    (RESULTS / "vanka_patches.md").write_text(table(rows))
