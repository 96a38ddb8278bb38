"""The GPU's kernels compile for a real GPU (PTX), where the ``gpu`` extra's numba-cuda and the CUDA
toolkit's NVVM are installed (no GPU needed; skipped elsewhere, as in CI)."""
import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

HERE = Path(__file__).parent


@pytest.mark.skipif(importlib.util.find_spec("numba_cuda") is None, reason="needs the gpu extra (numba-cuda)")
def test_every_gpu_kernel_compiles_for_the_cuda_target(tmp_path):
    """Every kernel of :mod:`fbmflow.gpu._kernels`, with the argument types of its launches in the
    simulator scripts (the operators, the Vanka smoother's factors and sweeps, a solve on the
    device with the residuals: ``_kernel_types.py`` under ``NUMBA_ENABLE_CUDASIM=1``), compiles to
    PTX for compute capability 9.0 (``_compile_kernels.py``), and those that synchronise their grid
    (the cooperative ``*_sweep`` kernels) link with the CUDA device runtime to a cubin. Before the
    kernels called copies of the CPU's bodies (``fbmflow.gpu._kernels.device_copy``), the four
    operator kernels failed here (numba-cuda 0.30.4: an AssertionError or a TypingError in the
    inlined bodies), which the simulator could not show."""
    record = tmp_path / "types.json"
    scripts = ["_simulated_operator.py", "_simulated_vanka.py", "_simulated_multigrid.py:2D, sharp disk"]
    simulated = subprocess.run([sys.executable, str(HERE / "_kernel_types.py"), str(record), *scripts],
                               env=dict(os.environ, NUMBA_ENABLE_CUDASIM="1"), capture_output=True, text=True,
                               timeout=1200)
    assert simulated.returncode == 0, simulated.stdout[-3000:] + simulated.stderr[-3000:]
    kinds = json.loads(record.read_text())
    compiled = subprocess.run([sys.executable, str(HERE / "_compile_kernels.py"), str(record)],
                              capture_output=True, text=True, timeout=1200)
    if compiled.returncode == 3:
        pytest.skip(compiled.stdout.strip())
    assert compiled.returncode == 0, compiled.stdout[-6000:] + compiled.stderr[-3000:]
    assert compiled.stdout.count("characters of PTX") == sum(len(v) for v in kinds.values())
    cooperative = sum(len(types) for name, types in kinds.items() if name.endswith("_sweep"))
    assert compiled.stdout.count("linked with the device runtime") == cooperative > 0
