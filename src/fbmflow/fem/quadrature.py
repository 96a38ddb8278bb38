"""Tensor-product Gauss–Legendre rules on the reference cell ``[-1, 1]^dim``."""
from __future__ import annotations

import numpy as np


def gauss_tensor(dim: int, n_1d: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss rule with ``n_1d`` points per axis (exact for degree ``2 n_1d - 1`` per axis).

    Returns
    -------
    points : (n_1d**dim, dim) float64, x fastest
    weights : (n_1d**dim,) float64, summing to ``2**dim``
    """
    x, w = np.polynomial.legendre.leggauss(n_1d)
    grids = np.meshgrid(*([x] * dim), indexing="ij")
    wgrids = np.meshgrid(*([w] * dim), indexing="ij")
    points = np.stack([g.ravel(order="F") for g in grids], axis=1)
    weights = np.prod(np.stack([g.ravel(order="F") for g in wgrids], axis=1), axis=1)
    return points, weights
