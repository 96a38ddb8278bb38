"""Run with ``NUMBA_ENABLE_CUDASIM=1`` (or without it on a GPU with the ``gpu`` extra: CuPy's arrays,
benchmarks/device/gpu.sh): the GPU's Vanka smoother (:class:`fbmflow.gpu.vanka.DeviceVanka`,
its local factors computed on the device, then its sweeps, a sweep's colours in one cooperative
launch, and one launch per colour, one or several threads per patch)
under Numba's CUDA simulator against the CPU's factored smoother: the same factors, and the same
sweeps in the same colour order, symmetric sweeps (forwards, then backwards): a 2D box with a
sharp-boundary disk (far patches, agglomerated patches, interface sweeps) and a 3D box with a
convecting flow, its Newton system (LU patches) and its Picard one (Schur patches); factors in
single precision. Prints one line per case; exits 1 on a mismatch."""
import os
import sys
import time
from pathlib import Path

import numpy as np
from numba import cuda

sys.path.insert(0, str(Path(__file__).parents[1]))
from sharp_disk import sharp_disk_problem  # noqa: E402

from fbmflow.flow import NavierStokesProblem, NoSlip  # noqa: E402
from fbmflow.gpu import colours  # noqa: E402
from fbmflow.gpu.device import gpu_backend, simulated_backend  # noqa: E402
from fbmflow.gpu.vanka import DeviceVanka  # noqa: E402
from fbmflow.mesh import StructuredMesh  # noqa: E402
from fbmflow.solvers import MultigridSolver, ordering  # noqa: E402
from fbmflow.solvers.vanka import FactoredVankaSmoother  # noqa: E402

assert cuda.is_available()
ordering.FAR_SHARE = 0.05  # the disk's 22 patches that reach furthest: colours of their own


def systems():
    prob, con = sharp_disk_problem(StructuredMesh.box((24, 24)), [0.513, 0.521], 0.3)
    system = prob.linear_system(prob.zero_state(), 100.0, 1.0, con)
    yield "2D, sharp disk", system.preconditioner or system, True
    mesh = StructuredMesh.box((4, 4, 4), periodic=(False, False, True))
    for solver, kind in ((None, "Newton"), (MultigridSolver(), "Picard")):
        prob = NavierStokesProblem(mesh, 0.01, {t: NoSlip() for t in mesh.tags}, linear_solver=solver,
                                   coarse_cells=8)
        x = prob.zero_state()
        x[:prob.space.n_u] = 0.1 * np.random.default_rng(3).standard_normal(prob.space.n_u)
        system = prob.linear_system(x, 100.0, 1.0, prob.constraints())
        # factorised on the CPU: the simulator runs every thread in Python (4 minutes for the Newton
        # system's 85 x 85 LU patches, 1-2 for the Picard system's Schur patches); the 2D case
        # checks both kinds of patches on the device, and the CPU test of the bisection
        # (tests/solvers/test_multigrid.py) compiles the factors' body as a GPU thread runs it
        yield f"3D, convection, {kind}", system.preconditioner or system, False


backend = simulated_backend() if os.environ.get("NUMBA_ENABLE_CUDASIM") == "1" else gpu_backend()
worst = 0.0
for name, system, device_factors in systems():
    smoother = FactoredVankaSmoother(system, symmetric=True, order="colours")
    t0 = time.perf_counter()
    template = FactoredVankaSmoother(system, symmetric=True, order="colours", factor=False) \
        if device_factors else smoother
    device = DeviceVanka(template, backend)
    factor_s = time.perf_counter() - t0
    # the factors computed on the device, positions by bisection: under the simulator the CPU's to
    # the last bits; on a GPU, whose compiler fuses multiply-adds, they may differ there (and a
    # near tie may pivot otherwise): the sweeps below, with these factors, decide
    store, piv = (backend.get(a) for a in device.patches[3:5])
    scale = np.abs(smoother.store).max()
    factors = float(np.abs(store.astype(np.float64) - smoother.store).max() / scale)
    if device_factors and backend.name == "numpy":
        worst = max(worst, 2.0 * (factors > 0.0 or not np.array_equal(piv, smoother.piv)))
    rng = np.random.default_rng(1)
    b = rng.standard_normal(system.n_u + system.n_p)
    want = rng.standard_normal(b.size)
    x0 = want.copy()
    x = backend.put(want)  # a copy, as on a GPU
    smoother.smooth(b, want, 2)
    device.smooth(backend.put(b), x, 2)  # a sweep in one cooperative launch
    got = backend.get(x)
    # the same sweeps with a launch per colour, and (the simulator) with several threads sharing a
    # patch's rows and a grid's groups taking several patches of a colour each: within a colour
    # the order does not matter, and each row's sum is one thread's: bit for bit
    launches = {"a launch per colour": (False, device.threads, device.lanes)}
    if backend.name == "numpy" and device_factors:  # the 2D case, every kind of patch (the simulator is slow)
        launches["one launch, blocks of 4 threads, 2 per patch"] = (True, 4, 2)
    alike = []
    for label, (colours.ONE_LAUNCH, device.threads, device.lanes) in launches.items():
        x = backend.put(x0)
        device.smooth(backend.put(b), x, 2)
        colours.ONE_LAUNCH, device.threads, device.lanes = True, backend.threads, backend.lanes
        alike.append(f"{label} {'alike' if np.array_equal(backend.get(x), got) else 'DIFFERENT'}")
        worst = max(worst, 2.0 * (not np.array_equal(backend.get(x), got)))
    error = float(np.abs(got - want).max() / np.abs(want).max())
    tolerance = 1e-5 if smoother.store.dtype == np.float32 and 0 in smoother.blocks else 1e-12
    worst = max(worst, error / tolerance)
    kinds = sorted(set(smoother.blocks.tolist()))
    far = FactoredVankaSmoother(system).far.size  # in the slab order's phases: swept one by one
    print(f"{name}: {len(device.sweeps[0])} colours, far {far}, merged {smoother.merged.size}, interface "
          f"{smoother.interface.size}, factors {smoother.store.dtype}, patch kinds {kinds}: factors "
          f"{'on the device' if device_factors else 'copied'}, {factors:.1e} apart ({factor_s:.0f} s), "
          f"pivots alike {np.array_equal(piv, smoother.piv)}; relative error {error:.1e}; {', '.join(alike)}",
          flush=True)
sys.exit(0 if worst <= 1.0 else 1)
