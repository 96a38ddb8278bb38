"""Numba's threads kept to the cores that other processes leave free.

A parallel loop ends when its slowest thread does. Beside another busy process on a machine with
no spare core, one of the threads shares its core, and every parallel region of a multigrid
cycle (thousands per time step) waits for it: measured on 2 cores, a multigrid run slowed 1.64x
beside one busy process while a single-threaded direct solve did not slow at all
(docs/validation/multigrid-with-fictitious-boundaries.md, "Under load"). :class:`FreeCores`
reads how much CPU time the other processes took since its last look (``/proc/stat``'s busy
time of the CPUs this process may run on, less its own) and sets Numba's thread count to the
cores they left, at least one, at most the count in use at its first look (or set by the user
since). Results do not depend on the count: every parallel kernel splits its work into the same
groups whatever the threads (:attr:`fbmflow.fem.space.FlowSpace.colour_groups`,
:mod:`fbmflow.solvers.ordering`; a test solves on one thread and on two).
:class:`~fbmflow.solvers.multigrid.MultigridSolver` calls :meth:`~fbmflow.cores.FreeCores.adapt`
before every set-up and solve (``solver.multigrid.threads = "free"``, the default; ``"fixed"``
leaves the count alone); the count stays until the next call, so that the work between solves
(assembly, residuals) runs on the free cores too: restoring it after each solve made a
``cavity-2d`` run beside a busy process 1.51 times slower than alone, against 1.13-1.27 times.
"""
from __future__ import annotations

import os
import time

from ._jit import numba_threads, set_threads

#: seconds between two looks below which the last decision stands (``/proc/stat`` counts in ticks
#: of 10 ms per CPU: a shorter window would misread a fifth of a core)
MIN_WINDOW_S = 0.25
#: a core counts as taken when other processes used at least this share of one
TAKEN_SHARE = 0.5


def usable_cpus() -> list[int]:
    """The CPUs this process may run on (its affinity: taskset, Slurm, a container's cpuset),
    sorted; all of ``os.cpu_count()`` where the platform does not say."""
    try:
        return sorted(os.sched_getaffinity(0))
    except AttributeError:
        return list(range(os.cpu_count() or 1))


def busy_cpu_seconds(cpus: list[int], stat: str | None = None) -> float | None:
    """Seconds the CPUs ``cpus`` spent busy since boot, from their ``cpuN`` lines of
    ``/proc/stat`` (``stat``: its text, default read now): user, nice, system, irq, softirq and
    steal (time the hypervisor gave another machine); None where there is no such file (not
    Linux) or it lacks one of them."""
    if stat is None:
        try:
            with open("/proc/stat") as f:
                stat = f.read()
        except OSError:
            return None
    wanted, total, found = {f"cpu{c}" for c in cpus}, 0, 0
    for line in stat.splitlines():
        fields = line.split()
        if fields and fields[0] in wanted and len(fields) >= 9:
            user, nice, system, _idle, _iowait, irq, softirq, steal = (int(v) for v in fields[1:9])
            total += user + nice + system + irq + softirq + steal
            found += 1
    return total / os.sysconf("SC_CLK_TCK") if found == len(wanted) else None


def free_threads(others: float, n_cpus: int, limit: int) -> int:
    """Threads for ``n_cpus`` CPUs of which other processes took ``others`` (cores, e.g. 0.9):
    the cores they leave, counting a core as taken from :data:`TAKEN_SHARE` of it, at least 1 and
    at most ``limit``."""
    taken = int(others + 1.0 - TAKEN_SHARE)
    return max(1, min(limit, n_cpus - taken))


class FreeCores:
    """Looks at what other processes take of this process's CPUs, and sets Numba's threads to
    the rest (:meth:`~fbmflow.cores.FreeCores.adapt`). The decision follows the load since the
    previous look, at least :data:`MIN_WINDOW_S` back (the first look waits that long); without
    ``/proc/stat`` the count stays as it is."""

    def __init__(self):
        self.cpus = usable_cpus()
        self.limit = None
        self._set = None
        self._last = None
        self._others = 0.0

    def _look(self) -> tuple[float, float, float] | None:
        busy = busy_cpu_seconds(self.cpus)
        return None if busy is None else (time.monotonic(), busy, time.process_time())

    @staticmethod
    def others(before: tuple[float, float, float], now: tuple[float, float, float]) -> float:
        """Cores the other processes used on average between two looks ``(wall, busy, own)``
        (seconds since any fixed instant: monotonic wall time, the CPUs' busy time, this
        process's CPU time)."""
        return max(0.0, (now[1] - before[1]) - (now[2] - before[2])) / (now[0] - before[0])

    def threads(self, limit: int) -> int:
        """The threads to use now, at most ``limit``: the cores the other processes left since
        the last look (the last decision where that was less than :data:`MIN_WINDOW_S` ago)."""
        if self._last is None:
            self._last = self._look()
            if self._last is None:
                return limit
            time.sleep(MIN_WINDOW_S)
        now = self._look()
        if now is not None and now[0] - self._last[0] >= MIN_WINDOW_S:
            self._others = self.others(self._last, now)
            self._last = now
        return free_threads(self._others, len(self.cpus), limit)

    def adapt(self) -> int:
        """Set Numba's thread count for this process to the free cores
        (:meth:`~fbmflow.cores.FreeCores.threads`), at most the count found at the first call or
        set by anyone else since (a count other than the one this method set last); returns it.
        The count stays until the next call, so that the work between two multigrid solves
        (assembly, residuals) runs on the free cores too."""
        current = numba_threads()
        if self.limit is None or current != self._set:
            self.limit = current
        threads = self.threads(self.limit)
        if threads != current:
            set_threads(threads)
        self._set = threads
        return threads


#: the process's one instance (its looks are the process's own)
FREE_CORES = FreeCores()
