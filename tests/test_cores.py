"""Numba's threads kept to the free cores (:mod:`fbmflow.cores`)."""
import os

import numba
import pytest

from fbmflow import cores
from fbmflow.cores import FreeCores, busy_cpu_seconds, free_threads


def test_busy_time_is_all_but_idle_and_waiting_from_the_cpu_line():
    tick = os.sysconf("SC_CLK_TCK")
    line = "cpu  100 5 50 1000 20 3 2 7 0 0\n"
    assert busy_cpu_seconds(line) == pytest.approx((100 + 5 + 50 + 3 + 2 + 7) / tick)
    assert busy_cpu_seconds("cpu0 1 2 3 4 5 6 7 8") is None
    assert busy_cpu_seconds("") is None


@pytest.mark.parametrize("others, n_cpus, limit, want", [
    (0.0, 2, 2, 2), (0.4, 2, 2, 2), (0.6, 2, 2, 1), (1.0, 2, 2, 1), (3.0, 2, 2, 1),
    (1.5, 16, 16, 14), (0.0, 16, 4, 4), (15.2, 16, 16, 1)])
def test_free_threads_leave_the_cores_others_took(others, n_cpus, limit, want):
    """A core counts as taken from half of it on; never fewer than one thread, never more than
    the limit."""
    assert free_threads(others, n_cpus, limit) == want


def _looks(monkeypatch, values):
    """Let FreeCores see ``values`` (wall, busy, own) one after the other."""
    it = iter(values)
    monkeypatch.setattr(FreeCores, "_look", staticmethod(lambda: next(it)))
    monkeypatch.setattr(cores.time, "sleep", lambda s: None)


def test_adapt_follows_the_other_processes_and_keeps_the_users_limit(monkeypatch):
    """On two CPUs: another process busy on one core (1.0 of 1 s) -> one thread; it stops -> two
    again; a count set by the user meanwhile becomes the most threads; a window shorter than
    MIN_WINDOW_S changes nothing."""
    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("needs two Numba threads")
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(2)
        free = FreeCores()
        free.n_cpus = 2
        _looks(monkeypatch, [(0.0, 0.0, 0.0), (1.0, 2.0, 1.0),  # first call: others 1.0
                             (2.0, 3.0, 2.0),  # others 0.0
                             (2.01, 3.02, 2.01),  # too short a window
                             (3.0, 4.0, 3.0)])  # others 0.0, but the user asked for one thread
        assert free.adapt() == 1 and numba.get_num_threads() == 1
        assert free.adapt() == 2 and numba.get_num_threads() == 2
        assert free.adapt() == 2
        numba.set_num_threads(1)
        assert free.adapt() == 1 and free.limit == 1
    finally:
        numba.set_num_threads(before)


def test_without_proc_stat_the_count_stays(monkeypatch):
    monkeypatch.setattr(FreeCores, "_look", staticmethod(lambda: None))
    assert FreeCores().adapt() == numba.get_num_threads()
