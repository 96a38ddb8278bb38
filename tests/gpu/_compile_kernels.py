"""Run with the ``gpu`` extra's numba-cuda and its NVVM, no GPU needed: ``python
_compile_kernels.py TYPES.json`` compiles every GPU kernel (:mod:`fbmflow.gpu._kernels`) for every
list of argument types in ``TYPES.json`` (:file:`_kernel_types.py`) to PTX for compute capability
9.0 (the lent H100/H200's), as a GPU would compile it at its first launch: what Numba's CUDA
simulator, which runs the kernels as Python, cannot check (the kernels' typing and lowering for the
CUDA target). A kernel that synchronises its grid (a cooperative launch) calls the CUDA device
runtime, which a GPU links in at the first launch: it is linked here too, with nvJitLink, to a
cubin. Prints one line per kernel and type list; exits 1 where one fails, 3 where NVVM is
missing (no CUDA toolkit: ``pip install "numba-cuda[cu12]"``)."""
import json
import sys
import time
import types as pytypes

import numba.cuda.dispatcher
from numba import cuda, types

CC = (9, 0)
# a device function's compilation asks the current device for its compute capability: there is no
# GPU here, so it answers the lent one's (a numba-cuda internal; the kernels themselves get CC)
numba.cuda.dispatcher.get_current_device = lambda: pytypes.SimpleNamespace(compute_capability=CC)

try:
    cuda.compile_ptx(lambda a: None, (types.float64[::1],), cc=CC)
except Exception as err:  # no NVVM: the CUDA toolkit's compiler is not installed
    print(f"cannot compile for CUDA here: {type(err).__name__}: {err}")
    sys.exit(3)

import fbmflow.gpu._kernels as kernels  # noqa: E402


def link(ptx: str) -> int:
    """Bytes of the cubin that nvJitLink links from ``ptx`` and the CUDA device runtime
    (``libcudadevrt.a``, which numba-cuda links for a kernel that synchronises its grid)."""
    from cuda.bindings import nvjitlink
    from numba.cuda.cudadrv.libs import get_cudalib

    handle = nvjitlink.create(1, [f"-arch=sm_{CC[0]}{CC[1]}"])
    try:
        nvjitlink.add_data(handle, nvjitlink.InputType.PTX, ptx.encode(), len(ptx), "kernel.ptx")
        nvjitlink.add_file(handle, nvjitlink.InputType.LIBRARY, get_cudalib("cudadevrt", static=True))
        nvjitlink.complete(handle)
        return nvjitlink.get_linked_cubin_size(handle)
    finally:
        nvjitlink.destroy(handle)


namespace = dict(vars(types), bool=types.boolean)
failed = 0
for name, signatures in json.loads(open(sys.argv[1]).read()).items():
    for signature in signatures:
        args = tuple(eval(t, namespace) for t in signature)  # Numba's own repr of each type
        t0 = time.perf_counter()
        try:
            ptx, _ = cuda.compile_ptx(getattr(kernels, name).py_func, args, cc=CC)
            cubin = link(ptx) if "cudaCG" in ptx else 0  # the grid's synchronisation
            linked = f", linked with the device runtime: {cubin} bytes of cubin" if cubin else ""
            print(f"{name}: {len(ptx)} characters of PTX in {time.perf_counter() - t0:.1f} s{linked}",
                  flush=True)
        except Exception as err:
            failed += 1
            print(f"{name} {signature}: FAILED {type(err).__name__}: {str(err)[:4000]}", flush=True)
sys.exit(1 if failed else 0)
