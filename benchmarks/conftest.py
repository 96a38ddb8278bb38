"""The benchmark suite: ``python -m pytest benchmarks`` (all), ``python -m pytest benchmarks -m
quick`` (coarse levels and short times, a few minutes on 2 cores).

``python -m pytest`` alone runs ``tests/`` only (``testpaths`` in pyproject.toml); the benchmarks
run when their folder is named. Each benchmark runs one configuration, asserts its accuracy
against the reference within a stated bound, merges its row into ``benchmarks/results/<name>.json``
and redraws that benchmark's tables and plots. The bound is taken from the measured result at
that configuration (:func:`fbmbench.common.bound`): a change of the numerics that makes the
result worse fails.

Every benchmark records what it measured with the ``bench`` fixture; the terminal summary lists
the figures and wall times, and ``benchmarks/results/suite.md`` / ``.json`` keep the latest
outcome of every benchmark with the date and commit.

Options: ``--bench-runs DIR`` (where the runs write their output, default ``out/bench``).
"""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent
os.environ.setdefault("NUMBA_CACHE_DIR", str(HERE.parent / ".numba_cache"))
sys.path.insert(0, str(HERE))


def pytest_addoption(parser):
    parser.addoption(
        "--bench-runs", default=None, help="output folder of the benchmark runs (default out/bench)"
    )


def pytest_configure(config):
    config.addinivalue_line(
        "markers", "quick: coarse levels and short times; `-m quick` runs in a few minutes on 2 cores"
    )
    if config.getoption("--bench-runs", None):
        os.environ["FBMFLOW_BENCH_RUNS"] = str(Path(config.getoption("--bench-runs")).resolve())
    _SESSION["start"] = time.time()


@pytest.fixture
def bench(request):
    """``bench(**figures)`` records what a benchmark measured (its run's wall time ``wall_s`` and
    its accuracy figures); they appear in the terminal summary, ``results/suite.md`` and JUnit
    XML."""

    def record(**figures):
        request.node.user_properties.extend(figures.items())

    return record


_SESSION: dict = {"rows": {}, "start": time.time()}


def pytest_runtest_logreport(report):
    if report.when == "call" or (report.when == "setup" and report.outcome != "passed"):
        _SESSION["rows"][report.nodeid] = {
            "test": report.nodeid,
            "outcome": report.outcome,
            "test_s": round(report.duration, 1),
            **dict(report.user_properties),
        }


def _fmt(value) -> str:
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    rows = list(_SESSION["rows"].values())
    if not rows:
        return
    total = time.time() - _SESSION["start"]
    terminalreporter.section("fbmflow benchmarks")
    for r in rows:
        figures = ", ".join(f"{k} {_fmt(v)}" for k, v in r.items() if k not in ("test", "outcome", "test_s"))
        terminalreporter.write_line(f"{r['outcome']:7s} {r['test_s']:8.1f} s  {r['test']}  {figures}")
    terminalreporter.write_line(
        f"session {total:.0f} s (wall times: the run itself; test_s adds the warm-up and process start)"
    )
    _write_suite(rows, total, config)


def _write_suite(rows, total, config) -> None:
    """Merge this session's outcomes into ``results/suite.json`` and redraw ``suite.md``."""
    from fbmbench.common import RESULTS, commit, provenance

    path = RESULTS / "suite.json"
    data = json.loads(path.read_text()) if path.is_file() else {"tests": {}, "sessions": []}
    stamp = provenance()
    for r in rows:
        data["tests"][r["test"]] = {**r, "date": stamp["date"], "commit": stamp["commit"]}
    selection = config.getoption("markexpr") or "all"
    if config.getoption("keyword"):
        selection += f", -k {config.getoption('keyword')}"
    data["sessions"] = (
        data["sessions"]
        + [
            {
                "date": stamp["date"],
                "commit": commit(),
                "selection": selection,
                "tests": len(rows),
                "failed": sum(r["outcome"] != "passed" for r in rows),
                "session_s": round(total),
            }
        ]
    )[-20:]
    RESULTS.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data, indent=1))
    lines = [
        "# Benchmark suite: latest outcome of each benchmark",
        "",
        "Written by `python -m pytest benchmarks` (benchmarks/conftest.py). 'test s': the test's time "
        "with its warm-up and process start; 'wall_s': the run itself. 2-core machine; runs niced beside "
        "other jobs are slower than alone.",
        "",
        "| benchmark | outcome | test s | figures | date | commit |",
        "|---|---|---|---|---|---|",
    ]
    for name, r in sorted(data["tests"].items()):
        figures = ", ".join(
            f"{k} {_fmt(v)}" for k, v in r.items() if k not in ("test", "outcome", "test_s", "date", "commit")
        )
        lines.append(
            f"| `{name}` | {r['outcome']} | {r['test_s']} | {figures} | {r['date']} | {r['commit']} |"
        )
    lines += [
        "",
        "## Sessions",
        "",
        "| date | commit | selection | tests | failed | session s |",
        "|---|---|---|---|---|---|",
    ]
    lines += [
        f"| {s['date']} | {s['commit']} | {s['selection']} | {s['tests']} | {s['failed']} | "
        f"{s['session_s']} |"
        for s in data["sessions"]
    ]
    (RESULTS / "suite.md").write_text("\n".join(lines) + "\n")
