"""What every benchmark needs: running a scene through the command line, the JIT warm-up,
the results files and the speed-against-accuracy plot.

A scene runs in a child process, ``python -m fbmflow.cli run SCENE --level L --set KEY=VALUE
--out DIR``, which writes ``DIR/summary.json`` (resolved parameters, unknowns, steps, Newton
iterations, the linear solver, the wall time of the run itself and the scene's ``quantities``).
The wall time is the run's, without the Python start-up and without the time the process was
stopped by other jobs (:func:`monitored`); the Numba kernels come from the cache that
:func:`warm_up` fills first, so it excludes the JIT compilation as the old scripts did.

Results: ``benchmarks/results/<name>.json`` holds a list of rows, one per configuration; a new
run replaces the row of its configuration and keeps the others (runs measured earlier, by other
commands or sessions), and the tables and plots are redrawn from all rows.
"""

from __future__ import annotations

import functools
import hashlib
import json
import math
import os
import resource
import subprocess
import sys
import time
from datetime import date
from pathlib import Path

BENCHMARKS = Path(__file__).resolve().parents[1]
ROOT = BENCHMARKS.parent
RESULTS = Path(os.environ.get("FBMFLOW_BENCH_RESULTS", BENCHMARKS / "results"))
RUNS = Path(os.environ.get("FBMFLOW_BENCH_RUNS", ROOT / "out" / "bench"))


def bound(measured: float) -> float:
    """The bound that a benchmark asserts for a relative error whose measured value is
    ``measured``: 1.1 |measured| + 0.001, rounded up to 0.001 (0.1 percentage point). The runs are
    deterministic to far better than that; the margin absorbs solver tolerances, not regressions."""
    return math.ceil(round((1.1 * abs(measured) + 0.001) * 1000, 6)) / 1000


class RunFailed(RuntimeError):
    """A scene run that exited with a non-zero status."""


def parse_settings(items: list[str]) -> dict:
    """``KEY=VALUE`` items (a benchmark's ``--set``) as a settings dict, each value read as JSON
    (numbers, true/false) or kept as a word."""
    settings = dict(item.split("=", 1) for item in items)
    for key, value in settings.items():
        try:
            settings[key] = json.loads(value)
        except json.JSONDecodeError:  # a word: keep the string
            pass
    return settings


def cli_value(value) -> str:
    """``value`` as the command line's ``--set KEY=VALUE`` parses it back."""
    if isinstance(value, bool):
        return "true" if value else "false"
    return repr(value) if isinstance(value, float) else str(value)


def slug(scene: str, level: int, settings: dict) -> str:
    """A folder name for one run: scene, level and the settings in order; past 200 characters
    (file systems allow 255) the settings' part is cut and a hash of the whole name added."""
    parts = [scene, f"level{level}"] + [f"{k}={cli_value(v)}" for k, v in sorted(settings.items())]
    name = "-".join(p.replace("/", "_") for p in parts)
    if len(name) <= 200:
        return name
    return f"{name[:183]}-{hashlib.sha1(name.encode()).hexdigest()[:16]}"


