"""Rigid particle shapes, in body coordinates, knowing nothing of meshes.

Every shape is described relative to its **centre of mass** in body axes and gives

* ``inside(x)``: vectorised inside test on points ``x (n, dim)`` -> ``(n,) bool``;
* ``volume``: volume [m^3] (area [m^2] in 2D);
* ``inertia``: inertia tensor per unit density in body axes, ``int (|x|^2 I - x x^T) dV``
  ((3, 3) in 3D; in 2D the polar moment ``int (x^2 + y^2) dA`` as a (1, 1) array);
* ``bounding_radius``: radius of a ball about the centre of mass that contains the shape;
* ``support(d)``: for directions ``d (n, dim)`` (body axes, any length) the points of the shape
  farthest along them, ``(n, dim)``, for contact detection (exact for the convex analytic shapes
  and for the vertices of a surface; the bounding ball for an implicit shape);
* ``project(x)`` (the analytic shapes: ball, box, cylinder): for points ``x (n, dim)`` inside
  the shape, the closest points of its surface and the outward unit normals there, both
  ``(n, dim)`` (for the sharp fictitious boundary);
* ``centre_of_mass``: where the centre of mass lies in the coordinates the user described the
  shape in (zero for the symmetric shapes; computed for implicit functions and surfaces, whose
  ``inside`` is then shifted so that it works relative to the centre of mass).

Shapes: :class:`Ball` (disk/sphere), :class:`Ellipsoid` (ellipse/ellipsoid), :class:`Box`
(rectangle/box), :class:`ImplicitShape` (a user's vectorised signed distance or inside test) and
:class:`TriangulatedSurface` (a closed triangle surface, e.g. from an STL/OBJ/PLY file).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from . import _kernels


def _check_dim(dim: int):
    if dim not in (2, 3):
        raise ValueError(f"dim must be 2 or 3, got {dim}")


def _unit(d: np.ndarray) -> np.ndarray:
    d = np.asarray(d, dtype=float)
    return d / np.maximum(np.linalg.norm(d, axis=-1, keepdims=True), 1e-300)


def _axes_inertia(volume: float, second_moments: np.ndarray) -> np.ndarray:
    """Inertia per unit density from the diagonal second moments ``int x_k^2 dV`` (``dim,``)."""
    m = np.asarray(second_moments, dtype=float)
    if m.size == 2:
        return np.array([[m.sum()]])
    return np.diag(m.sum() - m)


@dataclass(frozen=True)
class Ball:
    """Disk (``dim = 2``) or sphere (``dim = 3``) of the given radius [m]."""

    radius: float
    dim: int = 2

    def __post_init__(self):
        if not self.radius > 0:
            raise ValueError(f"radius must be positive, got {self.radius}")
        _check_dim(self.dim)

    def inside(self, x: np.ndarray) -> np.ndarray:
        """Points ``x (n, dim)`` (body frame) inside or on the surface -> (n,) bool."""
        return np.einsum("ij,ij->i", x, x) <= self.radius**2

    def support(self, d: np.ndarray) -> np.ndarray:
        return self.radius * _unit(d)

    def project(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Closest surface points ``r x / |x|`` and normals ``x / |x|`` (the centre itself goes
        along the first axis)."""
        x = np.array(x, dtype=float)
        x[np.all(x == 0.0, axis=1), 0] = 1.0
        n = _unit(x)
        return self.radius * n, n

    @property
    def bounding_radius(self) -> float:
        return self.radius

    @property
    def centre_of_mass(self) -> np.ndarray:
        return np.zeros(self.dim)

    @property
    def volume(self) -> float:
        r = self.radius
        return np.pi * r**2 if self.dim == 2 else 4.0 / 3.0 * np.pi * r**3

    @property
    def inertia(self) -> np.ndarray:
        """Inertia per unit density: ``pi r^4 / 2`` (disk, 1 x 1) or ``8 pi r^5 / 15 I`` (sphere)."""
        r = self.radius
        if self.dim == 2:
            return np.array([[np.pi * r**4 / 2.0]])
        return np.eye(3) * (8.0 * np.pi * r**5 / 15.0)


