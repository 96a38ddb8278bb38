"""Narrowphase: contact points, normals and gaps of candidate pairs and particle–plane pairs.

For a pair ``(i, j)`` the normal ``n`` points from ``j`` to ``i`` (an impulse ``+lambda n`` on
``i`` and ``-lambda n`` on ``j`` pushes them apart) and the gap is the signed surface distance
(negative when they overlap). With ``s_k(d)`` the support point of particle ``k`` (its surface
point farthest along ``d``, ``support`` of the shapes, in world axes):

* **sphere–sphere, disk–disk** (exact): ``n = (X_i - X_j) / |X_i - X_j|``,
  ``gap = |X_i - X_j| - R_i - R_j``, point midway between the surfaces.
* **any other pair** (a documented approximation): the same centre-line normal and
  ``gap = n · (s_i(-n) - s_j(n))``, the separation of the two shapes' projections on the centre
  line. It is exact for balls and, by the separating-axis theorem, a *lower bound* of the true
  distance for convex shapes: contacts of ellipsoids or boxes are never detected late, but an
  elongated shape at an angle may feel its neighbour slightly early and along the centre line
  rather than the true normal. Implicit shapes act as their bounding balls.
* **particle–plane** (exact for every shape with an exact support): the plane normal ``n_w``
  (into the domain) and ``gap = n_w · (s_i(-n_w) - p_w)``; point at the deepest surface point.

Along periodic axes a pair meets through the nearest image of ``j``: ``X_j + image`` with
``image`` a multiple of the periods (:func:`nearest_image`), and the contact point lies between
``X_i`` and that image.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..particles import Particles


@dataclass(frozen=True)
class Planes:
    """Infinite planes through ``points (p, dim)`` with unit ``normals (p, dim)`` pointing into the
    domain (the side the particles stay on)."""

    points: np.ndarray
    normals: np.ndarray

    def __post_init__(self):
        pts = np.atleast_2d(np.asarray(self.points, dtype=float))
        nrm = np.atleast_2d(np.asarray(self.normals, dtype=float))
        if pts.shape != nrm.shape or pts.shape[1] not in (2, 3):
            raise ValueError(f"plane points {pts.shape} and normals {nrm.shape} must both be (p, 2) or "
                             "(p, 3)")
        length = np.linalg.norm(nrm, axis=1)
        if np.any(length == 0):
            raise ValueError("plane normals must be non-zero")
        object.__setattr__(self, "points", pts)
        object.__setattr__(self, "normals", nrm / length[:, None])

    @classmethod
    def box(cls, lower, upper, faces=None) -> "Planes":
        """The walls of the box ``[lower, upper]``; ``faces`` keeps only the listed
        ``(axis, side)`` faces (side 0 lower, 1 upper), default all ``2 dim``."""
        lower, upper = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
        dim = lower.size
        faces = [(a, s) for a in range(dim) for s in (0, 1)] if faces is None else list(faces)
        pts, nrm = np.zeros((len(faces), dim)), np.zeros((len(faces), dim))
        for k, (a, s) in enumerate(faces):
            pts[k] = lower if s == 0 else upper
            nrm[k, a] = 1.0 if s == 0 else -1.0
        return cls(pts, nrm)

    @property
    def n(self) -> int:
        return len(self.points)


@dataclass
class Contacts:
    """Contacts, arrays over contacts ``c``.

    i : (m,) int64, the particle; j : (m,) int64, the other particle, or ``-1 - w`` for plane w
    normal : (m, dim) unit, from j towards i; point : (m, dim) [m]; gap : (m,) [m], < 0 overlapping
    image : (m, dim) [m], the shift of j's image that meets i across periodic sides (zero
    otherwise: planes, and every pair in a box without periodic axes)
    """

    i: np.ndarray
    j: np.ndarray
    normal: np.ndarray
    point: np.ndarray
    gap: np.ndarray
    image: np.ndarray

    FIELDS = ("i", "j", "normal", "point", "gap", "image")

    def select(self, keep: np.ndarray) -> "Contacts":
        """The contacts where ``keep (m,)`` bool is True."""
        return Contacts(*(getattr(self, f)[keep] for f in self.FIELDS))

    @property
    def m(self) -> int:
        return len(self.i)

    def keys(self, n_planes: int) -> np.ndarray:
        """One int64 per contact, equal for the same ordered pair (i, j) on every step."""
        return self.i * np.int64(n_planes + 2**31) + (self.j + n_planes)


def _support_world(p: Particles, idx: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Support points (k, dim) in world axes of particles ``idx (k,)`` along world ``d (k, dim)``;
    one vectorised call per distinct shape."""
    out = np.empty_like(d)
    if len(idx) == 0:
        return out
    R = p.rotations()[idx]
    body = np.einsum("kji,kj->ki", R, d)
    group, distinct = p.shape_groups
    shape_of = group[idx]
    for g in np.unique(shape_of):
        rows = np.flatnonzero(shape_of == g)
        out[rows] = distinct[g].support(body[rows])
    return p.position[idx] + np.einsum("kij,kj->ki", R, out)


def nearest_image(diff: np.ndarray, periods: np.ndarray | None) -> np.ndarray:
    """``diff (k, dim)`` reduced to its nearest periodic image: each component along an axis of
    period ``periods[a] > 0`` into ``[-L/2, L/2]`` (``periods`` None or 0: unchanged)."""
    if periods is None:
        return diff
    L = np.asarray(periods, dtype=float)
    return diff - L * np.round(diff / np.where(L > 0, L, 1.0))


def pair_contacts(p: Particles, pairs: np.ndarray, periods: np.ndarray | None = None) -> Contacts:
    """Contacts of candidate pairs ``(k, 2)`` (see the module docstring), through the nearest
    image along the axes with ``periods (dim,) > 0``."""
    i, j = pairs[:, 0].astype(np.int64), pairs[:, 1].astype(np.int64)
    raw = p.position[i] - p.position[j]
    diff = nearest_image(raw, periods)
    image = raw - diff  # X_j + image is the image of j next to i
    dist = np.linalg.norm(diff, axis=1)
    n = np.divide(diff, dist[:, None], out=np.zeros_like(diff), where=dist[:, None] > 0)
    n[dist == 0, -1] = 1.0  # coincident centres: any direction
    r = p.ball_radius
    if r is not None:
        si, sj = p.position[i] - r[i, None] * n, p.position[j] + image + r[j, None] * n
    else:
        si, sj = _support_world(p, i, -n), _support_world(p, j, n) + image
    gap = np.einsum("kd,kd->k", si - sj, n)
    return Contacts(i, j, n, 0.5 * (si + sj), gap, image)


def plane_contacts(p: Particles, part: np.ndarray, plane: np.ndarray, planes: Planes) -> Contacts:
    """Contacts of particle–plane candidates (see the module docstring)."""
    n = planes.normals[plane]
    s = _support_world(p, part, -n)
    gap = np.einsum("kd,kd->k", s - planes.points[plane], n)
    return Contacts(part.astype(np.int64), -1 - plane.astype(np.int64), n, s - 0.5 * gap[:, None] * n, gap,
                    np.zeros_like(n))


def concatenate(a: Contacts, b: Contacts) -> Contacts:
    return Contacts(*(np.concatenate([getattr(a, f), getattr(b, f)]) for f in Contacts.FIELDS))