def monitored(cmd: list[str], record=None) -> tuple[int, list[list[float]], float]:
    """Run ``cmd`` and return its exit status, the intervals ``[t0, t1]`` (epoch seconds) in
    which it was stopped (state T: another job's timing run can SIGSTOP the others on this
    shared machine; seen in the child's state, or as a gap in this process's own looks) and its
    CPU time (user + system, start-up included: on a machine shared
    with other jobs a better measure of the work than the wall time). ``record(intervals)`` is
    called every 30 s and at the end."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    proc = subprocess.Popen(cmd, cwd=ROOT)
    stat = Path(f"/proc/{proc.pid}/stat")
    intervals: list[list[float]] = []
    last_save = time.time()
    prev = None  # (time, stopped) of the last look
    while proc.poll() is None:
        now = time.time()
        try:
            stopped = stat.read_text().rsplit(")", 1)[1].split()[0] in "Tt"
        except (OSError, IndexError):
            stopped = False
        # Whoever stops the child stops this process too (both niced): a gap of more than 2 s
        # between its looks, 0.25 s apart, counts as stopped as well.
        if prev is not None and (stopped and prev[1] or now - prev[0] > 2.0):
            if intervals and prev[0] - intervals[-1][1] < 1.0:
                intervals[-1][1] = now
            else:
                intervals.append([prev[0], now])
        prev = (now, stopped)
        if record is not None and now - last_save > 30:
            record(intervals)
            last_save = now
        time.sleep(0.25)
    if record is not None:
        record(intervals)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return proc.returncode, intervals, cpu


def overlap(intervals: list[list[float]], start: float, end: float) -> float:
    """Seconds of ``intervals`` within ``[start, end]``."""
    return sum(max(0.0, min(b, end) - max(a, start)) for a, b in intervals)


def run_scene(
    scene: str, level: int, settings: dict | None = None, out: Path | None = None, checkpoint_every: int = 0
) -> dict:
    """Run ``scene`` at ``level`` with the ``settings`` (``{"time.dt": 0.004, ...}``) and return
    its ``summary.json`` with ``wall_s`` added: the run's wall time less the time its process was
    stopped by other jobs (``stopped_s``, see :func:`monitored`); ``cpu_s`` is the process's CPU
    time (pieces of an interrupted run that were not waited for count none).

    With ``checkpoint_every > 0`` the run checkpoints into ``out`` and a later call with the same
    arguments continues it (``fbmflow resume``) when it was interrupted: a long run can span
    sessions. ``wall_s`` then sums the pieces, each counted to its last checkpoint (the
    checkpoint file's time) or to its end. A finished run in ``out`` is run again.
    """
    settings = dict(settings or {})
    out = Path(out) if out is not None else RUNS / slug(scene, level, settings)
    out.mkdir(parents=True, exist_ok=True)
    pieces_file = out / "bench-pieces.json"
    summary_file = out / "summary.json"
    resumable = (
        checkpoint_every > 0
        and (out / "checkpoint.h5").is_file()
        and (out / "run.json").is_file()
        and not summary_file.is_file()
        and pieces_file.is_file()
    )
    pieces = json.loads(pieces_file.read_text()) if resumable else []
    if resumable and pieces and "wall_s" not in pieces[-1]:  # the piece that stopped: to its checkpoint
        last, end = pieces[-1], (out / "checkpoint.h5").stat().st_mtime
        last["stopped_s"] = overlap(last.get("stopped", []), last["start"], end)
        last["wall_s"] = max(0.0, end - last["start"] - last["stopped_s"])
    summary_file.unlink(missing_ok=True)
    if resumable:
        args = ["resume", str(out), "--no-plot"]
    else:
        # the harness owns its run folders: a finished run of the same configuration is replaced
        args = ["run", scene, "--level", str(level), "--out", str(out), "--no-plot", "--overwrite"]
        args += [a for k, v in settings.items() for a in ("--set", f"{k}={cli_value(v)}")]
        if checkpoint_every:
            args += ["--checkpoint-every", str(checkpoint_every)]
    piece = {"start": time.time(), "command": "fbmflow " + " ".join(args), "stopped": []}
    pieces.append(piece)

    def save(intervals):
        piece["stopped"] = intervals
        pieces_file.write_text(json.dumps(pieces, indent=1))

    save([])
    status, intervals, cpu = monitored([sys.executable, "-m", "fbmflow.cli", *args], save)
    piece["cpu_s"] = cpu
    if status != 0 or not summary_file.is_file():
        raise RunFailed(f"fbmflow {' '.join(args)} exited with status {status}")
    summary = json.loads(summary_file.read_text())
    end = summary_file.stat().st_mtime
    piece["stopped_s"] = overlap(intervals, end - summary["wall_time_s"], end)
    piece["wall_s"] = summary["wall_time_s"] - piece["stopped_s"]
    save(intervals)
    summary["wall_s"] = sum(p["wall_s"] for p in pieces)
    summary["stopped_s"] = sum(p.get("stopped_s", 0.0) for p in pieces)
    summary["cpu_s"] = sum(p.get("cpu_s", 0.0) for p in pieces)
    summary["pieces"] = len(pieces)
    return summary


@functools.lru_cache(maxsize=None)
def _warm(scene: str, level: int, items: tuple) -> None:
    run_scene(scene, level, dict(items), out=RUNS / f"warm-up-{scene}")


def warm_up(scene: str, level: int = 0, **settings) -> None:
    """Run a tiny case of ``scene`` once per process, so that the Numba cache holds its kernels
    and the timed runs after it exclude the JIT compilation."""
    _warm(scene, level, tuple(sorted(settings.items())))


def commit() -> str:
    """The last commit that changed ``src/`` (``+`` when ``src/`` has changes since), or
    ``FBMFLOW_BENCH_COMMIT`` when set (for runs of a source snapshot outside the repository)."""
    if os.environ.get("FBMFLOW_BENCH_COMMIT"):
        return os.environ["FBMFLOW_BENCH_COMMIT"]
    try:
        head = subprocess.run(
            ["git", "log", "-1", "--format=%h", "--", "src"],
            cwd=ROOT,
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no", "src"],
            cwd=ROOT,
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return ""
    return head + ("+" if dirty else "")


def provenance() -> dict:
    """What a new row records about where it was measured."""
    return {"date": date.today().isoformat(), "commit": commit(), "cpus": os.cpu_count()}


def load_rows(name: str) -> list[dict]:
    path = RESULTS / f"{name}.json"
    return json.loads(path.read_text()) if path.is_file() else []


def save_rows(name: str, rows: list[dict]) -> None:
    RESULTS.mkdir(parents=True, exist_ok=True)
    path = RESULTS / f"{name}.json"
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(rows))
    os.replace(tmp, path)


def merge_row(name: str, row: dict, same) -> list[dict]:
    """Put ``row`` into ``results/<name>.json`` in place of the rows ``same(old, row)`` holds for;
    returns all rows. The file is read again just before writing: runs that another process
    recorded meanwhile stay."""
    rows = [r for r in load_rows(name) if not same(r, row)] + [row]
    save_rows(name, rows)
    return rows


def write_text(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)


def cpu(row: dict) -> str:
    """A row's CPU time for the tables ("" for rows measured before it was recorded)."""
    return f"{row['cpu_s']:.0f}" if "cpu_s" in row else ""


def percent(value, spec: str = "+.2f") -> str:
    return "–" if value is None else f"{100 * value:{spec}} %"


def tradeoff_plot(path: Path, curves: dict, ylabel: str, title: str) -> None:
    """Error against wall time, one line per ``curves[label] = [(wall_s, |error|, point label)]``
    (points in order of refinement), both axes logarithmic."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4.2))
    for k, (label, points) in enumerate(curves.items()):
        points = [p for p in points if p[0] > 0 and p[1] is not None and p[1] > 0]
        if not points:
            continue
        ax.loglog([p[0] for p in points], [p[1] for p in points], "o-", color=f"C{k % 10}", label=label)
        for wall, err, text in points:
            ax.annotate(text, (wall, err), textcoords="offset points", xytext=(4, 4), fontsize=7)
    ax.set_xlabel("wall time per run [s] (2-core machine)")
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=8.5)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.16), frameon=False)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
