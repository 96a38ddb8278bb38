"""Numba's threads kept to the free cores (:mod:`fbmflow.cores`)."""
import os

import numba
import pytest

from fbmflow import cores
from fbmflow.cores import FreeCores, busy_cpu_seconds, free_threads

STAT = """cpu  200 10 100 2000 40 6 4 14 0 0
cpu0 100 5 50 1000 20 3 2 7 0 0
cpu1 100 5 50 1000 20 3 2 7 0 0
intr 12345
"""


def test_busy_time_is_all_but_idle_and_waiting_from_the_cpus_lines():
    """The CPUs asked for, summed; None where one of them is missing (not this machine's file)."""
    tick = os.sysconf("SC_CLK_TCK")
    one = (100 + 5 + 50 + 3 + 2 + 7) / tick
    assert busy_cpu_seconds([1], STAT) == pytest.approx(one)
    assert busy_cpu_seconds([0, 1], STAT) == pytest.approx(2 * one)
    assert busy_cpu_seconds([2], STAT) is None
    assert busy_cpu_seconds([0], "") is None


@pytest.mark.parametrize("others, n_cpus, limit, want", [
    (0.0, 2, 2, 2), (0.4, 2, 2, 2), (0.6, 2, 2, 1), (1.0, 2, 2, 1), (3.0, 2, 2, 1),
    (1.5, 16, 16, 14), (0.0, 16, 4, 4), (15.2, 16, 16, 1)])
def test_free_threads_leave_the_cores_others_took(others, n_cpus, limit, want):
    """A core counts as taken from half of it on; never fewer than one thread, never more than
    the limit."""
    assert free_threads(others, n_cpus, limit) == want


def _two_cpus_seeing(monkeypatch, looks):
    """A FreeCores on two CPUs that sees ``looks`` (wall, busy, own) one after the other."""
    free = FreeCores()
    free.cpus = [0, 1]
    it = iter(looks)
    monkeypatch.setattr(free, "_look", lambda: next(it))
    monkeypatch.setattr(cores.time, "sleep", lambda s: None)
    return free


def test_adapt_follows_the_other_processes_and_keeps_the_callers_most(monkeypatch):
    """On two CPUs: another process busy on one core (1.0 of 1 s) -> one thread, kept until the
    next look; a window shorter than MIN_WINDOW_S keeps the last decision; the other stops -> two
    again; a count the caller sets afterwards becomes the most threads."""
    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("needs two Numba threads")
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(2)
        free = _two_cpus_seeing(monkeypatch, [(0.0, 0.0, 0.0), (1.0, 2.0, 1.0),  # others 1.0
                                              (1.1, 2.2, 1.1),  # too short: still 1.0
                                              (2.0, 3.0, 2.0),  # others 0.0
                                              (3.0, 4.0, 3.0)])  # others 0.0, the caller asks 1
        assert free.adapt() == 1 and numba.get_num_threads() == 1
        assert free.adapt() == 1
        assert free.adapt() == 2 and numba.get_num_threads() == 2
        numba.set_num_threads(1)
        assert free.adapt() == 1 and free.limit == 1
    finally:
        numba.set_num_threads(before)


def test_without_proc_stat_the_count_stays(monkeypatch):
    free = FreeCores()
    monkeypatch.setattr(free, "_look", lambda: None)
    assert free.adapt() == numba.get_num_threads()


def test_fixed_threads_leave_the_count_alone(monkeypatch):
    """``solver.multigrid.threads = "fixed"``: a set-up and solve never look."""
    from fbmflow.solvers.multigrid import MultigridSettings, _take_free_cores
    monkeypatch.setattr(cores.FREE_CORES, "threads", lambda limit: pytest.fail("looked"))
    _take_free_cores(MultigridSettings(threads="fixed"))
    with pytest.raises(pytest.fail.Exception, match="looked"):
        _take_free_cores(MultigridSettings(threads="free"))
