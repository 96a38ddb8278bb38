"""Multigrid on the device (:mod:`fbmflow.gpu.multigrid`) against the CPU's, under Numba's CUDA
simulator (no GPU needed: CI has none)."""
import os
import subprocess
import sys
from pathlib import Path


def test_a_solve_on_the_device_under_the_simulator_is_the_cpus_in_colour_order():
    """``NUMBA_ENABLE_CUDASIM=1 python _simulated_multigrid.py``: FGMRES with multigrid cycles on
    the device (operator, smoother, transfers; the coarsest level on the CPU) takes as many
    cycles as the CPU's multigrid with the smoothers in the same colour order and gives its
    velocity to 1e-10 relative, on a 2D sharp-boundary disk in a closed box (the Picard
    hierarchy, the mean-pressure border) and on a 3D Newton block moved to another iterate (the
    Newton terms applied without a matrix on the device); the flow problem with the device's
    solver computes its Newton residual (operator, gradient, continuity rows) and its time step's
    mass and spatial terms on the device, the CPU's to 1e-13 relative, from one copy of the
    space's cells that the Newton terms share and the operator's copies of the divergence.
    Every level's operator and transfers are the CPU level's to 1e-14 relative, its divergence
    and transfers are copied once for every set-up, and a moved Newton block's coefficients are
    computed on the device alone, the CPU's bit for bit."""
    script = Path(__file__).with_name("_simulated_multigrid.py")
    out = subprocess.run([sys.executable, str(script)], env=dict(os.environ, NUMBA_ENABLE_CUDASIM="1"),
                         capture_output=True, text=True, timeout=900)
    assert out.returncode == 0, out.stdout + out.stderr
    assert out.stdout.count("cycles CPU") == 2


def test_a_whole_step_on_the_device_under_the_simulator_is_the_cpus_in_colour_order():
    """``NUMBA_ENABLE_CUDASIM=1 python _simulated_step.py``: one time step of a disk settling in a
    closed box with ``solver.device = gpu`` (the Newton residuals, the solves, the rigid
    responses of the implicit coupling) gives the disk the velocity the CPU's step gives with its
    smoothers in the same colour order, to 1e-9 relative, in as many solves and cycles, computing
    the Newton blocks' coefficients on the CPU fewer times than the CPU's step. With the device's
    residual missing its convection the velocities differ by 4.2e-5 (checked by hand)."""
    script = Path(__file__).with_name("_simulated_step.py")
    out = subprocess.run([sys.executable, str(script)], env=dict(os.environ, NUMBA_ENABLE_CUDASIM="1"),
                         capture_output=True, text=True, timeout=900)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "relative difference" in out.stdout
