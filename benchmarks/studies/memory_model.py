"""The memory guard's estimate against the measured peak, and where a time step's bytes go.

Question: how close is the memory guard's estimate (``fbmflow.solvers.choice.estimate_memory``)
to the peak a run measures, in 2D and 3D at three sizes, and which arrays hold the memory of a
3D particle time step?
Answer: the process's peak after one step of ten-cate at levels 0 / 1 / 2 (64 547 / 278 739 /
2 012 403 unknowns, multigrid) is 0.38 / 0.68 / 3.08 GB, 5 870 / 2 448 / 1 532 bytes per
unknown (0.48 / 1.27 / 7.63 GB at commit 1775983); a process's peak varies by a few per cent
between runs. The guard's time-step model (fitted to these) estimates 1.15-1.26 times that.
glowinski-free-fall at levels 2 / 3 / 4 (SuperLU): 0.28 / 0.53 / 1.49 GB. After one ten Cate
level-1 step NumPy and SciPy hold 0.400 GB (1 433 bytes per unknown; 1.02 GB at 1775983): the
smoother's factors 76 MB, the scalar velocity operator 39 MB, the divergence and its constrained
copy about 72 MB, the space's geometry and patterns about 42 MB. With the continuity block
(28462f9, no constrained copy): levels 1 / 2 at 0.65 / 2.67 GB, 2 337 / 1 328 bytes per unknown;
at ded330a level 1 at 0.62 GB, NumPy and SciPy holding 0.345 GB (1 236 bytes per unknown) after
the step, the block's changed rows 43 of them.
Measured: 2026-11-29, commit ded330a (ten-cate level 1 and the breakdown; level 2 at 28462f9,
level 0 at a1bb209, the glowinski rows at c34e364); quoted in
docs/validation/multigrid-with-fictitious-boundaries.md, "Memory"
Run: python -m fbmbench memory_model

Every case is one process, one after the other: the scene is built at its level, ``steps`` time
steps are taken, and the process reports its unknowns, its peak resident memory (``ru_maxrss``)
and the guard's estimate for its linear solver and a particle scene's time steps.
``--breakdown``: one more process for the first case, under ``tracemalloc``, lists the arrays
still held after the steps, grouped by the fbmflow line that allocated them (the last three
fbmflow frames), and the traced peak within the steps; tracemalloc sees NumPy's and SciPy's
allocations, not Numba's or the interpreter's.

writes benchmarks/results/memory_model.{json,md} (rows of cases not run are kept).
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

BENCHMARKS = Path(__file__).resolve().parents[1]
RESULTS = BENCHMARKS / "results"

CHILD = r"""
import json, sys, time
args = json.loads(sys.argv[1])
if args["breakdown"]:
    import tracemalloc
    tracemalloc.start(64)
from fbmflow.scenes.registry import load_scene
from fbmflow.solvers.choice import estimate_memory, peak_resident_memory
scene, params, level = load_scene(args["scene"], args["level"], args["overrides"])
setup = scene.build(params, level)
sim = setup.sim
if args["breakdown"]:
    tracemalloc.reset_peak()
t0 = time.perf_counter()
for _ in range(args["steps"]):
    sim.step(setup.dt)
wall = time.perf_counter() - t0
n, dim = int(sim.flow.n_dofs), sim.flow.mesh.dim
need, words = estimate_memory(n, dim, sim.flow.linear_solver, transient=True)  # a particle scene
out = dict(unknowns=n, dim=dim, solver=words, estimate_gb=need / 1e9,
           peak_gb=peak_resident_memory() / 1e9, s_per_step=wall / args["steps"])
if args["breakdown"]:
    from collections import defaultdict
    current, peak = tracemalloc.get_traced_memory()
    by = defaultdict(int)
    for stat in tracemalloc.take_snapshot().statistics("traceback"):
        frames = [f for f in stat.traceback if "/fbmflow/" in f.filename]
        key = " <- ".join(f"{f.filename.split('/fbmflow/')[1]}:{f.lineno}" for f in frames[-3:][::-1])
        by[key or "outside fbmflow"] += stat.size
    out.update(traced_gb=current / 1e9, traced_peak_gb=peak / 1e9,
               sites=sorted(([k, v / 1e6] for k, v in by.items()), key=lambda kv: -kv[1])[:args["top"]])
