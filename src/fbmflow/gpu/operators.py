"""The matrix-free velocity operators on the GPU: ``alpha M + beta L + gamma N(c)`` and the Newton
term ``R(u)``, and the per-point coefficients they read. One numba-cuda thread per cell; where
threads add into a vector, the cells go in colours that share no node (no atomics), all colours
in one cooperative launch (:class:`~fbmflow.gpu.colours.DeviceColours`). Each
thread runs the body the CPU kernel runs per cell (``fbmflow.fem._kernels``: ``cell_operator``,
``reaction_cell``, ``velocity_at``, ``reaction_at``). Arguments are device arrays (numba-cuda's
or CuPy's) of the CPU kernels' shapes and types.
"""
from __future__ import annotations

import functools

import numpy as np
import scipy.sparse as sp

from .device import launch_views


def cell_colours(cell_dofs: np.ndarray) -> list[np.ndarray]:
    """The cells in colours, no two cells of a colour sharing a node (greedy, in cell order),
    a list of (k,) int64 arrays. ``cell_dofs (n_cells, nl)``: every cell's nodes."""
    from ..solvers._kernels import greedy_colours

    n_cells, nl = cell_dofs.shape
    rows = np.repeat(np.arange(n_cells), nl)
    incidence = sp.csr_matrix((np.ones(cell_dofs.size), (rows, cell_dofs.ravel())))
    touch = (incidence @ incidence.T).tocsr()
    touch.setdiag(0.0)
    touch.eliminate_zeros()
    colour = greedy_colours(touch.indptr.astype(np.int64), touch.indices.astype(np.int64))
    return [np.flatnonzero(colour == c).astype(np.int64) for c in range(int(colour.max()) + 1)]


def apply_cell_operator(colours, detJw, Jinv, cell_dofs, phi, dphi, alpha: float, beta: float, gamma: float,
                        conv, w, out, threads: int = 128) -> None:
    """Add ``(alpha M + beta L + gamma N(c)) w`` to ``out`` in place on the GPU, as
    ``fbmflow.fem._kernels.apply_cell_operator`` does on the CPU: the same arguments as
    device arrays (numba-cuda's, or CuPy's), the cells in ``colours``
    (:class:`~fbmflow.gpu.colours.DeviceColours` of :func:`cell_colours`) instead of groups;
    ``conv`` None (the CPU's empty array): ``N(w) w``. One launch of ``threads`` per block
    (:meth:`DeviceColours.launch <fbmflow.gpu.colours.DeviceColours.launch>`)."""
    own = conv is None
    if own:  # a stand-in no thread reads (a CuPy array of size 0 has no address to pass)
        conv = _no_convection()
    colours.launch("apply_cells", "apply_cells_sweep", threads, detJw, Jinv, cell_dofs, phi, dphi,
                   float(alpha), float(beta), float(gamma), conv, own, w, out)


@functools.cache
def _no_convection():
    """A (1, 1, 1) float64 device array, for ``conv`` where the kernel reads none (one per
    process)."""
    from .._jit import cuda_target

    return cuda_target().device_array((1, 1, 1))


def apply_reaction(colours, react, cell_dofs, phi, w, scale: float, out, threads: int = 128) -> None:
    """Add ``scale R(u) w`` to ``out`` in place on the GPU, as ``fbmflow.fem._kernels.apply_reaction``
    does on the CPU, the cells in ``colours`` (:class:`~fbmflow.gpu.colours.DeviceColours` of
    :func:`cell_colours`) instead of groups."""
    colours.launch("apply_reaction_cells", "apply_reaction_sweep", threads, react, cell_dofs, phi, w,
                   float(scale), out)


def velocity_coefficients(u, cell_dofs, phi, detJw, conv, threads: int = 128) -> None:
    """``|det J| w_q u_k`` at every cell's quadrature points written into ``conv (n_cells, nq, d)``
    float64, as ``fbmflow.fem._kernels.velocity_coefficients`` returns it on the CPU."""
    from ._kernels import velocity_rows

    velocity_rows[max(1, -(-cell_dofs.shape[0] // threads)), threads](*launch_views(u, cell_dofs, phi, detJw,
                                                                                    conv))


def reaction_coefficients(u, cell_dofs, phi, dphi, detJw, Jinv, react, threads: int = 128) -> None:
    """``|det J| w_q d u_i / d x_k`` at every cell's quadrature points written into ``react
    (n_cells, nq, d, d)`` (float32, as ``fbmflow.fem._kernels.reaction_coefficients`` returns it
    on the CPU)."""
    from ._kernels import reaction_rows

    reaction_rows[max(1, -(-cell_dofs.shape[0] // threads)), threads](*launch_views(u, cell_dofs, phi, dphi,
                                                                                    detJw, Jinv, react))