@dataclass(frozen=True)
class Ellipsoid:
    """Ellipse (two semi-axes) or ellipsoid (three semi-axes) ``sum (x_k / a_k)^2 <= 1`` [m],
    semi-axis ``k`` along body axis ``k``."""

    semi_axes: tuple

    def __post_init__(self):
        a = np.asarray(self.semi_axes, dtype=float)
        _check_dim(a.size)
        if not np.all(a > 0):
            raise ValueError(f"semi-axes must be positive, got {self.semi_axes}")
        object.__setattr__(self, "semi_axes", tuple(float(v) for v in a))

    @property
    def dim(self) -> int:
        return len(self.semi_axes)

    def inside(self, x: np.ndarray) -> np.ndarray:
        return np.sum((x / np.array(self.semi_axes)) ** 2, axis=1) <= 1.0

    def support(self, d: np.ndarray) -> np.ndarray:
        """``A^2 d / |A d|`` with ``A = diag(a)``."""
        a = np.array(self.semi_axes)
        return a * _unit(a * d)

    @property
    def bounding_radius(self) -> float:
        return max(self.semi_axes)

    @property
    def centre_of_mass(self) -> np.ndarray:
        return np.zeros(self.dim)

    @property
    def volume(self) -> float:
        p = float(np.prod(self.semi_axes))
        return np.pi * p if self.dim == 2 else 4.0 / 3.0 * np.pi * p

    @property
    def inertia(self) -> np.ndarray:
        """``int x_k^2 dV = V a_k^2 / 4`` (ellipse) or ``V a_k^2 / 5`` (ellipsoid)."""
        a2 = np.array(self.semi_axes) ** 2
        return _axes_inertia(self.volume, self.volume * a2 / (4.0 if self.dim == 2 else 5.0))


