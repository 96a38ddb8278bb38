"""Assembly of the Q2/P1disc operators into precomputed CSR patterns.

Local matrices are computed in *tensor form* (Kirby & Logg's reference-tensor representation):
for a batch of cells, the quadrature-point coefficients (a Numba kernel) are multiplied by a
constant reference table with one BLAS GEMM,

    local[c, (a, b)] = sum_{q, l, ...} coeff[c, (q, l, ...)] * table[(q, l, ...), (a, b)],

and a Numba kernel scatters them straight into ``csr.data`` through the per-cell slot map. No COO
matrix is ever built.

Weak forms (``phi`` test, ``psi`` trial pressure; velocity components are blocked):

* mass ``M[a, b] = int phi_a phi_b``
* viscous term in *gradient form* ``L[a, b] = int grad phi_a · grad phi_b`` per component. We use
  the gradient form (not the deformation tensor ``2 D(u) : D(v)``) because its natural boundary
  condition ``nu du/dn - p n = 0`` is the classical "do-nothing" outflow that leaves Poiseuille
  flow undisturbed; for divergence-free fields both forms give the same interior operator, and the
  particle forces are evaluated with the full Cauchy stress anyway.
* convection ``N(w)[a, b] = int phi_a (w · grad phi_b)`` per component,
* Newton term ``R_ik(w)[a, b] = int phi_a phi_b d w_i / d x_k`` coupling components,
* gradient/divergence ``B[(i, a), (c, m)] = -int_c psi_m d phi_a/dx_i``; ``B^T u = 0`` is the
  discrete continuity equation.
"""
from __future__ import annotations

import functools

import numpy as np
import scipy.sparse as sp
from threadpoolctl import ThreadpoolController

from .._jit import numba_threads
from . import _kernels
from .space import FlowSpace


@functools.cache
def _threadpool_controller() -> ThreadpoolController:
    import scipy.linalg.cython_blas  # noqa: F401  (the BLAS of Numba's np.dot, loaded before the look)

    return ThreadpoolController()


def single_threaded_blas():
    """Context in which BLAS runs on one thread (NumPy's and the one Numba's kernels call).

    The assembly alternates small BLAS GEMMs with Numba parallel loops; with both thread pools
    active on 2 cores they oversubscribe and each phase slows down several-fold (measured). The
    GEMMs run on Numba's threads instead, a chunk of rows each (``_times``).
    """
    return _threadpool_controller().limit(limits=1, user_api="blas")


def _times(a: np.ndarray, table: np.ndarray) -> np.ndarray:
    """``a @ table`` (m, n) on every Numba thread, a chunk of ``a``'s rows each, inside
    :func:`single_threaded_blas` (NumPy's product there runs on one core: some 0.3 s of a ten Cate
    level-2 step, serial; 512 x 81 times 81 x 729, a 3D batch's convection: 1.95 times as fast on
    2 cores)."""
    a = np.ascontiguousarray(a, dtype=np.float64)
    out = np.empty((a.shape[0], table.shape[1]))
    _kernels.rows_times(a, np.ascontiguousarray(table, dtype=np.float64), out,
                        max(1, min(a.shape[0], numba_threads())))
    return out


def _mass_laplace_coefficients(space: FlowSpace, cells: np.ndarray, alpha: float, beta: float) -> np.ndarray:
    """The coefficients of ``alpha M + beta L`` on ``cells`` (m,) for the rows of
    :attr:`~fbmflow.fem.space.FlowSpace.table_mass_laplace_cells`: the cells' weights of
    :attr:`~fbmflow.fem.space.FlowSpace.cell_axes` (``1 + d`` per cell) where the cells are
    axis-aligned boxes, else the coefficients at every point (the Laplacian's symmetric pairs of
    axes folded, 7 rows per point in 3D); (m, k) float64."""
    axes = space.cell_axes
    if axes is not None:
        return axes[cells] * np.array([alpha] + [beta] * space.dim)
    return _kernels.mass_laplace_coefficients(space.detJw[cells], space.Jinv[cells], alpha, beta)


