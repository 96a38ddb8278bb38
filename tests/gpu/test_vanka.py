"""The GPU's Vanka sweeps (:mod:`fbmflow.gpu.vanka`) against the CPU's, under Numba's CUDA
simulator (no GPU needed: CI has none)."""
import os
import subprocess
import sys
from pathlib import Path


def test_the_gpu_sweeps_under_the_simulator_are_the_cpu_smoothers_in_colour_order():
    """``NUMBA_ENABLE_CUDASIM=1 python _simulated_vanka.py``: the local factors computed on the
    device (one thread per patch, positions by bisection) are the CPU's bit for bit, with the same
    pivots (the 2D case: LU and Schur patches), and two symmetric sweeps of the GPU smoother (one
    thread per patch, a launch per colour) give the CPU's factored smoother's in the same colour
    order, to 1e-5 relative where the factors are single (the two sum in different
    orders in single precision) and 1e-12 where the patches solve in double, on a 2D sharp disk
    (LU and Schur patches, far, agglomerated and interface patches) and a 3D periodic box's Newton
    (LU patches) and Picard (Schur patches) systems."""
    script = Path(__file__).with_name("_simulated_vanka.py")
    out = subprocess.run([sys.executable, str(script)], env=dict(os.environ, NUMBA_ENABLE_CUDASIM="1"),
                         capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stdout + out.stderr
    assert out.stdout.count("relative error") == 3
