"""Where the GPU solver's arrays live (:class:`~fbmflow.gpu.device.Backend`): CuPy's arrays and sparse
matrices on an NVIDIA GPU, or NumPy's and SciPy's under Numba's CUDA simulator, where the numba-cuda
kernels run on the CPU (``NUMBA_ENABLE_CUDASIM=1``: how the tests check the GPU path on a machine
without one). :func:`gpu_problem` says, before any work, why ``solver.device = "gpu"`` cannot run
here."""
from __future__ import annotations

import contextlib
import importlib.util
import sys

import numpy as np
import scipy.sparse as sp

from ..kept import KeptByIdentity
from ..solvers.newton import ConvergenceError


class DeviceMemoryError(ConvergenceError):
    """The GPU ran out of memory during a run (past the check before the first step): the run
    stops as a failed step does, keeping its last good state, and a shorter time step is not
    tried (it needs as much memory)."""

    retry = False


class Backend:
    """The array module ``xp`` (``cupy`` or ``numpy``) and sparse module (``cupyx.scipy.sparse`` or
    ``scipy.sparse``) of a device solver, the moves between host and device, and the threads per
    block of the kernels' launches (the simulator runs a Python thread for each, idle or not)."""

    def __init__(self, xp, sparse, name: str, threads: int, lanes: int = 1,
                 out_of_memory: type = MemoryError):
        self.xp, self.sparse, self.name, self.threads = xp, sparse, name, threads
        if threads % lanes:
            raise ValueError(f"the threads per block ({threads}) must be a multiple of the lanes ({lanes})")
        #: threads that share one smoother patch (its residual's rows and its update): a warp on a GPU
        self.lanes = lanes
        #: the exception the array module raises when the device's memory runs out
        self.out_of_memory = out_of_memory
        #: device copies of host objects that nothing writes to, by the host object's identity
        #: and what was made of it (:meth:`kept`)
        self._kept = KeptByIdentity()

    def put(self, a, dtype=None):
        """A host array (or scalar sequence) as a contiguous device array: a copy, also under the
        simulator, so that host and device arrays never alias, as on a GPU."""
        return self.xp.array(np.ascontiguousarray(a, dtype=dtype))

    def kept(self, host, what: str, build):
        """``build(host)``: a device copy of the host object ``host``, made at the first call for
        ``host`` and ``what`` and kept while ``host`` lives. For what nothing writes to and many
        set-ups read (a level's divergence and transfers, a space's cells): copied once, not
        again by every set-up. ``what`` names what ``build`` makes of it."""
        return self._kept.get(host, what, build)

    def get(self, a) -> np.ndarray:
        """A device array back on the host (a copy)."""
        return a.get() if hasattr(a, "get") else np.array(a)

    def csr(self, M):
        """A host sparse matrix as the device's CSR matrix (int32 indices: CuPy's kernels take
        no others)."""
        M = sp.csr_matrix(M)
        return self.sparse.csr_matrix((self.put(M.data), self.put(M.indices, np.int32),
                                       self.put(M.indptr, np.int32)), shape=M.shape)

    def synchronize(self) -> None:
        """Wait for the device's kernels to finish (for timing; nothing on the host)."""
        if self.name == "cupy":
            self.xp.cuda.Device().synchronize()

    @contextlib.contextmanager
    def memory_guard(self, what: str):
        """Turn the device's running out of memory while doing ``what`` into a
        :class:`DeviceMemoryError` that says so and names the remedies."""
        try:
            yield
        except self.out_of_memory as err:
            free = self.free_bytes()
            now = "" if free is None else f"; {free / 1e9:.1f} GB free now"
            remedy = "use a coarser mesh (a lower --level), or solver.device = 'cpu'"
            raise DeviceMemoryError(f"the GPU ran out of memory {what} ({err}{now})", remedy) from None

    def free_bytes(self) -> int | None:
        """The device memory free now [bytes], None where the arrays live on the host."""
        if self.name != "cupy":
            return None
        free, _ = self.xp.cuda.runtime.memGetInfo()
        return int(free)


def nbytes(*held) -> int:
    """The device memory of arrays, sparse matrices (their three arrays), objects with an
    ``nbytes`` and tuples of these [bytes]; None counts nothing."""
    total = 0
    for a in held:
        if isinstance(a, tuple):
            total += nbytes(*a)
        elif hasattr(a, "indptr"):
            total += int(a.data.nbytes + a.indices.nbytes + a.indptr.nbytes)
        elif a is not None:
            total += int(a.nbytes)
    return total


def launch_view(a):
    """``a`` as a kernel launch takes it with the least host work: a CuPy array as numba-cuda's
    device array over the same memory (:func:`numba.cuda.as_cuda_array`: no copy, and it keeps
    ``a`` alive), anything else as it is.

    numba-cuda makes such a device array of every CUDA-array-interface argument (CuPy's) at every
    launch and, as version 3 of the interface asks by default, synchronises the stream the array
    names (CuPy's legacy default stream): a Vanka sweep's launch, with 31 arrays, waited for the GPU
    to finish all it had been given (and synchronised 30 times more), so that the host's preparation
    of a launch never overlapped the GPU's work. The view here is made without that synchronisation
    (``sync=False``): CuPy's operations and numba-cuda's launches both go to the legacy default
    stream (fbmflow sets no other), which runs them in the order given. A view made once, where the
    arrays are set up, passes a launch as numba-cuda's own arrays do: numba-cuda's maintainers
    measured arrays passed through the interface 3-7 times slower to pass (numba-cuda pull request
    539, issue 578)."""
    cupy = sys.modules.get("cupy")
    if cupy is not None and isinstance(a, cupy.ndarray):
        from .._jit import cuda_target

        return cuda_target().as_cuda_array(a, sync=False)
    return a


def launch_views(*args) -> tuple:
    """:func:`launch_view` of each of ``args``."""
    return tuple(launch_view(a) for a in args)


def gpu_backend() -> Backend:
    """CuPy's backend (the ``gpu`` extra; :func:`gpu_problem` first says whether it can run)."""
    import cupy
    import cupyx.scipy.sparse

    return Backend(cupy, cupyx.scipy.sparse, "cupy", 128, 32, cupy.cuda.memory.OutOfMemoryError)


def simulated_backend() -> Backend:
    """NumPy and SciPy, for numba-cuda kernels under Numba's CUDA simulator (tests)."""
    return Backend(np, sp, "numpy", 1)


def gpu_problem() -> str | None:
    """Why the GPU solver cannot run in this process, in words that name the fix, or None where
    it can: the ``gpu`` extra missing, or no CUDA device or driver. Imports CUDA only where the
    extra is installed."""
    missing = [name for name in ("cupy", "numba") if importlib.util.find_spec(name) is None]
    if missing:
        return (f"solver.device = 'gpu' needs the gpu extra ({', '.join(missing)} not installed): "
                "pip install -e '.[gpu]' on a machine with an NVIDIA GPU, or set solver.device = 'cpu'")
    from .._jit import cuda_target

    cuda = cuda_target()
    try:
        available = cuda.is_available()
    except Exception:  # a broken driver raises instead of saying False
        available = False
    if not available:
        return ("solver.device = 'gpu' found no CUDA GPU (numba.cuda.is_available() is False: no device, or "
                "no NVIDIA driver); run on a machine with one, or set solver.device = 'cpu'")
    return None