def assemble_mass_laplace(space: FlowSpace, alpha: float, beta: float) -> np.ndarray:
    """Data (nnz,) of ``alpha M + beta L`` on ``space``'s scalar pattern, one GEMM per batch with
    :attr:`~fbmflow.fem.space.FlowSpace.table_mass_laplace_cells` (with a convection term:
    :func:`assemble_convection`'s ``mass_laplace``, the same GEMM)."""
    data = np.zeros(space.nnz)
    table = space.table_mass_laplace_cells
    with single_threaded_blas():
        for cells in space.batches:
            local = _times(_mass_laplace_coefficients(space, cells.ravel(), alpha, beta), table)
            _kernels.scatter_scalar(cells, local, space.offsets, space.V.cell_dofs, space.indptr, data)
    return data


def assemble_mass(space: FlowSpace) -> np.ndarray:
    """Data (nnz,) of the scalar Q2 mass matrix on ``space``'s pattern."""
    return assemble_mass_laplace(space, 1.0, 0.0)


def assemble_laplace(space: FlowSpace) -> np.ndarray:
    """Data (nnz,) of the scalar Q2 stiffness matrix ``int grad phi_a · grad phi_b``."""
    return assemble_mass_laplace(space, 0.0, 1.0)


def assemble_convection(space: FlowSpace, u: np.ndarray, scale: float,
                        scalar_out: np.ndarray | None = None,
                        newton_out: np.ndarray | None = None,
                        mass_laplace: tuple[float, float] | None = None) -> None:
    """Add ``scale * N(u)`` to ``scalar_out``, or ``scale * (N(u) + R(u))`` to ``newton_out``;
    with ``mass_laplace = (alpha, beta)`` also ``alpha M + beta L`` (on every diagonal block of
    ``newton_out``).

    The mass and Laplace terms' coefficients join the convection's: one GEMM per batch with
    :attr:`~fbmflow.fem.space.FlowSpace.table_convection_mass_laplace` and one scatter, where
    :func:`assemble_mass_laplace` and this function apart write and scatter every local matrix
    twice.

    Parameters
    ----------
    u : (dim * n_v,) float64, component-blocked convecting velocity
    scale : float
    scalar_out : (nnz,) float64, scalar pattern data, updated in place (Picard operator)
    newton_out : (dim * dim * nnz,) float64, coupled pattern data, updated in place (Newton
        Jacobian: the convection on the diagonal blocks plus the Newton blocks ``R_ik``)
    mass_laplace : (alpha, beta), or None for the convection alone
    """
    if (scalar_out is None) == (newton_out is None):
        raise ValueError("give exactly one of scalar_out and newton_out")
    d = space.dim
    uu = np.ascontiguousarray(u.reshape(d, space.n_v))
    newton = newton_out is not None
    mass_upper, sym = space.table_mass_upper
    table = space.table_convection if mass_laplace is None else space.table_convection_mass_laplace
    chunks = 4 * numba_threads()
    with single_threaded_blas():
        for cells in space.batches:
            c = cells.ravel()
            conv, react = _kernels.convection_coefficients(
                c, uu, space.V.cell_dofs, space.phi, space.dphi, space.detJw, space.Jinv, newton, chunks)
            conv *= scale
            if mass_laplace is not None:
                conv = np.hstack([conv, _mass_laplace_coefficients(space, c, *mass_laplace)])
            local = _times(conv, table)
            if newton:
                react *= scale
                _kernels.scatter_coupled(cells, local, _times(react, mass_upper), sym, space.offsets,
                                         space.V.cell_dofs, space.indptr, d, newton_out)
            else:
                _kernels.scatter_scalar(cells, local, space.offsets, space.V.cell_dofs, space.indptr,
                                        scalar_out)


