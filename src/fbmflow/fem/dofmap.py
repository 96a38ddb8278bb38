"""DOF maps of the Q2 velocity and P1disc pressure spaces on a structured mesh.

Q2 nodes of a structured mesh form a lattice with ``2 n + 1`` points per axis (``2 n`` on a
periodic axis, where index ``2 n`` is identified with 0). Cell ``(a, b[, c])`` owns the lattice
points ``(2a + i, 2b + j[, 2c + k])``, ``i, j, k in {0, 1, 2}``. Lattice point ``(I, J[, K])`` is
DOF ``I + L_x (J + L_y K)``. P1disc DOFs are cell-local: DOF ``m`` of cell ``c`` is
``c (dim + 1) + m``.
"""
from __future__ import annotations

from functools import cached_property

import numpy as np

from ..mesh import StructuredMesh, q1_basis
from ..mesh.structured import AXES
from .elements import ElementP1Disc, ElementQ2


class DofMap:
    """Q2 DOF map of a :class:`~fbmflow.mesh.structured.StructuredMesh`, periodic directions identified.

    Attributes
    ----------
    cell_dofs : (n_cells, 3**dim) int64
        Global DOF of every local node.
    lattice_shape : tuple of int
        Lattice points per axis (``2 n + 1``, or ``2 n`` when periodic).
    n_dofs : int
    """

    def __init__(self, mesh: StructuredMesh):
        self.mesh = mesh
        self.element = ElementQ2(mesh.dim)
        self.lattice_shape = tuple(2 * n if p else 2 * n + 1 for n, p in zip(mesh.shape, mesh.periodic))
        self.n_dofs = int(np.prod(self.lattice_shape))
        lat = 2 * mesh.cell_indices()[:, None, :] + self.element.local_index[None, :, :]
        self.cell_dofs = self._lattice_to_dof(lat)

    def _lattice_to_dof(self, lat: np.ndarray) -> np.ndarray:
        shape = np.array(self.lattice_shape)
        lat = lat % shape  # identifies periodic sides; no-op elsewhere (indices < shape)
        strides = np.cumprod((1,) + self.lattice_shape[:-1])
        return (lat * strides).sum(axis=-1).astype(np.int64)

    @cached_property
    def lattice(self) -> np.ndarray:
        """Lattice multi-index of every DOF, (n_dofs, dim) int64."""
        return np.indices(self.lattice_shape).reshape(self.mesh.dim, -1, order="F").T.copy()

    @cached_property
    def lattice_axes(self) -> tuple[np.ndarray, ...]:
        """Node coordinates per axis of a tensor-product mesh (vertices and cell midpoints),
        ``(lattice_shape[d],)`` each; ValueError on a deformed mesh."""
        axes = self.mesh.axis_coordinates
        if axes is None:
            raise ValueError("lattice axes need a tensor-product (uniform or rectilinear) mesh")
        out = []
        for a, m in zip(axes, self.lattice_shape):
            nodes = np.empty(2 * a.size - 1)
            nodes[0::2], nodes[1::2] = a, 0.5 * (a[:-1] + a[1:])
            out.append(nodes[:m])
        return tuple(out)

    @cached_property
    def coordinates(self) -> np.ndarray:
        """Physical coordinates of every DOF, (n_dofs, dim) float64 (lower side if periodic)."""
        mesh = self.mesh
        lat = self.lattice
        cell = np.minimum(lat // 2, np.array(mesh.shape) - 1)
        xi = (lat - 2 * cell).astype(float) - 1.0
        strides = np.cumprod((1,) + mesh.shape[:-1])
        cell_id = (cell * strides).sum(axis=1)
        coords = mesh.vertices[mesh.cell_vertices[cell_id]]
        return np.einsum("pv,pvd->pd", q1_basis(xi), coords)

    def boundary_dofs(self, tag: str) -> np.ndarray:
        """DOFs on the box face ``tag``, (n,) int64 sorted."""
        axis, side = self.mesh._parse_tag(tag)
        target = 0 if side == "min" else self.lattice_shape[axis] - 1
        return np.flatnonzero(self.lattice[:, axis] == target)

    def all_boundary_dofs(self) -> np.ndarray:
        """DOFs on any non-periodic box face, (n,) int64 sorted."""
        return np.unique(np.concatenate([self.boundary_dofs(t) for t in self.mesh.tags]
                                        or [np.zeros(0, np.int64)]))

    def __repr__(self) -> str:
        axes = "x".join(str(n) for n in self.lattice_shape)
        per = "".join(AXES[d] for d in range(self.mesh.dim) if self.mesh.periodic[d])
        return f"DofMap(Q2, lattice {axes}, n_dofs={self.n_dofs}, periodic='{per}')"


class PressureDofMap:
    """P1disc DOF map: ``dim + 1`` cell-local DOFs, DOF ``c (dim + 1) + m``."""

    def __init__(self, mesh: StructuredMesh):
        self.mesh = mesh
        self.element = ElementP1Disc(mesh.dim)
        self.n_local = mesh.dim + 1
        self.n_dofs = mesh.n_cells * self.n_local
        self.cell_dofs = np.arange(self.n_dofs, dtype=np.int64).reshape(mesh.n_cells, self.n_local)
        self.centre, self.scale = ElementP1Disc.frame(mesh.cell_coordinates())
