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
    """

    A: sp.csr_matrix
    BT: sp.csr_matrix
    mean_weights: np.ndarray | None = None
    fixed: np.ndarray | None = None

    @property
    def n_u(self) -> int:
        return self.A.shape[0]

    @property
    def n_p(self) -> int:
        return self.BT.shape[0]

    def matrix(self) -> sp.csc_matrix:
        """The assembled (bordered) system matrix, CSC."""
        blocks = [[self.A, self.BT.T], [self.BT, None]]
        if self.mean_weights is not None:
            w = sp.csr_matrix(self.mean_weights[None, :])
            blocks = [[self.A, self.BT.T, None], [self.BT, None, w.T], [None, w, None]]
        return sp.bmat(blocks, format="csc")


@dataclass
class LinearReport:
    """Work done by one linear solve."""

    solver: str
    wall_time_s: float
    iterations: int = 0
    residuals: list[float] = field(default_factory=list)


class DirectSolver:
    """Sparse LU (SuperLU, COLAMD ordering) of the saddle-point matrix with the constrained
    velocity DOFs eliminated; for small and medium problems (3D: up to a few 10^4 unknowns)."""

    name = "direct"

    def solve(self, system: SaddlePointSystem, f: np.ndarray, g: np.ndarray):
        t0 = time.perf_counter()
        K = system.matrix().tocsr()
        rhs = np.concatenate([f, g] + ([np.zeros(1)] if system.mean_weights is not None else []))
        x = rhs.copy()
        if system.fixed is not None and system.fixed.size:
            free = np.ones(K.shape[0], dtype=bool)
            free[system.fixed] = False
            K_free = K[free]
            b = rhs[free] - K_free[:, system.fixed] @ rhs[system.fixed]
            x[free] = spla.splu(K_free[:, free].tocsc(), permc_spec="COLAMD").solve(b)
        else:
            x = spla.splu(K.tocsc(), permc_spec="COLAMD").solve(rhs)
        if not np.all(np.isfinite(x)):
            raise np.linalg.LinAlgError("direct solve produced non-finite values (singular system?)")
        report = LinearReport(self.name, time.perf_counter() - t0, iterations=1)
        return x[:system.n_u], x[system.n_u:system.n_u + system.n_p], report


LINEAR_SOLVERS = {"direct": DirectSolver}


def make_linear_solver(name: str):
    """Instantiate a registered linear solver by name."""
    try:
        return LINEAR_SOLVERS[name]()
    except KeyError:
        raise ValueError(f"unknown linear solver {name!r}; choose one of {sorted(LINEAR_SOLVERS)}") from None
