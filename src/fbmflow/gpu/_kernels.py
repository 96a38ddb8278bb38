"""The numba-cuda kernels (imported only when a GPU kernel is asked for: this module loads
Numba's CUDA target). Each thread runs a body that the CPU kernels run too (``jitable`` in
``fbmflow._jit``), with scratch arrays of the largest cell's sizes."""
from .._jit import cuda_target, float64
from ..fem._kernels import cell_operator, reaction_at, reaction_cell, velocity_at
from ..solvers._kernels import factor_patch, vanka_patch

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


@cuda.jit
def apply_reaction_cells(cells, react, cell_dofs, phi, w, scale, out):
    """Thread ``t`` adds cell ``cells[t]``'s part of ``scale R(u) w`` to ``out``
    (``fbmflow.fem._kernels.reaction_cell``); ``cells`` share no node."""
    t = cuda.grid(1)
    if t < cells.shape[0]:
        wq = cuda.local.array((MAX_POINTS, MAX_DIM), float64)
        fq = cuda.local.array((MAX_POINTS, MAX_DIM), float64)
        reaction_cell(cells[t], react, cell_dofs, phi, w, scale, out, wq, fq)


@cuda.jit
def velocity_rows(u, cell_dofs, phi, detJw, conv):
    """Thread ``c`` writes cell ``c``'s row of the convecting velocity's coefficients
    (``fbmflow.fem._kernels.velocity_at``)."""
    c = cuda.grid(1)
    if c < cell_dofs.shape[0]:
        velocity_at(c, u, cell_dofs, phi, detJw, conv)


@cuda.jit
def reaction_rows(u, cell_dofs, phi, dphi, detJw, Jinv, react):
    """Thread ``c`` writes cell ``c``'s row of the Newton term's coefficients
    (``fbmflow.fem._kernels.reaction_at``)."""
    c = cuda.grid(1)
    if c < cell_dofs.shape[0]:
        ul = cuda.local.array((MAX_DIM, MAX_NODES), float64)
        uq = cuda.local.array((MAX_POINTS, MAX_DIM), float64)
        gq = cuda.local.array((MAX_POINTS, MAX_DIM, MAX_DIM), float64)
        reaction_at(c, u, cell_dofs, phi, dphi, detJw, Jinv, react, ul, uq, gq)


@cuda.jit(fastmath=True)
def vanka_patches(patches, b, x, omega, ptr, dofs, lu_ptr, store, piv, blocks, d_read, nl, d, n_v, n_u,
                  regular, s_ptr, s_idx, s_val, nc_ptr, nc_cell, nc_rank, gt, d_pos, d_ptr, d_idx, d_val,
                  b_idx, k_ptr, k_idx, k_val, r, w, w64, out):
    """Thread ``t`` adds patch ``patches[t]``'s Vanka correction to ``x``
    (``fbmflow.solvers._kernels.vanka_patch``), with the rows ``t`` of the work arrays ``r``,
    ``w64``, ``out`` (float64) and ``w`` (the factors' dtype), (threads, width) each; ``patches``
    touch nothing of each other."""
    t = cuda.grid(1)
    if t < patches.shape[0]:
        vanka_patch(patches[t], b, x, omega, (ptr, dofs, lu_ptr, store, piv, blocks, d_read, nl, d, n_v, n_u),
                    (regular, s_ptr, s_idx, s_val, nc_ptr, nc_cell, nc_rank, gt, d_pos, d_ptr, d_idx, d_val,
                     b_idx, k_ptr, k_idx, k_val), r[t], w[t], w64[t], out[t])


@cuda.jit
def vanka_factors(patches, schur_tol, ptr, dofs, lu_ptr, store, piv, blocks, d_read, nl, d, n_v, n_u, regular,
                  s_ptr, s_idx, s_val, nc_ptr, nc_cell, nc_rank, gt, d_pos, d_ptr, d_idx, d_val, b_idx, k_ptr,
                  k_idx, k_val, work, A, Ainv, Y, Sc, Sinv, p_work, e, col):
    """Thread ``t`` writes patch ``patches[t]``'s local factors into ``store`` and ``piv``
    (``fbmflow.solvers._kernels.factor_patch``, positions by bisection), with
    entry ``t`` of the work arrays ``work (threads, width, width)``, ``A``, ``Ainv``, ``Y``,
    ``Sc``, ``Sinv``, ``p_work``, ``e``, ``col`` (the shapes of ``factor_patch``'s behind
    the thread axis)."""
    t = cuda.grid(1)
    if t < patches.shape[0]:
        factor_patch(patches[t], (ptr, dofs, lu_ptr, store, piv, blocks, d_read, nl, d, n_v, n_u),
                     (regular, s_ptr, s_idx, s_val, nc_ptr, nc_cell, nc_rank, gt, d_pos, d_ptr, d_idx, d_val,
                      b_idx, k_ptr, k_idx, k_val), schur_tol, None, work[t], A[t], Ainv[t], Y[t], Sc[t],
                     Sinv[t], p_work[t], e[t], col[t])
