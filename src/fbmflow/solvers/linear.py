"""Linear solvers for the Newton/Oseen saddle-point systems, behind one interface.

A :class:`SaddlePointSystem` holds the blocks of

    [ A   B ] [du]   [f]
    [ B^T 0 ] [dp] = [g]      (+ the border  w . dp = 0  when the pressure is fixed by its mean)

and a linear solver is any object with ``solve(system, f, g) -> (du, dp, LinearReport)``.
Solvers are registered by name in :data:`LINEAR_SOLVERS`; the multigrid solver plugs in here.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla


@dataclass
class SaddlePointSystem:
    """Blocks of one linearised system.

    A : (n_u, n_u) CSR, constrained rows already unit rows
    BT : (n_p, n_u) CSR, constrained columns zeroed; ``B = BT.T``
    mean_weights : (n_p,) float64 or None, border row fixing ``int p = 0``
    fixed : (n_c,) int64 or None, the constrained velocity DOFs (unit rows of ``A``); solvers
        may eliminate them (their solution is the right-hand side there)
    space : FlowSpace or None, the discretisation (cell structure for cell-wise smoothers)
    coarser : SaddlePointSystem or None, the same operator re-discretised on the next coarser mesh
    prolongation : (P_v, P_p) or None, scalar Q2 (n_v x n_v_coarse) and P1disc (n_p x n_p_coarse)
        prolongations from ``coarser`` to this level
    pressure_block : (n_cells, dim+1, dim+1) float64 or None, cell-wise pressure-pressure block
        ``C``: the projector onto the pressure modes of a cell that no free velocity DOF sees any
        more (cells inside or almost inside a fictitious boundary). Those modes would make the
        system singular; ``C`` sets them to ``g`` (zero for Newton updates) and leaves every
        other unknown unchanged. Computed from ``B^T`` when ``space`` is given.
    """

    A: sp.csr_matrix
    BT: sp.csr_matrix
    mean_weights: np.ndarray | None = None
    fixed: np.ndarray | None = None
    space: object = None
    coarser: "SaddlePointSystem | None" = None
    prolongation: tuple | None = None
    pressure_block: np.ndarray | None = None

    def __post_init__(self):
        if self.pressure_block is None and self.space is not None:
            self.pressure_block = orphan_pressure_block(self.BT, self.space.dim + 1)

    @property
    def n_u(self) -> int:
        return self.A.shape[0]

    @property
    def n_p(self) -> int:
        return self.BT.shape[0]

    def apply(self, x: np.ndarray) -> np.ndarray:
        """``K x`` for ``x = [u, p]`` (n_u + n_p,), without the border row."""
        u, p = x[:self.n_u], x[self.n_u:]
        q = self.BT @ u
        if self.pressure_block is not None:
            npl = self.pressure_block.shape[1]
            q += np.einsum("cmn,cn->cm", self.pressure_block, p.reshape(-1, npl)).ravel()
        return np.concatenate([self.A @ u + self.BT.T @ p, q])

    def remove_pressure_mean(self, x: np.ndarray) -> None:
        """Shift the pressure part of ``x`` in place so that ``mean_weights . p = 0`` (no-op when
        the pressure is determined)."""
        if self.mean_weights is None:
            return
        p = x[self.n_u:]
        const = np.zeros(self.n_p)
        const[::self.space.dim + 1] = 1.0  # the constant pressure: mean DOFs of P1disc
        p -= np.multiply.outer(const, self.mean_weights @ p) / (self.mean_weights @ const)

    def matrix(self, bordered: bool = True) -> sp.csc_matrix:
        """The assembled system matrix, CSC, bordered by ``mean_weights`` unless ``bordered`` is
        False."""
        C = None
        if self.pressure_block is not None and np.any(self.pressure_block):
            C = sp.block_diag(list(self.pressure_block), format="csr")
        blocks = [[self.A, self.BT.T], [self.BT, C]]
        if bordered and self.mean_weights is not None:
            w = sp.csr_matrix(self.mean_weights[None, :])
            blocks = [[self.A, self.BT.T, None], [self.BT, C, w.T], [None, w, None]]
        return sp.bmat(blocks, format="csc")


def orphan_pressure_block(BT: sp.csr_matrix, npl: int, tol: float = 1e-10) -> np.ndarray | None:
    """Projectors onto the pressure modes of each cell that ``B^T`` (constrained columns zeroed)
    no longer couples to any velocity: (n_cells, npl, npl) float64, or None when there are none.

    The rows of ``B^T`` are cell-local with ``dim nl`` entries each, so the local blocks are a
    reshape; only cells with zeroed entries are examined (batched SVD)."""
    n_cells = BT.shape[0] // npl
    Bc = BT.data.reshape(n_cells, npl, -1)
    suspect = np.flatnonzero((Bc == 0.0).all(axis=1).any(axis=1))  # cells with a zeroed column
    if suspect.size == 0:
        return None
    U, sv, _ = np.linalg.svd(Bc[suspect], full_matrices=False)  # U (n, npl, npl), sv (n, npl)
    scale = np.abs(Bc).max()
    null = sv <= tol * scale
    if not null.any():
        return None
    C = np.zeros((n_cells, npl, npl))
    C[suspect] = np.einsum("cmk,ck,cnk->cmn", U, null.astype(float), U)
    return C


@dataclass
class LinearReport:
    """Work done by one linear solve."""

    solver: str
    wall_time_s: float
    iterations: int = 0
    residuals: list[float] = field(default_factory=list)
    smoothing_sweeps: int = 0
    setup_time_s: float = 0.0


def factorize(system: SaddlePointSystem):
    """Sparse LU of the saddle-point matrix with the constrained velocity DOFs eliminated; returns
    ``solve(f, g) -> (u, p)``.

    When the pressure is determined only up to a constant (``mean_weights`` given), the constant
    mode of one cell is pinned to zero instead of bordering the matrix with the dense row
    ``mean_weights``: the dense row would fill the LU factors completely (measured: 76 M non-zeros
    instead of a few M for 33 000 unknowns). The mean is removed afterwards, which gives the
    bordered system's solution for compatible data.
    """
    K = system.matrix(bordered=False).tocsr()
    n = K.shape[0]
    free = np.ones(n, dtype=bool)
    if system.fixed is not None:
        free[system.fixed] = False
    pinned = system.n_u + _pinned_pressure(system) if system.mean_weights is not None else None
    if pinned is not None:
        free[pinned] = False
    K_free = K[free]
    coupling = K_free[:, ~free]
    lu = spla.splu(K_free[:, free].tocsc(), permc_spec="COLAMD", diag_pivot_thresh=0.01)

    def solve(f, g):  # (n_u,), (n_p,) or, for k right-hand sides at once, (n_u, k), (n_p, k)
        x = np.concatenate([f, g])
        if pinned is not None:
            x[pinned] = 0.0
        x[free] = lu.solve(x[free] - coupling @ x[~free])
        if not np.all(np.isfinite(x)):
            raise np.linalg.LinAlgError("direct solve produced non-finite values (singular system?)")
        system.remove_pressure_mean(x)
        return x[:system.n_u], x[system.n_u:]

    return solve


def _pinned_pressure(system: SaddlePointSystem) -> int:
    """Pressure DOF (constant mode of a cell) to pin: the first cell whose pressure still couples
    to free velocities."""
    npl = system.space.dim + 1 if system.space is not None else 1
    if system.pressure_block is None:
        return 0
    seen = np.flatnonzero(~system.pressure_block.any(axis=(1, 2)))
    return int(seen[0]) * npl


class DirectSolver:
    """Sparse LU (SuperLU, COLAMD ordering, threshold pivoting 0.01 so that the ordering survives)
    of the saddle-point matrix with the constrained velocity DOFs eliminated; for small and medium
    problems (2D: up to a few 10^5 unknowns, 3D: a few 10^4)."""

    name = "direct"
    needs_hierarchy = False

    def factor(self, system: SaddlePointSystem):
        """Factorise ``system`` once; returns ``solve(f, g) -> (u, p, LinearReport)``."""
        t0 = time.perf_counter()
        direct = factorize(system)
        pending = [time.perf_counter() - t0]  # the set-up time, charged to the first solve only

        def solve(f, g):
            t1 = time.perf_counter()
            u, p = direct(f, g)
            setup = pending.pop() if pending else 0.0
            return u, p, LinearReport(self.name, setup + time.perf_counter() - t1, iterations=1,
                                      setup_time_s=setup)
        solve.multiple_rhs = True  # f (n_u, k) and g (n_p, k) solve k systems in one call
        return solve

    def solve(self, system: SaddlePointSystem, f: np.ndarray, g: np.ndarray):
        return self.factor(system)(f, g)
