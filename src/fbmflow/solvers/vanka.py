"""Vanka-type smoothers for the Q2/P1disc saddle-point system.

Each cell's DOFs (its ``dim * nl`` velocity and ``dim + 1`` pressure unknowns) get a correction
from the local saddle-point problem driven by the current residual. Cells are visited class by
class (:attr:`FlowSpace.vanka_classes`: cell indices modulo 3, so no cell's residual involves the
DOFs of another cell of its class): the cells of a class are updated in parallel, and the sweep
equals a sequential block Gauss–Seidel sweep in class order, whatever the number of threads.

Variants (a registry):

* ``vanka-full``: the full local block ``[[A_cc, B_c], [B_c^T, 0]]`` solved by LU (21 x 21 in 2D,
  85 x 85 in 3D); robust for convection-dominated Oseen/Newton systems.
* ``vanka-diagonal``: ``A_cc`` replaced by its diagonal and solved through the
  ``(dim+1) x (dim+1)`` Schur complement, precomputed per cell; cheap, for Stokes-like systems.
"""
from __future__ import annotations

import numpy as np

from . import _kernels
from .linear import SaddlePointSystem, cell_blocks


class VankaSmoother:
    """Cell-wise Vanka smoother on one level.

    Parameters
    ----------
    system : SaddlePointSystem with ``space`` set
    variant : "vanka-full" or "vanka-diagonal"
    omega : float, damping of the corrections
    """

    def __init__(self, system: SaddlePointSystem, variant: str = "vanka-full", omega: float = 1.0):
        if variant not in VANKA_VARIANTS:
            raise ValueError(f"unknown smoother {variant!r}; choose one of {sorted(VANKA_VARIANTS)}")
        self.variant = variant
        self.omega = omega
        self.system = system
        space = system.space
        self.space = space
        B = system.BT.T.tocsr()
        self._b = (B.indptr.astype(np.int64), B.indices.astype(np.int64), B.data)
        nb = system.A.data.size // (space.dim * space.nnz)  # blocks per row: dim or 1
        npl = space.dim + 1
        pblock = cell_blocks(system.orphans, space.mesh.n_cells, npl)  # cluster modes: cell parts only
        self._common = (space.dim, nb, space.n_v, space.indptr, space.indices, system.A.data,
                        *self._b, system.BT.data, space.local_rank, space.V.cell_dofs, pblock)
        if variant == "vanka-diagonal":
            diag = system.A.diagonal()
            diag_inv = np.where(diag != 0.0, 1.0 / np.where(diag != 0.0, diag, 1.0), 0.0)
            S = _kernels.schur_diagonal(system.BT.data, space.local_rank, space.V.cell_dofs,
                                        diag_inv, space.dim, space.n_v)
            self._extra = (diag_inv, np.linalg.pinv(S + pblock, rcond=1e-12, hermitian=True))
        else:
            self._extra = (space.slots,)

    def update(self, cells: np.ndarray, b: np.ndarray, x: np.ndarray, omega: float | None = None) -> None:
        """Add ``omega`` times the local corrections of ``cells`` (one class) to ``x``."""
        kernel = _kernels.vanka_full if self.variant == "vanka-full" else _kernels.vanka_diagonal
        kernel(cells, b, x, self.omega if omega is None else omega, *self._common, *self._extra)

    def smooth(self, b: np.ndarray, x: np.ndarray, sweeps: int) -> None:
        """``sweeps`` smoothing sweeps on ``K x = b``, updating ``x`` in place."""
        for _ in range(sweeps):
            for cells in self.space.vanka_classes:
                self.update(cells, b, x)


VANKA_VARIANTS = {"vanka-full": 0.7, "vanka-diagonal": 0.7}  # name -> default damping