print(json.dumps(out))
"""

#: name -> (scene, level, overrides)
CASES = {
    "ten-cate-0": ("ten-cate", 0, []), "ten-cate-1": ("ten-cate", 1, []),
    "ten-cate-2": ("ten-cate", 2, []),
    "glowinski-2": ("glowinski-free-fall", 2, []), "glowinski-3": ("glowinski-free-fall", 3, []),
    "glowinski-4": ("glowinski-free-fall", 4, []),
}


def one(case: str, steps: int, breakdown: bool = False, top: int = 15) -> dict:
    """One process for ``case``."""
    scene, level, overrides = CASES[case]
    args = dict(scene=scene, level=level, overrides=overrides, steps=steps, breakdown=breakdown, top=top)
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    proc = subprocess.run([sys.executable, "-c", CHILD, json.dumps(args)], env=env, capture_output=True,
                          text=True, check=False)
    if proc.returncode != 0:
        raise RuntimeError(f"{case} failed:\n{proc.stderr[-3000:]}")
    row = json.loads(proc.stdout.strip().splitlines()[-1])
    return dict(row, case=case, scene=scene, level=level, steps=steps)


def table(rows: list[dict], breakdown: dict | None) -> str:
    lines = ["# The memory guard's estimate against the measured peak (python -m fbmbench memory_model)", "",
             "One process per row: build, then the steps; `peak`: the process's peak resident memory "
             "(interpreter, libraries and compiled kernels included); `estimate`: "
             "`fbmflow.solvers.choice.estimate_memory` for the run's linear solver.", "",
             "| case | dim | unknowns | solver | steps | peak GB | bytes / unknown | estimate GB | "
             "estimate / peak |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['case']} | {r['dim']} | {r['unknowns']} | {r['solver']} | {r['steps']} | "
                     f"{r['peak_gb']:.2f} | {r['peak_gb'] * 1e9 / r['unknowns']:.0f} | "
                     f"{r['estimate_gb']:.2f} | {r['estimate_gb'] / r['peak_gb']:.2f} |")
    if breakdown:
        b = breakdown
        lines += ["", f"## Where the bytes are: {b['case']} ({b['unknowns']} unknowns)", "",
                  f"Under tracemalloc, after {b['steps']} step(s): {b['traced_gb']:.3f} GB held by NumPy "
                  f"and SciPy arrays ({b['traced_gb'] * 1e9 / b['unknowns']:.0f} bytes per unknown), a peak "
                  f"of {b['traced_peak_gb']:.3f} GB within the steps; the process's peak "
                  f"{b['peak_gb']:.2f} GB. By allocating line (the last three fbmflow frames, innermost "
                  "first):", "",
                  "| MB | bytes / unknown | allocated at |", "|---|---|---|"]
        for site, mb in breakdown["sites"]:
            lines.append(f"| {mb:.1f} | {mb * 1e6 / breakdown['unknowns']:.0f} | `{site}` |")
    return "\n".join(lines) + "\n"


def run(*, cases: list[str] = ("ten-cate-1", "ten-cate-0", "ten-cate-2", "glowinski-2", "glowinski-3",
                               "glowinski-4"), steps: int = 1, breakdown: bool = True, top: int = 15) -> None:
    """Measure the cases one after the other.

    Parameters
    ----------
    cases : names of :data:`CASES` (the first is the one broken down)
    steps : time steps per case
    breakdown : list the arrays held after the steps of the first case (one more process)
    top : allocation sites listed
    """
    unknown = sorted(set(cases) - set(CASES))
    if unknown:
        raise SystemExit(f"memory_model: no case {unknown}; cases: {', '.join(CASES)}")
    RESULTS.mkdir(exist_ok=True)
    path = RESULTS / "memory_model.json"
    old = json.loads(path.read_text()) if path.exists() else {"rows": [], "breakdown": None}
    rows = {r["case"]: r for r in old["rows"]}
    found = old["breakdown"]
    for case in cases:
        rows[case] = one(case, steps)
        r = rows[case]
        print(f"{case}: {r['unknowns']} unknowns, peak {r['peak_gb']:.2f} GB, estimate "
              f"{r['estimate_gb']:.2f} GB", flush=True)
        ordered = [rows[c] for c in CASES if c in rows]
        path.write_text(json.dumps({"rows": ordered, "breakdown": found}, indent=1))
        (RESULTS / "memory_model.md").write_text(table(ordered, found))
    if breakdown and cases:
        found = one(cases[0], steps, breakdown=True, top=top)
        for site, mb in found["sites"]:
            print(f"{mb:8.1f} MB  {site}")
        ordered = [rows[c] for c in CASES if c in rows]
        path.write_text(json.dumps({"rows": ordered, "breakdown": found}, indent=1))
        (RESULTS / "memory_model.md").write_text(table(ordered, found))
