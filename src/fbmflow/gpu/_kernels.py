"""The numba-cuda kernels (imported only when a GPU kernel is asked for: this module loads
Numba's CUDA target). Each thread runs a body that the CPU kernels run too (``jitable`` in
``fbmflow._jit``), with scratch arrays of the largest cell's sizes."""
from .._jit import cuda_target, float64
from ..fem._kernels import cell_operator

cuda = cuda_target()

#: the largest Q2 cell (3D): nodes and quadrature points (3 x 3 x 3 Gauss), and axes; the
#: threads' scratch arrays have these sizes whatever the mesh
MAX_NODES, MAX_POINTS, MAX_DIM = 27, 27, 3


@cuda.jit
def apply_cells(cells, detJw, Jinv, cell_dofs, phi, dphi, alpha, beta, gamma, conv, own, w, out):
    """Thread ``t`` adds cell ``cells[t]``'s part of ``(alpha M + beta L + gamma N(c)) w`` to
    ``out`` (``fbmflow.fem._kernels.cell_operator``); ``cells`` share no node."""
    t = cuda.grid(1)
    if t < cells.shape[0]:
        wl = cuda.local.array((MAX_DIM, MAX_NODES), float64)
        wq = cuda.local.array((MAX_POINTS, MAX_DIM), float64)
        gq = cuda.local.array((MAX_POINTS, MAX_DIM, MAX_DIM), float64)
        value = cuda.local.array((MAX_POINTS, MAX_DIM), float64)
        flux = cuda.local.array((MAX_POINTS, MAX_DIM, MAX_DIM), float64)
        cell_operator(cells[t], detJw, Jinv, cell_dofs, phi, dphi, alpha, beta, gamma, conv, own, w, out, wl,
                      wq, gq, value, flux)
