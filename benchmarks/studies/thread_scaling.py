"""Seconds per time step against Numba's thread count, for this tree and, beside it, another.

Question: how much faster is a time step of a 3D particle scene on more cores, and what did the
blocked sweep order and the parallel mat-vec change?
Answer: ten Cate level 1 on the 16-core machine (commit 152794f, the parallel mat-vec; the blocks
did not yet reach level 1): 8.67 s per step at 16 threads against a1c18aa's 9.86 s, 12.93
against 14.48 s at 2, 1.49x from 2 to 16 threads (before: 1.47x); on this 2-core machine the
blocked order's step at 2 threads is 9.31 s against 9.56 s, three runs each in turn: no
measurable change. The blocked order on 16 cores is not measured yet
(benchmarks/device/threads.sh).
Measured: 2026-11-28, commit dbea9d2; quoted in
docs/validation/multigrid-with-fictitious-boundaries.md, "Threads"
Run: python -m fbmbench thread_scaling --threads 2 --repeats 3 --baseline ../out/baseline/src

Every row is one process, run one after the other: the scene is built at ``level``, ``warm`` steps
are taken (the first step also builds the multigrid hierarchy's kernels from the Numba cache), and
the next ``steps`` steps are timed. The process reports seconds per step, the linear solves' share,
multigrid cycles per step and its peak resident memory. ``--baseline DIR`` runs the same rows
with the package at ``DIR`` (a ``src`` folder, for example ``git archive COMMIT src | tar -x -C
DIR``), so that the two trees' ratio is measured in one run on one machine. Run the Numba cache
warm first (one row at level 0 does).

writes benchmarks/results/thread_scaling.{json,md}: the rows of this run, with the machine (CPU
model and count); ``--tag`` names the run (rows with other tags are kept).
"""
from __future__ import annotations

import json
import os
import platform
import subprocess
import sys
from pathlib import Path

BENCHMARKS = Path(__file__).resolve().parents[1]
RESULTS = BENCHMARKS / "results"
SRC = BENCHMARKS.parent / "src"

CHILD = r"""
import json, resource, sys, time
args = json.loads(sys.argv[1])
import numba
from fbmflow.scenes.registry import load_scene
if not args["free_cores"]:
    try:  # the count asked for, whatever other processes do (trees before fbmflow.cores lack it)
        from fbmflow.cores import FREE_CORES
        FREE_CORES.threads = lambda limit: limit
    except ImportError:
        pass
scene, params, level = load_scene(args["scene"], args["level"], args["overrides"])
t0 = time.perf_counter()
setup = scene.build(params, level)
build = time.perf_counter() - t0
steps = []
total = args["warm"] + args["steps"]
for k in range(total):
    if args["profile"] and k == total - 1:
        import cProfile
        profile = cProfile.Profile()
        profile.enable()
    t1 = time.perf_counter()
    report = setup.sim.step(setup.dt)
    if k >= args["warm"]:
        steps.append(dict(wall=time.perf_counter() - t1, linear=report.linear.time_s,
                          cycles=report.linear.iterations, solves=report.linear.solves))
n = len(steps)
if args["profile"]:
    import io, pstats
    profile.disable()
    text = io.StringIO()
    pstats.Stats(profile, stream=text).sort_stats("tottime").print_stats(25)
    print(text.getvalue(), file=sys.stderr)
print(json.dumps(dict(threads=numba.get_num_threads(), build_s=build,
                      unknowns=int(setup.sim.flow.n_dofs),
                      s_per_step=sum(s["wall"] for s in steps) / n,
                      linear_s_per_step=sum(s["linear"] for s in steps) / n,
                      cycles_per_step=sum(s["cycles"] for s in steps) / n,
                      peak_gb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 / 1e9)))
"""


def machine() -> str:
    """CPU model and logical CPU count of this machine."""
    model = platform.processor() or "unknown CPU"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{model}, {os.cpu_count()} logical CPUs"


