"""The one place that imports Numba.

``njit`` is :func:`numba.njit` with ``cache=True`` so that a second process loads compiled
kernels from disk (set ``NUMBA_CACHE_DIR`` to share the cache between CI runs). ``prange`` is
re-exported so kernels never import numba themselves. ``jitable`` marks a helper that CPU
kernels and GPU kernels (:mod:`fbmflow.gpu`, numba-cuda) both call: one body for both targets,
inlined into the CPU's callers, compiled as a CUDA device function from a copy for the GPU's
(:data:`JITABLE`); it must take every scratch array from its caller and allocate nothing.
"""
from functools import partial

import numba

njit = partial(numba.njit, cache=True)
prange = numba.prange


#: every function marked :func:`jitable`, with its jit options: the GPU's kernels compile copies
#: of them (:func:`fbmflow.gpu._kernels.device_copy`), never these objects, whose overloads the
#: CPU's kernels inline into their IR
JITABLE: dict = {}


def jitable(function=None, *, inline: bool = True, **options):
    """``function`` callable from CPU and GPU kernels alike (:func:`numba.extending.register_jitable`):
    inlined into each caller's code (``inline``: a called helper measured 5-10 % slower per
    cell than the same code written in its kernel), or compiled once as a function of its own
    with the jit ``options`` (e.g. ``fastmath=True``) and called, where several call sites would
    each compile a copy of a large body (the Vanka sweep's patch and row products, inlined with
    fastmath throughout: a cold process compiled 1.5 times as long). Used bare (``@jitable``) or
    with arguments."""
    if function is None:
        return partial(jitable, inline=inline, **options)
    JITABLE[function] = options
    if inline:
        return numba.extending.register_jitable(inline="always")(function)
    if not options:
        return numba.extending.register_jitable(function)
    return numba.extending.register_jitable(**options)(function)


float64 = numba.float64


def cuda_target():
    """Numba's CUDA target (:mod:`numba.cuda`, numba-cuda's where installed), imported on first
    use: only :mod:`fbmflow.gpu` asks for it, so the core never loads CUDA. Under
    ``NUMBA_ENABLE_CUDASIM=1`` it is Numba's simulator, which runs the kernels on the CPU."""
    import numba.cuda

    return numba.cuda


def cuda_simulated() -> bool:
    """Whether Numba's CUDA target is its simulator (``NUMBA_ENABLE_CUDASIM=1``)."""
    return bool(numba.config.ENABLE_CUDASIM)


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


__all__ = ["njit", "prange", "jitable", "JITABLE", "float64", "cuda_target", "cuda_simulated",
           "numba_threads", "max_threads", "set_threads"]
