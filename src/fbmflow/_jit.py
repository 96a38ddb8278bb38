"""The one place that imports Numba.

``njit`` is :func:`numba.njit` with ``cache=True`` so that a second process loads compiled
kernels from disk (set ``NUMBA_CACHE_DIR`` to share the cache between CI runs). ``prange`` is
re-exported so kernels never import numba themselves.
"""
from functools import partial

import numba

njit = partial(numba.njit, cache=True)
prange = numba.prange


def numba_threads() -> int:
    """Number of threads Numba's parallel loops use."""
    return numba.get_num_threads()


def max_threads() -> int:
    """The most threads Numba's parallel loops may use in this process (``NUMBA_NUM_THREADS``
    when it started)."""
    return numba.config.NUMBA_NUM_THREADS


def set_threads(n: int) -> None:
    """Let Numba's parallel loops use ``n`` threads (1 to :func:`max_threads`) from now on."""
    numba.set_num_threads(n)


__all__ = ["njit", "prange", "numba_threads", "max_threads", "set_threads"]