@dataclass(frozen=True)
class Box:
    """Rectangle (``dim = 2``) or box (``dim = 3``) ``|x_k| <= h_k`` with half-extents ``h`` [m]."""

    half_extents: tuple

    def __post_init__(self):
        h = np.asarray(self.half_extents, dtype=float)
        _check_dim(h.size)
        if not np.all(h > 0):
            raise ValueError(f"half-extents must be positive, got {self.half_extents}")
        object.__setattr__(self, "half_extents", tuple(float(v) for v in h))

    @property
    def dim(self) -> int:
        return len(self.half_extents)

    def inside(self, x: np.ndarray) -> np.ndarray:
        return np.all(np.abs(x) <= np.array(self.half_extents), axis=1)

    def support(self, d: np.ndarray) -> np.ndarray:
        return np.where(d >= 0.0, 1.0, -1.0) * np.array(self.half_extents)

    def project(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Closest surface points of inside points: onto the nearest face, ``x_k = +-h_k`` for
        the axis ``k`` of least ``h_k - |x_k|``; normals ``+-e_k``."""
        x = np.asarray(x, dtype=float)
        k = np.argmin(np.array(self.half_extents) - np.abs(x), axis=1)
        rows = np.arange(len(x))
        sign = np.where(x[rows, k] >= 0.0, 1.0, -1.0)
        p, n = x.copy(), np.zeros_like(x)
        p[rows, k] = sign * np.array(self.half_extents)[k]
        n[rows, k] = sign
        return p, n

    @property
    def bounding_radius(self) -> float:
        return float(np.linalg.norm(self.half_extents))

    @property
    def centre_of_mass(self) -> np.ndarray:
        return np.zeros(self.dim)

    @property
    def volume(self) -> float:
        return float(np.prod(2.0 * np.array(self.half_extents)))

    @property
    def inertia(self) -> np.ndarray:
        """``int x_k^2 dV = V h_k^2 / 3``."""
        return _axes_inertia(self.volume, self.volume * np.array(self.half_extents) ** 2 / 3.0)


@dataclass(frozen=True)
class Cylinder:
    """Circular cylinder (3D) ``x^2 + y^2 <= r^2, |z| <= L / 2`` [m], axis along body axis z."""

    radius: float
    length: float

    def __post_init__(self):
        if not (self.radius > 0 and self.length > 0):
            raise ValueError(f"radius and length must be positive, got {self.radius}, {self.length}")

    dim = 3

    def inside(self, x: np.ndarray) -> np.ndarray:
        return (x[:, 0] ** 2 + x[:, 1] ** 2 <= self.radius**2) & (np.abs(x[:, 2]) <= self.length / 2.0)

    def support(self, d: np.ndarray) -> np.ndarray:
        """Rim point: the disk's support in the x-y plane plus ``sign(d_z) L / 2`` along z."""
        d = np.asarray(d, dtype=float)
        s = np.zeros_like(d)
        s[..., :2] = self.radius * _unit(d[..., :2])
        s[..., 2] = np.where(d[..., 2] >= 0.0, 0.5, -0.5) * self.length
        return s

    def project(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Closest surface points of inside points: radially onto the mantle, or onto the nearer
        cap where that is closer."""
        x = np.asarray(x, dtype=float)
        radial = np.array(x[:, :2])
        radial[np.all(radial == 0.0, axis=1), 0] = 1.0
        radial = _unit(radial)
        to_mantle = self.radius - np.hypot(x[:, 0], x[:, 1])
        to_cap = self.length / 2.0 - np.abs(x[:, 2])
        cap = to_cap < to_mantle
        p, n = x.copy(), np.zeros_like(x)
        p[:, :2] = np.where(cap[:, None], x[:, :2], self.radius * radial)
        n[:, :2] = np.where(cap[:, None], 0.0, radial)
        sign = np.where(x[:, 2] >= 0.0, 1.0, -1.0)
        p[cap, 2] = sign[cap] * self.length / 2.0
        n[cap, 2] = sign[cap]
        return p, n

    @property
    def bounding_radius(self) -> float:
        return float(np.hypot(self.radius, self.length / 2.0))

    @property
    def centre_of_mass(self) -> np.ndarray:
        return np.zeros(3)

    @property
    def volume(self) -> float:
        return float(np.pi * self.radius**2 * self.length)

    @property
    def inertia(self) -> np.ndarray:
        """``int x^2 dV = int y^2 dV = V r^2 / 4``, ``int z^2 dV = V L^2 / 12``."""
        r2, l2 = self.radius**2, self.length**2
        return _axes_inertia(self.volume, self.volume * np.array([r2 / 4.0, r2 / 4.0, l2 / 12.0]))


def _lattice_moments(inside: Callable, lower: np.ndarray, upper: np.ndarray, n: int):
    """Volume, first and second moments of ``{inside}`` by the midpoint rule on an ``n^dim``
    lattice over the box ``[lower, upper]``; evaluated slab by slab to bound memory."""
    dim = lower.size
    h = (upper - lower) / n
    axes = [lower[k] + (np.arange(n) + 0.5) * h[k] for k in range(dim)]
    cell = float(np.prod(h))
    vol, first, second = 0.0, np.zeros(dim), np.zeros((dim, dim))
    rest = np.stack([g.ravel() for g in np.meshgrid(*axes[1:], indexing="ij")], axis=1)
    for x0 in axes[0]:
        pts = np.column_stack([np.full(len(rest), x0), rest])
        p = pts[np.asarray(inside(pts), dtype=bool)]
        vol += cell * len(p)
        first += cell * p.sum(axis=0)
        second += cell * p.T @ p
    return vol, first, second


def _inertia_from_moments(vol: float, com: np.ndarray, second: np.ndarray) -> np.ndarray:
    """Inertia per unit density about the centre of mass from ``int x x^T dV`` about the origin."""
    c = second - vol * np.outer(com, com)
    if com.size == 2:
        return np.array([[np.trace(c)]])
    return np.trace(c) * np.eye(3) - c


@dataclass(frozen=True)
class ImplicitShape:
    """A shape given by the user's vectorised function of points ``x (n, dim)`` in body axes.

    ``function`` returns either a float array that is ``<= 0`` inside (a signed distance or any
    level-set function, ``kind = "level-set"``) or a bool array that is True inside
    (``kind = "inside"``). ``extent`` is the half-width of a box about the origin that contains the
    shape. Volume, centre of mass and inertia are computed once by the midpoint rule on a
    ``resolution^dim`` lattice over that box (relative error about ``1 / resolution`` for a
    shape with a sharp boundary); pass ``volume`` and ``inertia`` when you know them exactly.
    """

    function: Callable
    dim: int
    extent: float
    kind: str = "level-set"
    resolution: int = 0
    volume: float = None
    inertia: np.ndarray = None
    centre_of_mass: np.ndarray = field(default=None)
    bounding_radius: float = field(default=None, init=False)

    def __post_init__(self):
        _check_dim(self.dim)
        if not callable(self.function):
            raise ValueError("function must be callable: f(x (n, dim)) -> (n,) values")
        if self.kind not in ("level-set", "inside"):
            raise ValueError(f"kind must be 'level-set' or 'inside', got {self.kind!r}")
        if not self.extent > 0:
            raise ValueError(f"extent must be positive, got {self.extent}")
        res = self.resolution or (800 if self.dim == 2 else 160)
        lo, hi = -np.full(self.dim, float(self.extent)), np.full(self.dim, float(self.extent))
        vol, first, second = _lattice_moments(self._raw_inside, lo, hi, res)
        if vol == 0.0:
            raise ValueError("the implicit shape has no point inside its extent box; check the sign "
                             "convention (negative inside for kind='level-set') and the extent")
        com = first / vol if self.centre_of_mass is None else np.asarray(self.centre_of_mass, float)
        setv = object.__setattr__
        setv(self, "centre_of_mass", com)
        if self.volume is None:
            setv(self, "volume", vol)
        if self.inertia is None:
            setv(self, "inertia", _inertia_from_moments(vol, com, second) * (self.volume / vol))
        # corners of the extent box relative to the centre of mass bound the shape
        setv(self, "bounding_radius", float(np.linalg.norm(np.abs(com) + self.extent)))

    def support(self, d: np.ndarray) -> np.ndarray:
        """The bounding ball's support point: contact acts as for that ball (an approximation)."""
        return self.bounding_radius * _unit(d)

    def _raw_inside(self, x: np.ndarray) -> np.ndarray:
        v = np.asarray(self.function(x))
        if v.shape != (len(x),):
            raise ValueError(f"the shape function returned shape {v.shape} for {len(x)} points; it must "
                             "return one value per point")
        return v if self.kind == "inside" else v <= 0.0

    def inside(self, x: np.ndarray) -> np.ndarray:
        return np.asarray(self._raw_inside(x + self.centre_of_mass), dtype=bool)


@dataclass(frozen=True)
class TriangulatedSurface:
    """A closed, consistently oriented triangle surface in 3D (a polyhedron).

    ``vertices (n_v, 3)`` [m] in the user's coordinates, ``triangles (n_t, 3)`` int. Volume,
    centre of mass and inertia are exact for the polyhedron (sum over the signed tetrahedra from
    the origin to every triangle). The inside test is the generalised winding number (sum of the
    solid angles of the triangles, / 4 pi, > 1/2 inside), evaluated by a Numba kernel; it is
    robust to the orientation of rays and to points near edges. The vertices are stored shifted to
    the centre of mass. Inward-oriented surfaces are flipped.
    """

    vertices: np.ndarray
    triangles: np.ndarray
    centre_of_mass: np.ndarray = field(default=None, init=False)
    volume: float = field(default=None, init=False)
    inertia: np.ndarray = field(default=None, init=False)
    bounding_radius: float = field(default=None, init=False)

    dim = 3

    @classmethod
    def from_file(cls, path, scale: float = 1.0) -> "TriangulatedSurface":
        """Read a closed surface with meshio (STL, OBJ, PLY, ...); ``scale`` multiplies the
        coordinates (e.g. 1e-3 for a file in millimetres)."""
        import meshio

        m = meshio.read(path)
        tris = [c.data for c in m.cells if c.type == "triangle"]
        if not tris:
            raise ValueError(f"{path}: no triangles in the file (cell types: "
                             f"{sorted({c.type for c in m.cells})})")
        return cls(np.asarray(m.points, dtype=float)[:, :3] * scale, np.concatenate(tris))

    def __post_init__(self):
        v = np.ascontiguousarray(self.vertices, dtype=float)
        t = np.ascontiguousarray(self.triangles, dtype=np.int64)
        if v.ndim != 2 or v.shape[1] != 3 or t.ndim != 2 or t.shape[1] != 3:
            raise ValueError("vertices must be (n, 3) and triangles (m, 3)")
        if t.min() < 0 or t.max() >= len(v):
            raise ValueError("triangle vertex indices out of range")
        v, t = _merge_duplicate_vertices(v, t)
        _check_closed(t)
        a, b, c = v[t[:, 0]], v[t[:, 1]], v[t[:, 2]]
        det = np.einsum("ij,ij->i", a, np.cross(b, c))
        vol = det.sum() / 6.0
        if vol < 0:
            t = t[:, ::-1].copy()
            det, vol = -det, -vol
            b, c = c, b
        com = ((a + b + c) * det[:, None]).sum(axis=0) / (24.0 * vol)
        # int x x^T over a tetrahedron (0, a, b, c): det/120 (sum of outer products + (a+b+c)(a+b+c)^T)
        s = a + b + c
        second = (np.einsum("n,ni,nj->ij", det, a, a) + np.einsum("n,ni,nj->ij", det, b, b)
                  + np.einsum("n,ni,nj->ij", det, c, c) + np.einsum("n,ni,nj->ij", det, s, s)) / 120.0
        setv = object.__setattr__
        setv(self, "vertices", v - com)
        setv(self, "triangles", t)
        setv(self, "centre_of_mass", com)
        setv(self, "volume", float(vol))
        setv(self, "inertia", _inertia_from_moments(vol, com, second))
        setv(self, "bounding_radius", float(np.sqrt((self.vertices**2).sum(axis=1).max())))

    def winding_number(self, x: np.ndarray) -> np.ndarray:
        """Generalised winding number of points ``x (n, 3)`` (relative to the centre of mass):
        1 inside, 0 outside, (n,) float64."""
        return _kernels.winding_number(np.ascontiguousarray(x, dtype=float), self.vertices, self.triangles)

    def inside(self, x: np.ndarray) -> np.ndarray:
        return self.winding_number(x) > 0.5

    def support(self, d: np.ndarray) -> np.ndarray:
        return self.vertices[np.argmax(np.asarray(d) @ self.vertices.T, axis=1)]


def _merge_duplicate_vertices(v: np.ndarray, t: np.ndarray):
    """STL stores every triangle's corners separately; merge equal coordinates."""
    uniq, inverse = np.unique(v, axis=0, return_inverse=True)
    return uniq, inverse.reshape(-1)[t]


def _check_closed(t: np.ndarray):
    """Every directed edge must appear once and its reverse once: closed and consistently oriented."""
    edges = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    key = edges[:, 0] * (t.max() + 1) + edges[:, 1]
    rkey = edges[:, 1] * (t.max() + 1) + edges[:, 0]
    if np.unique(key).size != key.size:
        raise ValueError("the surface is not consistently oriented or has an edge shared by more than "
                         "two triangles; repair it (e.g. in MeshLab) before using it as a particle")
    if not np.all(np.isin(rkey, key)):
        raise ValueError("the surface is not closed (some edges belong to one triangle only); a particle "
                         "needs a watertight surface")

