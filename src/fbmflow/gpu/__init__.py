"""GPU computing, an optional extra (``pip install -e ".[gpu]"``: numba-cuda and CuPy):
``solver.device = "gpu"`` runs multigrid's cycles and FGMRES on an NVIDIA GPU
(:mod:`fbmflow.gpu.multigrid`), the set-up and the coarsest level on the CPU. The kernels are
numba-cuda kernels whose threads run the CPU kernels' own per-cell and per-patch bodies: the
matrix-free operators (:mod:`fbmflow.gpu.operators`) and the factored Vanka sweep
(:mod:`fbmflow.gpu.vanka`), their colours in one launch (:mod:`fbmflow.gpu.colours`). Nothing
here is imported by the rest of fbmflow before a GPU is asked for, and nothing here imports CUDA
before a kernel runs; under Numba's CUDA simulator
(``NUMBA_ENABLE_CUDASIM=1``, :func:`~fbmflow.gpu.device.simulated_backend`) the kernels run on
the CPU, which is how the tests check them on a machine without a GPU.
"""
from .multigrid import DeviceMultigridSolver, gpu_solver
from .operators import (
    apply_cell_operator,
    apply_reaction,
    cell_colours,
    reaction_coefficients,
    velocity_coefficients,
)

__all__ = ["DeviceMultigridSolver", "apply_cell_operator", "apply_reaction", "cell_colours", "gpu_solver",
           "reaction_coefficients", "velocity_coefficients"]