def assemble_divergence(space: FlowSpace) -> sp.csr_matrix:
    """``B^T`` as CSR, shape (n_p, dim * n_v); ``B = B^T.T`` is its zero-copy CSC transpose."""
    d = space.dim
    cd = space.V.cell_dofs
    nl = cd.shape[1]
    npl = d + 1
    data = np.empty(space.mesh.n_cells * npl * d * nl)
    _kernels.divergence_local(space.dphi, space.detJw, space.Jinv, space.psi, space.local_rank, data)
    sorted_dofs = np.sort(cd, axis=1)  # (n_cells, nl)
    cols = (sorted_dofs[:, None, :] + space.n_v * np.arange(d)[None, :, None]).reshape(-1, d * nl)
    indices = np.repeat(cols, npl, axis=0).ravel().astype(np.int32)
    indptr = np.arange(space.n_p + 1, dtype=np.int64) * (d * nl)
    return sp.csr_matrix((data, indices, indptr), shape=(space.n_p, space.n_u))


def assemble_load(space: FlowSpace, values: np.ndarray) -> np.ndarray:
    """Load vector ``F[(i, a)] = int f_i phi_a`` from point values of ``f``.

    Parameters
    ----------
    values : (n_cells, nq, dim) float64, ``f`` at ``space.xq``

    Returns
    -------
    (dim * n_v,) float64
    """
    local = np.einsum("cqi,cq,qa->ica", values, space.detJw, space.phi)
    cd = space.V.cell_dofs.ravel()
    return np.concatenate([np.bincount(cd, weights=local[i].ravel(), minlength=space.n_v)
                           for i in range(space.dim)])


def pressure_mean_weights(space: FlowSpace) -> np.ndarray:
    """``int psi_j dx`` for every pressure DOF: (n_p,) float64 (so ``w · p = int p``)."""
    return np.einsum("cq,cqm->cm", space.detJw, space.psi).ravel()


def velocity_coefficients(space: FlowSpace, u: np.ndarray, cells: np.ndarray | None = None) -> np.ndarray:
    """``|det J| w_q u_k`` at every quadrature point, (n_cells, nq, dim) float64: what
    :func:`apply_convection` needs of a convecting velocity ``u`` (dim * n_v,). ``cells`` (m,)
    int64: computed on these cells only, zero on the others (whose memory is never written)."""
    uu = np.ascontiguousarray(u.reshape(space.dim, space.n_v))
    if cells is None:
        return _kernels.velocity_coefficients(uu, space.V.cell_dofs, space.phi, space.detJw)
    return _on_cells(space, cells, _kernels.velocity_coefficients(uu, space.V.cell_dofs[cells], space.phi,
                                                                  space.detJw[cells]))


