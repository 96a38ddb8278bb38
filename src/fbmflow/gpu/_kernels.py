"""The numba-cuda kernels (imported only when a GPU kernel is asked for: this module loads
Numba's CUDA target). Each thread runs a body that the CPU kernels run too (``jitable`` in
``fbmflow._jit``), with scratch arrays of the largest cell's sizes: a copy of it compiled as a
CUDA device function (:func:`device_copy`)."""
import types

from .._jit import JITABLE, cuda_simulated, cuda_target, float64
from ..fem import _kernels as fem
from ..solvers import _kernels as solvers

cuda = cuda_target()


#: the device copies made in this process, by the CPU's function
_COPIES: dict = {}


def device_copy(function):
    """A copy of the :func:`~fbmflow._jit.jitable` ``function`` compiled as a CUDA device function
    (with its jit options), calling the copies of the jitable functions it calls.

    The GPU's kernels call these copies, never the CPU's function objects: those are registered
    for the CPU's kernels to inline into their IR (``inline="always"``), which numba-cuda cannot
    compile (numba-cuda 0.30.4: an ``AssertionError`` in its IR post-processing, for any body with
    a branch), and a typing of the CPU's, once cached, is reused for a GPU kernel whatever the
    target. Under Numba's CUDA simulator the copies are plain Python functions (the simulator
    calls them as the CPU's Python code would)."""
    found = _COPIES.get(function)
    if found is not None:
        return found
    namespace = dict(function.__globals__)
    for name in function.__code__.co_names:  # the globals its body reads: the jitable ones it calls
        value = namespace.get(name)
        if isinstance(value, types.FunctionType) and value in JITABLE:
            namespace[name] = device_copy(value)
    copy = types.FunctionType(function.__code__, namespace, function.__name__, function.__defaults__,
                              function.__closure__)
    copy.__doc__, copy.__qualname__ = function.__doc__, function.__qualname__
    found = _COPIES[function] = copy if cuda_simulated() else cuda.jit(device=True, **JITABLE[function])(copy)
    return found


cell_operator, reaction_at, reaction_cell, velocity_at = (
    device_copy(f) for f in (fem.cell_operator, fem.reaction_at, fem.reaction_cell, fem.velocity_at))
factor_patch, vanka_residual, vanka_solve, vanka_update = (device_copy(f) for f in (
    solvers.factor_patch, solvers.vanka_residual, solvers.vanka_solve, solvers.vanka_update))

#: the largest Q2 cell (3D): nodes and quadrature points (3 x 3 x 3 Gauss), and axes; the
#: threads' scratch arrays have these sizes whatever the mesh
MAX_NODES, MAX_POINTS, MAX_DIM = 27, 27, 3


@cuda.jit(device=True)
def _cells_colour(order, first, last, detJw, Jinv, cell_dofs, phi, dphi, alpha, beta, gamma, conv, own, w,
                  out):
    """Adds the parts of ``(alpha M + beta L + gamma N(c)) w`` of the cells ``order[first:last]``
    (one colour: they share no node) to ``out`` (``fbmflow.fem._kernels.cell_operator``), thread
    ``t`` taking every ``gridsize``-th from ``first + t``."""
    wl = cuda.local.array((MAX_DIM, MAX_NODES), float64)
    wq = cuda.local.array((MAX_POINTS, MAX_DIM), float64)
    gq = cuda.local.array((MAX_POINTS, MAX_DIM, MAX_DIM), float64)
    value = cuda.local.array((MAX_POINTS, MAX_DIM), float64)
    flux = cuda.local.array((MAX_POINTS, MAX_DIM, MAX_DIM), float64)
    for k in range(first + cuda.grid(1), last, cuda.gridsize(1)):
        cell_operator(order[k], detJw, Jinv, cell_dofs, phi, dphi, alpha, beta, gamma, conv, own, w, out, wl,
                      wq, gq, value, flux)


@cuda.jit
def apply_cells(order, first, last, detJw, Jinv, cell_dofs, phi, dphi, alpha, beta, gamma, conv, own, w, out):
    """The cells ``order[first:last]`` (one colour) in one launch (:func:`_cells_colour`)."""
    _cells_colour(order, first, last, detJw, Jinv, cell_dofs, phi, dphi, alpha, beta, gamma, conv, own, w,
                  out)


@cuda.jit
def apply_cells_sweep(order, starts, detJw, Jinv, cell_dofs, phi, dphi, alpha, beta, gamma, conv, own, w,
                      out):
    """The colours ``order[starts[c]:starts[c + 1]]`` in turn (:func:`_cells_colour`), the whole
    grid synchronised between them: one cooperative launch."""
    grid = cuda.cg.this_grid()
    colours = starts.shape[0] - 1
    for c in range(colours):
        _cells_colour(order, starts[c], starts[c + 1], detJw, Jinv, cell_dofs, phi, dphi, alpha, beta, gamma,
                      conv, own, w, out)
        if c + 1 < colours:
            grid.sync()


