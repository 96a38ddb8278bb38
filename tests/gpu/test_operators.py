"""The GPU's kernels (:mod:`fbmflow.gpu`) against the CPU's, under Numba's CUDA simulator (no GPU
needed: CI has none)."""
import os
import subprocess
import sys
from pathlib import Path


def test_the_gpu_operators_under_the_simulator_are_the_cpu_kernels():
    """``NUMBA_ENABLE_CUDASIM=1 python _simulated_operator.py``: the cell operator's kernel (one
    thread per cell, the cells in colours that share no node) adds what the CPU kernel adds, to
    1e-13 relative, for the mass, Laplace and convection terms, with a given convecting velocity
    and with ``N(w) w``; so do the Newton term's, and the two coefficient kernels write the CPU's
    arrays; on a 2D mesh (6 x 4, periodic along x: 4 colours) and a 3D one (4 x 2 x 4, periodic
    along z: 8 colours). In a process of its own: the simulator is chosen when Numba is
    imported."""
    script = Path(__file__).with_name("_simulated_operator.py")
    out = subprocess.run([sys.executable, str(script)], env=dict(os.environ, NUMBA_ENABLE_CUDASIM="1"),
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stdout + out.stderr
    assert out.stdout.count("relative error") == 12


def test_fbmflow_without_the_gpu_package_imports_no_cuda():
    """The core imports neither :mod:`fbmflow.gpu` nor Numba's CUDA target: the ``gpu`` extra is
    optional."""
    code = ("import sys, fbmflow\nfrom fbmflow.scenes.registry import load_scene\n"
            "print('numba.cuda' in sys.modules, 'fbmflow.gpu' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["False", "False"]
