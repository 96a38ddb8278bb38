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


__all__ = ["njit", "prange", "numba_threads"]