def commit() -> str:
    """The short git commit of this tree ("+" when its package has changes), "this tree" without
    git; or ``FBMFLOW_BENCH_COMMIT`` when set (a run of a source snapshot outside the repository,
    as :func:`fbmbench.common.commit`)."""
    if os.environ.get("FBMFLOW_BENCH_COMMIT"):
        return os.environ["FBMFLOW_BENCH_COMMIT"]
    try:
        head = subprocess.run(["git", "rev-parse", "--short=7", "HEAD"], cwd=BENCHMARKS, capture_output=True,
                              text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no", "--", str(SRC)],
                               cwd=BENCHMARKS, capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "this tree"
    return head + ("+" if dirty else "")


def one(tree: Path, threads: int, scene: str, level: int, overrides: list[str], warm: int, steps: int,
        profile: bool = False, free_cores: bool = False) -> dict:
    """One process: the package from ``tree`` at ``threads`` Numba threads (``profile``: its last
    step's functions by own time printed; ``free_cores``: multigrid may take fewer threads where
    other processes are busy, :mod:`fbmflow.cores`)."""
    args = dict(scene=scene, level=level, overrides=overrides, warm=warm, steps=steps, profile=profile,
                free_cores=free_cores)
    result, stderr = run_child(CHILD, args, threads, tree, f"{tree} at {threads} threads")
    if profile:
        print(stderr[-6000:], flush=True)
    return result


def run_child(code: str, args: dict, threads: int, tree: Path | None = None, what: str = "child") -> tuple:
    """Run ``code`` (reading ``json.loads(sys.argv[1])``, printing a JSON line last) in a process
    of its own at ``threads`` Numba threads and one BLAS thread, with the package from ``tree``
    first on the path (default: the installed one): its last line's JSON and its stderr."""
    env = dict(os.environ, NUMBA_NUM_THREADS=str(threads), OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    if tree is not None:
        env["PYTHONPATH"] = os.pathsep.join([str(tree)] + [p for p in [env.get("PYTHONPATH")] if p])
    out = subprocess.run([sys.executable, "-c", code, json.dumps(args)], env=env, capture_output=True,
                         text=True, check=False)
    if out.returncode != 0:
        raise RuntimeError(f"{what} failed:\n{out.stderr[-3000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1]), out.stderr


def table(rows: list[dict]) -> str:
    """The rows as Markdown, with each row's speed-up over its tree's fewest threads in the same
    run and, for this commit's rows, the baseline's time at the same threads over its own (both
    medians where a row has several runs)."""
    fewest = {}
    for r in rows:
        key = (r["tag"], r["tree"])
        if key not in fewest or r["threads"] < fewest[key]["threads"]:
            fewest[key] = r
    base = {(r["tag"], r["threads"]): r for r in rows if r["baseline"]}
    lines = ["# Seconds per time step against threads (python -m fbmbench thread_scaling)", "",
             "One process per row, one after the other, nothing else running. `tree`: the commit of the "
             "package measured. Speed-up: over the same tree's fewest threads in the same run; vs "
             "baseline: the baseline's seconds per step at the same threads (same tag) over this row's.", "",
             "| tag | machine | scene | level | unknowns | tree | threads | runs | s / step (range) | "
             "linear s / step | cycles / step | speed-up | vs baseline | peak GB |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        speedup = fewest[(r["tag"], r["tree"])]["s_per_step"] / r["s_per_step"]
        b = None if r["baseline"] else base.get((r["tag"], r["threads"]))
        versus = f"{b['s_per_step'] / r['s_per_step']:.2f}" if b else ""
        low, high = r.get("s_per_step_range", [r["s_per_step"]] * 2)
        spread = f" ({low:.2f}-{high:.2f})" if r.get("runs", 1) > 1 else ""
        lines.append(f"| {r['tag']} | {r['machine']} | {r['scene']} | {r['level']} | {r['unknowns']} | "
                     f"{r['tree']} | {r['threads']} | {r.get('runs', 1)} | {r['s_per_step']:.2f}{spread} | "
                     f"{r['linear_s_per_step']:.2f} | {r['cycles_per_step']:.1f} | {speedup:.2f} | "
                     f"{versus} | {r['peak_gb']:.2f} |")
    return "\n".join(lines) + "\n"


def _median_rows(runs: dict, **fields) -> list[dict]:
    """One row per ``(tree, threads, is_baseline)`` of ``runs``: its median process by seconds per
    step, with the number of processes, their range and ``fields``."""
    rows = []
    for (tree, _, is_baseline), rs in runs.items():
        times = sorted(q["s_per_step"] for q in rs)
        middle = sorted(rs, key=lambda q: q["s_per_step"])[(len(rs) - 1) // 2]
        rows.append(dict(middle, tree=tree, baseline=is_baseline, runs=len(rs),
                         s_per_step_range=[times[0], times[-1]], **fields))
    return rows


def run(*, threads: list[int] = (1, 2), scene: str = "ten-cate", level: int = 1, overrides: list[str] = (),
        warm: int = 1, steps: int = 2, repeats: int = 1, baseline: Path | None = None,
        baseline_name: str = "baseline", baseline_threads: list[int] = (), profile: bool = False,
        free_cores: bool = False, name: str = "", tag: str = "dev") -> None:
    """Time ``steps`` steps after ``warm`` ones at every thread count, for this tree and the
    baseline.

    Parameters
    ----------
    threads : Numba thread counts, one process each
    scene : the scene
    level : its level
    overrides : ``KEY=VALUE`` parameter overrides
    warm : steps taken before the timed ones
    steps : steps timed
    repeats : processes per tree and thread count, in turn (this tree, the baseline, this tree,
        ...), so that a drift of the machine's speed reaches both alike; a row gives the median
        process's figures (by seconds per step) and the range
    baseline : a ``src`` folder holding another version of the package, run at the same thread
        counts (none: this tree only)
    baseline_name : the baseline's name in the table (a commit)
    baseline_threads : the baseline's thread counts (none: those of ``threads``)
    name : this tree's name in the table (none: its git commit, "this tree" without git)
    profile : print the last timed step's profile (functions by own time) of every row (the
        profiler's overhead is in that step's time)
    free_cores : let multigrid take the cores other processes leave free (the package's default,
        :mod:`fbmflow.cores`; the reported threads are the last count); off, every step runs on
        the count asked for
    tag : this run's name in the results (rows with other tags are kept)
    """
    RESULTS.mkdir(exist_ok=True)
    path = RESULTS / "thread_scaling.json"
    kept = [r for r in json.loads(path.read_text()) if r["tag"] != tag] if path.exists() else []
    trees = [(SRC, name or commit(), threads, False)]
    if baseline:
        trees.append((Path(baseline).resolve(), baseline_name, baseline_threads or threads, True))
    where = machine()
    runs: dict = {}
    for _ in range(repeats):
        for k in sorted({k for _, _, counts, _ in trees for k in counts}, reverse=True):
            for tree, label, counts, is_baseline in trees:
                if k not in counts:
                    continue
                r = one(tree, k, scene, level, list(overrides), warm, steps, profile, free_cores)
                print(f"{label}, {k} threads: {r['s_per_step']:.2f} s per step "
                      f"({r['linear_s_per_step']:.2f} s linear, {r['cycles_per_step']:.1f} cycles), "
                      f"peak {r['peak_gb']:.2f} GB", flush=True)
                runs.setdefault((label, k, is_baseline), []).append(r)
                rows = _median_rows(runs, tag=tag, machine=where, scene=scene, level=level,
                                    free_cores=free_cores)
                path.write_text(json.dumps(kept + rows, indent=1))
                (RESULTS / "thread_scaling.md").write_text(table(kept + rows))
