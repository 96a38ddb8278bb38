"""Numba's threads kept to the cores that other processes leave free.

A parallel loop ends when its slowest thread does. Beside another busy process on a machine with
no spare core, one of the threads shares its core, and every parallel region of a multigrid
cycle (thousands per time step) waits for it: measured on 2 cores, a multigrid run slowed 1.64x
beside one busy process while a single-threaded direct solve did not slow at all
(docs/validation/multigrid-with-fictitious-boundaries.md, "Under load"). :class:`FreeCores`
reads how much CPU time the other processes took since its last look (``/proc/stat``'s busy
time of all CPUs less this process's own) and sets Numba's thread count to the cores they left,
at least one, at most the count in use when it first looked (or set by the user since). Results
do not depend on the count: every parallel kernel splits its work into the same groups whatever
the threads (:attr:`fbmflow.fem.space.FlowSpace.colour_groups`, :mod:`fbmflow.solvers.ordering`;
a test solves on one thread and on two). :class:`~fbmflow.solvers.multigrid.MultigridSolver`
calls :meth:`~fbmflow.cores.FreeCores.adapt` before every set-up and solve (``solver.multigrid.threads =
"free"``, the default; ``"fixed"`` leaves the count alone).
"""
from __future__ import annotations

import os
import time

from ._jit import numba_threads, set_threads

#: seconds between two looks below which the last decision stands (too short a window to tell)
MIN_WINDOW_S = 0.05
#: a core counts as taken when other processes used at least this share of one
TAKEN_SHARE = 0.5


def busy_cpu_seconds(stat: str | None = None) -> float | None:
    """Seconds all CPUs spent busy since boot, from the ``cpu`` line of ``/proc/stat`` (``stat``:
    its text, default read now): user, nice, system, irq, softirq and steal (time the hypervisor
    gave another machine); None where there is no such file (not Linux)."""
    if stat is None:
        try:
            with open("/proc/stat") as f:
                stat = f.readline()
        except OSError:
            return None
    fields = stat.split()
    if not fields or fields[0] != "cpu" or len(fields) < 9:
        return None
    user, nice, system, _idle, _iowait, irq, softirq, steal = (int(v) for v in fields[1:9])
    return (user + nice + system + irq + softirq + steal) / os.sysconf("SC_CLK_TCK")


def free_threads(others: float, n_cpus: int, limit: int) -> int:
    """Threads for ``n_cpus`` CPUs of which other processes took ``others`` (cores, e.g. 0.9):
    the cores they leave, counting a core as taken from :data:`TAKEN_SHARE` of it, at least 1 and
    at most ``limit``."""
    taken = int(others + 1.0 - TAKEN_SHARE)
    return max(1, min(limit, n_cpus - taken))


class FreeCores:
    """Numba's thread count set, at every :meth:`~fbmflow.cores.FreeCores.adapt`, to the cores
    other processes left free since the previous call (the first call looks for
    :data:`MIN_WINDOW_S`), at most the count found at the first call or set by anyone else since
    (``numba.set_num_threads`` keeps its meaning: the most threads). Without ``/proc/stat`` it
    leaves the count alone."""

    def __init__(self):
        self.n_cpus = os.cpu_count() or 1
        self.limit = None
        self._set = None
        self._last = None

    @staticmethod
    def _look() -> tuple[float, float, float] | None:
        busy = busy_cpu_seconds()
        return None if busy is None else (time.monotonic(), busy, time.process_time())

    @staticmethod
    def others(before: tuple[float, float, float], now: tuple[float, float, float]) -> float:
        """Cores the other processes used on average between two looks ``(wall, busy, own)``
        (seconds since any fixed instant: monotonic wall time, all CPUs' busy time, this
        process's CPU time)."""
        return max(0.0, (now[1] - before[1]) - (now[2] - before[2])) / (now[0] - before[0])

    def adapt(self) -> int:
        """Set Numba's thread count to the cores left free since the last call; returns it."""
        current = numba_threads()
        if self.limit is None or current != self._set:
            self.limit = self._set = current
        if self._last is None:
            self._last = self._look()
            if self._last is None:
                return current
            time.sleep(MIN_WINDOW_S)
        now = self._look()
        if now is None or now[0] - self._last[0] < MIN_WINDOW_S:
            return current
        threads = free_threads(self.others(self._last, now), self.n_cpus, self.limit)
        self._last = now
        if threads != current:
            set_threads(threads)
        self._set = threads
        return threads


#: the process's one instance (its looks are the process's own)
FREE_CORES = FreeCores()