def _on_cells(space: FlowSpace, cells: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Per-cell ``values`` (m, ...) of ``cells`` (m,) in an array of every cell, zero on the
    others: a few cells' coefficients for the kernels that index them by cell (the pages of the
    others are never written, and the system commits no memory to them)."""
    out = np.zeros((space.mesh.n_cells,) + values.shape[1:], dtype=values.dtype)
    out[cells] = values
    return out


def apply_convection(space: FlowSpace, u: np.ndarray, scale: float, out: np.ndarray,
                     conv: np.ndarray | None = None, cells: np.ndarray | None = None,
                     groups: list[np.ndarray] | None = None) -> None:
    """Add ``scale N(c) u``, ``int phi_a (c · grad) u_i`` per velocity DOF, to ``out``
    (dim * n_v,) float64 in place, without assembling ``N(c)``.

    Parameters
    ----------
    conv : (n_cells, nq, dim) float64, optional: :func:`velocity_coefficients` of the convecting
        velocity ``c``; default ``u`` itself (``N(u) u``)
    cells : (m,) int64, optional: only these cells' contributions (sequentially)
    groups : list of (n_groups, length) int64, optional: only these cells, in parallel groups of
        DOF-disjoint cells (-1 = padding), e.g. :meth:`~fbmflow.fem.space.FlowSpace.cell_groups`;
        default all cells in ``space.colour_groups``
    """
    if cells is not None:
        groups = [np.asarray(cells, dtype=np.int64)[None, :]]
    _apply_cells(space, 0.0, 0.0, scale, u, out, conv, groups)


def _apply_cells(space: FlowSpace, alpha: float, beta: float, gamma: float, u: np.ndarray, out: np.ndarray,
                 conv: np.ndarray | None = None, groups: list[np.ndarray] | None = None) -> None:
    """Add ``(alpha M + beta L + gamma N(c)) u`` to ``out`` (dim * n_v,) in place
    (:func:`~fbmflow.fem._kernels.apply_cell_operator`; ``c`` from ``conv``, default ``u``, whose
    point values the kernel has: no coefficient array, 21 bytes per unknown in 3D)."""
    if conv is None:
        conv = np.zeros((0, 0, 0))
    uu = np.ascontiguousarray(u.reshape(space.dim, space.n_v))
    target = out.reshape(space.dim, space.n_v)
    for batch in space.colour_groups if groups is None else groups:
        _kernels.apply_cell_operator(batch, space.detJw, space.Jinv, space.V.cell_dofs, space.phi, space.dphi,
                                     alpha, beta, gamma, conv, uu, target)


def reaction_coefficients(space: FlowSpace, u: np.ndarray, cells: np.ndarray | None = None) -> np.ndarray:
    """``|det J| w_q d u_i / d x_k`` at every quadrature point, (n_cells, nq, dim, dim) float32
    (a Jacobian's term: half the bytes, ten Cate level 2 67 -> 33 per unknown): what
    :func:`apply_reaction` needs of the velocity ``u`` (dim * n_v,). ``cells`` (m,) int64:
    computed on these cells only, zero on the others (whose memory is never written)."""
    uu = np.ascontiguousarray(u.reshape(space.dim, space.n_v))
    if cells is None:
        return _kernels.reaction_coefficients(uu, space.V.cell_dofs, space.phi, space.dphi, space.detJw,
                                              space.Jinv)
    return _on_cells(space, cells, _kernels.reaction_coefficients(
        uu, space.V.cell_dofs[cells], space.phi, space.dphi, space.detJw[cells], space.Jinv[cells]))


def apply_mass_laplace(space: FlowSpace, alpha: float, beta: float, u: np.ndarray,
                       convection: float = 0.0) -> np.ndarray:
    """``(alpha M + beta L + convection N(u)) u`` per velocity component, by quadrature cell by
    cell in one pass (no matrix): ``u`` (dim * n_v,) -> (dim * n_v,) float64."""
    out = np.zeros(space.dim * space.n_v)
    _apply_cells(space, alpha, beta, convection, u, out)
    return out


def apply_reaction(space: FlowSpace, react: np.ndarray, w: np.ndarray, scale: float, out: np.ndarray,
                   cells: np.ndarray | None = None) -> None:
    """Add ``scale R(u) w`` to ``out`` in place, the Newton term ``R_ik(u)[a, b] = int phi_a phi_b
    d u_i / d x_k`` applied without a matrix (``react``: :func:`reaction_coefficients` of ``u``).

    Parameters
    ----------
    w, out : (dim * n_v,) float64
    cells : (m,) int64, optional: only these cells' contributions (sequentially), e.g. the cells
        where ``w`` is non-zero; default all cells (in parallel).
    """
    ww = np.ascontiguousarray(w.reshape(space.dim, space.n_v))
    target = out.reshape(space.dim, space.n_v)
    batches = space.colour_groups if cells is None else [np.asarray(cells, dtype=np.int64)[None, :]]
    for batch in batches:
        _kernels.apply_reaction(batch, react, space.V.cell_dofs, space.phi, ww, scale, target)
