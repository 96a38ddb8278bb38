"""Reference elements: Q1 (geometry), Q2 (velocity) and P1disc (pressure).

Q1 and Q2 live on the reference cell ``[-1, 1]^dim`` with local nodes in lexicographic order,
x fastest (Q2: node ``(i, j[, k])``, ``i, j, k in {0, 1, 2}`` at ``xi = i - 1``, local index
``i + 3 j + 9 k``). P1disc is *unmapped*: its basis is linear in the physical coordinates,

    psi_0 = 1,   psi_l = (x_l - c_l) / s_l,   l = 1..dim,

with ``c`` the cell centroid (mean of the vertices) and ``s_l`` the half extent of the cell along
axis ``l``; it therefore keeps full order on deformed cells.
"""
from __future__ import annotations

import numpy as np


def _lagrange_1d(degree: int, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """1D Lagrange basis on equidistant nodes of [-1, 1] -> values, derivatives (n, degree+1)."""
    if degree == 1:
        v = np.stack([0.5 * (1 - x), 0.5 * (1 + x)], axis=1)
        d = np.stack([-0.5 * np.ones_like(x), 0.5 * np.ones_like(x)], axis=1)
    elif degree == 2:
        v = np.stack([0.5 * x * (x - 1), 1 - x * x, 0.5 * x * (x + 1)], axis=1)
        d = np.stack([x - 0.5, -2 * x, x + 0.5], axis=1)
    else:
        raise ValueError(f"degree {degree} not supported")
    return v, d


class ElementQk:
    """Tensor-product Lagrange element of degree ``k`` (1 or 2) on ``[-1, 1]^dim``."""

    def __init__(self, dim: int, degree: int):
        self.dim = dim
        self.degree = degree
        self.n_local = (degree + 1) ** dim
        idx = np.indices((degree + 1,) * dim).reshape(dim, -1, order="F").T
        self.local_index = idx  # (n_local, dim) node multi-index
        self.nodes = idx * (2.0 / degree) - 1.0  # (n_local, dim)

    def tabulate(self, xi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Basis values and reference gradients at ``xi (n, dim)``.

        Returns
        -------
        phi : (n, n_local) float64
        dphi : (n, n_local, dim) float64, derivatives with respect to ``xi``
        """
        xi = np.atleast_2d(np.asarray(xi, dtype=float))
        n = xi.shape[0]
        vals, ders = zip(*(_lagrange_1d(self.degree, xi[:, d]) for d in range(self.dim)))
        phi = np.ones((n, self.n_local))
        dphi = np.ones((n, self.n_local, self.dim))
        for d in range(self.dim):
            v_d = vals[d][:, self.local_index[:, d]]
            g_d = ders[d][:, self.local_index[:, d]]
            phi *= v_d
            for e in range(self.dim):
                dphi[:, :, e] *= g_d if e == d else v_d
        return phi, dphi


class ElementQ2(ElementQk):
    """Biquadratic / triquadratic velocity element (9 / 27 nodes)."""

    def __init__(self, dim: int):
        super().__init__(dim, 2)


class ElementQ1(ElementQk):
    """Multilinear geometry element (4 / 8 vertices)."""

    def __init__(self, dim: int):
        super().__init__(dim, 1)


class ElementP1Disc:
    """Discontinuous linear pressure in physical coordinates (3 / 4 DOFs per cell)."""

    def __init__(self, dim: int):
        self.dim = dim
        self.n_local = dim + 1

    @staticmethod
    def frame(cell_coords: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Centroid and half extents of cells, ``cell_coords (n_cells, n_vertices, dim)``.

        Returns centre (n_cells, dim) and scale (n_cells, dim), both float64.
        """
        centre = cell_coords.mean(axis=1)
        scale = 0.5 * (cell_coords.max(axis=1) - cell_coords.min(axis=1))
        return centre, scale

    def tabulate(self, x: np.ndarray, centre: np.ndarray, scale: np.ndarray) -> np.ndarray:
        """Basis values at physical points ``x (..., dim)`` of cells with the given frame.

        ``centre`` and ``scale`` broadcast against ``x``. Returns (..., dim + 1) float64.
        """
        rel = (x - centre) / scale
        return np.concatenate([np.ones(rel.shape[:-1] + (1,)), rel], axis=-1)
