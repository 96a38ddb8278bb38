"""State of a set of rigid particles (2D: angle about z; 3D: unit quaternion)."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class Particles:
    """Rigid particles, arrays indexed by particle id.

    Attributes
    ----------
    shapes : list of shapes (``inside``, ``volume``, ``inertia``, ``bounding_radius``)
    density : (n,) float64 [kg/m^3]
    position : (n, dim) float64, centres of mass [m]
    velocity : (n, dim) float64 [m/s]
    orientation : (n,) float64 angle [rad] in 2D, (n, 4) unit quaternion (w, x, y, z) in 3D
    angular_velocity : (n,) float64 in 2D, (n, 3) in 3D [rad/s], world frame
    fixed : (n,) bool, particles held still (obstacles)

    The shapes' volumes, inertia tensors and bounding radii are tabulated once (one evaluation per
    distinct shape object) and shared by copies, so nothing loops over particles in Python.
    """

    shapes: list
    density: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    orientation: np.ndarray
    angular_velocity: np.ndarray
    fixed: np.ndarray = field(default=None)
    _table: dict = field(default=None, repr=False, compare=False)

    @classmethod
    def at_rest(cls, shapes: list, density, position) -> "Particles":
        """Particles released from rest with identity orientation."""
        shapes = list(shapes)
        try:
            position = np.atleast_2d(np.asarray(position, dtype=float))
        except (TypeError, ValueError):
            raise ValueError(f"position must be numbers, (n, dim), got {position!r}") from None
        if position.ndim != 2 or position.shape[1] not in (2, 3):
            raise ValueError(f"position must be (n, 2) or (n, 3), one row per particle; got shape "
                             f"{position.shape}")
        n, dim = position.shape
        if len(shapes) != n:
            raise ValueError(f"{len(shapes)} shapes for {n} positions; give one shape per position")
        if not np.all(np.isfinite(position)):
            raise ValueError(f"position has non-finite entries (particles "
                             f"{np.flatnonzero(~np.isfinite(position).all(axis=1)).tolist()})")
        wrong = [k for k, s in enumerate(shapes) if getattr(s, "dim", None) != dim]
        if wrong:
            raise ValueError(f"shape {wrong[0]} ({type(shapes[wrong[0]]).__name__}) is not {dim}D like the "
                             f"positions; make it with dim={dim}")
        try:
            density = np.broadcast_to(np.asarray(density, dtype=float), (n,)).copy()
        except (TypeError, ValueError):
            raise ValueError(f"density must be a number or one per particle ({n}), got {density!r}") from None
        if not np.all(np.isfinite(density) & (density > 0)):
            raise ValueError("particle densities must be positive and finite")
        orientation = np.zeros(n) if dim == 2 else np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
        angular = np.zeros(n) if dim == 2 else np.zeros((n, 3))
        return cls(list(shapes), density, position, np.zeros((n, dim)), orientation, angular,
                   np.zeros(n, dtype=bool))

    def __post_init__(self):
        if self.fixed is None:
            self.fixed = np.zeros(len(self.shapes), dtype=bool)
        if self._table is None:
            self._table = _shape_table(self.shapes)

    @property
    def n(self) -> int:
        return len(self.shapes)

    @property
    def dim(self) -> int:
        return self.position.shape[1]

    @property
    def volume(self) -> np.ndarray:
        """(n,) float64 [m^3] (area in 2D)."""
        return self._table["volume"]

    @property
    def bounding_radius(self) -> np.ndarray:
        """(n,) float64 [m], radius of a ball about each centre of mass containing the shape."""
        return self._table["bounding_radius"]

    @property
    def shape_groups(self) -> tuple[np.ndarray, list]:
        """``(group (n,) int64, distinct shapes)``: particle k has shape ``distinct[group[k]]``."""
        return self._table["group"], self._table["distinct"]

    @property
    def ball_radius(self) -> np.ndarray | None:
        """(n,) float64 [m] when every shape is a :class:`~fbmflow.particles.shapes.Ball`, else None."""
        return self._table["ball_radius"]

    @property
    def mass(self) -> np.ndarray:
        """(n,) float64 [kg]."""
        return self.density * self.volume

    def inertia_world(self) -> np.ndarray:
        """Inertia tensors in world axes: (n, 1, 1) in 2D, (n, 3, 3) in 3D [kg m^2]."""
        body = self._table["inertia"] * self.density[:, None, None]
        if self.dim == 2:
            return body
        R = self.rotations()
        return np.einsum("nij,njk,nlk->nil", R, body, R)

    def rotations(self) -> np.ndarray:
        """Body-to-world rotation matrices, (n, dim, dim) float64."""
        if self.dim == 2:
            c, s = np.cos(self.orientation), np.sin(self.orientation)
            return np.stack([np.stack([c, -s], axis=1), np.stack([s, c], axis=1)], axis=1)
        w, x, y, z = self.orientation.T
        return np.stack([
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], axis=1),
            np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], axis=1),
            np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], axis=1)], axis=1)

    def copy(self) -> "Particles":
        return Particles(list(self.shapes), self.density.copy(), self.position.copy(), self.velocity.copy(),
                         self.orientation.copy(), self.angular_velocity.copy(), self.fixed.copy(),
                         self._table)


def _shape_table(shapes: list) -> dict:
    """Per-particle volume (n,), body inertia per unit density (n, k, k), bounding radius (n,) and,
    if every shape is a ball, the radii (n,); each distinct shape object evaluated once."""
    from .shapes import Ball

    ids = np.array([id(s) for s in shapes], dtype=np.int64)
    uniq, first, inverse = np.unique(ids, return_index=True, return_inverse=True)
    distinct = [shapes[k] for k in first]
    k = 1 if not distinct or distinct[0].dim == 2 else 3
    table = {
        "volume": np.array([s.volume for s in distinct], dtype=float)[inverse],
        "inertia": np.array([s.inertia for s in distinct], dtype=float).reshape(-1, k, k)[inverse],
        "bounding_radius": np.array([s.bounding_radius for s in distinct], dtype=float)[inverse],
        "ball_radius": None,
        "group": inverse.astype(np.int64),   # index of each particle's shape in "distinct"
        "distinct": distinct,
    }
    if all(isinstance(s, Ball) for s in distinct):
        table["ball_radius"] = np.array([s.radius for s in distinct], dtype=float)[inverse]
    return table
