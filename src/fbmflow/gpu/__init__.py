"""GPU computing (issue "GPU computing"), an optional extra (``pip install -e ".[gpu]"``:
numba-cuda and CuPy): the matrix-free operators as numba-cuda kernels with the same per-cell
bodies as the CPU kernels. Nothing here is imported by the rest of fbmflow, and nothing here
imports CUDA before a kernel is asked for; the kernels run under Numba's CUDA simulator
(``NUMBA_ENABLE_CUDASIM=1``) on a machine without a GPU, which is how the tests check them.

Not yet: a solver that runs on the GPU (``solver.device``); this package holds its kernels,
each checked against its CPU kernel.
"""
from .operators import (
    apply_cell_operator,
    apply_reaction,
    cell_colours,
    reaction_coefficients,
    velocity_coefficients,
)

__all__ = ["apply_cell_operator", "apply_reaction", "cell_colours", "reaction_coefficients",
           "velocity_coefficients"]