@cuda.jit(device=True)
def _reaction_colour(order, first, last, react, cell_dofs, phi, w, scale, out):
    """Adds the parts of ``scale R(u) w`` of the cells ``order[first:last]`` (one colour) to
    ``out`` (``fbmflow.fem._kernels.reaction_cell``), thread ``t`` taking every ``gridsize``-th
    from ``first + t``."""
    wq = cuda.local.array((MAX_POINTS, MAX_DIM), float64)
    fq = cuda.local.array((MAX_POINTS, MAX_DIM), float64)
    for k in range(first + cuda.grid(1), last, cuda.gridsize(1)):
        reaction_cell(order[k], react, cell_dofs, phi, w, scale, out, wq, fq)


@cuda.jit
def apply_reaction_cells(order, first, last, react, cell_dofs, phi, w, scale, out):
    """The cells ``order[first:last]`` (one colour) in one launch (:func:`_reaction_colour`)."""
    _reaction_colour(order, first, last, react, cell_dofs, phi, w, scale, out)


@cuda.jit
def apply_reaction_sweep(order, starts, react, cell_dofs, phi, w, scale, out):
    """The colours ``order[starts[c]:starts[c + 1]]`` in turn (:func:`_reaction_colour`), the
    whole grid synchronised between them: one cooperative launch."""
    grid = cuda.cg.this_grid()
    colours = starts.shape[0] - 1
    for c in range(colours):
        _reaction_colour(order, starts[c], starts[c + 1], react, cell_dofs, phi, w, scale, out)
        if c + 1 < colours:
            grid.sync()


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


@cuda.jit(device=True)
def _vanka_colour(order, first, last, lanes, b, x, omega, patches, op, r, w, w64, out):
    """The Vanka corrections of the patches ``order[first:last]`` (one colour: they touch nothing
    of each other) added to ``x``, every patch by ``lanes`` consecutive threads of a block (whose
    size ``lanes`` divides): they take its residual's rows in turn, the first of them solves, they
    take its update's entries in turn (``fbmflow.solvers._kernels``: ``vanka_residual``,
    ``vanka_solve``, ``vanka_update``), the block synchronised between. Patch group ``g`` of the
    grid works in the rows ``g`` of the work arrays ``r``, ``w64``, ``out`` (float64) and ``w``
    (the factors' dtype), (groups, width) each; a grid with fewer groups than patches takes
    them in turn."""
    per = cuda.blockDim.x // lanes
    group = cuda.threadIdx.x // lanes
    lane = cuda.threadIdx.x - group * lanes
    slot = cuda.blockIdx.x * per + group
    for base in range(first + cuda.blockIdx.x * per, last, cuda.gridDim.x * per):  # alike in a block
        e = base + group
        if e < last:
            vanka_residual(order[e], lane, lanes, b, x, patches, op, r[slot])
        if lanes > 1:  # (alike in the block; a patch of one thread needs no barrier)
            cuda.syncthreads()
        if e < last and lane == 0:
            vanka_solve(order[e], patches, op, r[slot], w[slot], w64[slot], out[slot])
        if lanes > 1:
            cuda.syncthreads()
        if e < last:
            vanka_update(order[e], lane, lanes, x, omega, patches, out[slot])


@cuda.jit(fastmath=True)
def vanka_patches(order, first, last, lanes, b, x, omega, ptr, dofs, lu_ptr, store, piv, blocks, d_read, nl,
                  d, n_v, n_u, regular, s_ptr, s_idx, s_val, nc_ptr, nc_cell, nc_rank, gt, d_pos, d_ptr,
                  d_idx, d_val, b_idx, k_ptr, k_idx, k_val, r, w, w64, out):
    """The patches ``order[first:last]`` (one colour), ``lanes`` threads each
    (:func:`_vanka_colour`)."""
    _vanka_colour(order, first, last, lanes, b, x, omega,
                  (ptr, dofs, lu_ptr, store, piv, blocks, d_read, nl, d, n_v, n_u),
                  (regular, s_ptr, s_idx, s_val, nc_ptr, nc_cell, nc_rank, gt, d_pos, d_ptr, d_idx, d_val,
                   b_idx, k_ptr, k_idx, k_val), r, w, w64, out)


@cuda.jit(fastmath=True)
def vanka_sweep(order, starts, lanes, b, x, omega, ptr, dofs, lu_ptr, store, piv, blocks, d_read, nl, d, n_v,
                n_u, regular, s_ptr, s_idx, s_val, nc_ptr, nc_cell, nc_rank, gt, d_pos, d_ptr, d_idx, d_val,
                b_idx, k_ptr, k_idx, k_val, r, w, w64, out):
    """The colours ``order[starts[c]:starts[c + 1]]`` in turn, each as :func:`vanka_patches`
    sweeps one, the whole grid synchronised between colours (``cuda.cg.this_grid().sync()``): a
    sweep in one launch. Numba launches a kernel that synchronises its grid cooperatively: all its
    blocks resident at once (at most ``max_cooperative_grid_blocks``)."""
    grid = cuda.cg.this_grid()
    patches = (ptr, dofs, lu_ptr, store, piv, blocks, d_read, nl, d, n_v, n_u)
    op = (regular, s_ptr, s_idx, s_val, nc_ptr, nc_cell, nc_rank, gt, d_pos, d_ptr, d_idx, d_val, b_idx,
          k_ptr, k_idx, k_val)
    colours = starts.shape[0] - 1
    for c in range(colours):
        _vanka_colour(order, starts[c], starts[c + 1], lanes, b, x, omega, patches, op, r, w, w64, out)
        if c + 1 < colours:
            grid.sync()


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
