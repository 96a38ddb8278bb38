"""Structured quadrilateral (2D) and hexahedral (3D) meshes.

A :class:`StructuredMesh` is logically a box of ``shape = (n_x, n_y[, n_z])`` cells. Its vertex
coordinates are stored explicitly, so they may be moved later (grid deformation) without changing
the topology, the refinement hierarchy or the DOF maps. The geometry of every cell is the
multilinear (Q1) map of its ``2**dim`` vertices.

Numbering is lexicographic with x fastest:

* vertex ``(i, j[, k])`` -> ``i + (n_x + 1) * (j + (n_y + 1) * k)``
* cell ``(a, b[, c])`` -> ``a + n_x * (b + n_y * c)``
* local vertex ``(di, dj[, dk])`` of a cell, ``d* in {0, 1}`` -> ``di + 2 dj + 4 dk``

Boundary faces of the box carry the tags ``xmin, xmax, ymin, ymax[, zmin, zmax]``. A periodic
direction has no boundary faces: its two sides are identified by the DOF maps (the vertex array
keeps both sides so that the geometry stays explicit).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

AXES = "xyz"


def face_tags(dim: int) -> tuple[str, ...]:
    """Names of the box faces, ``('xmin', 'xmax', 'ymin', ...)`` for ``dim`` axes."""
    return tuple(f"{AXES[d]}{side}" for d in range(dim) for side in ("min", "max"))


@dataclass(frozen=True, eq=False)
class StructuredMesh:
    """A logically box-shaped mesh of quadrilaterals or hexahedra.

    Parameters
    ----------
    shape : tuple of int, length dim
        Number of cells per axis.
    lower, upper : tuple of float, length dim
        Corners of the box (used for the initial uniform vertex placement and for point location).
    periodic : tuple of bool, length dim
        Periodic directions; a periodic direction needs at least 2 cells.
    vertices : (n_vertices, dim) float64, optional
        Explicit vertex coordinates; uniform placement in the box when omitted.
    images : tuple of float, length dim, or None
        A piece cut from a periodic mesh that is not periodic itself (a slab of a ring of slabs,
        :func:`~fbmflow.parallel.blocks.cut_box`): the whole mesh's period of every axis (0
        where it has none), by which points and particles repeat (:attr:`periods`); None: the
        mesh's own periodic axes only.
    """

    shape: tuple[int, ...]
    lower: tuple[float, ...]
    upper: tuple[float, ...]
    periodic: tuple[bool, ...]
    vertices: np.ndarray
    images: tuple[float, ...] | None = None

    @classmethod
    def box(cls, shape, lower=None, upper=None, periodic=None) -> "StructuredMesh":
        """Uniform mesh of the box ``[lower, upper]`` with ``shape`` cells per axis."""
        shape = tuple(int(n) for n in shape)
        dim = len(shape)
        if dim not in (2, 3):
            raise ValueError(f"a structured mesh has 2 or 3 axes, got shape {shape}")
        if any(n < 1 for n in shape):
            raise ValueError(f"every axis needs at least one cell, got shape {shape}")
        lower = tuple(float(v) for v in (lower if lower is not None else (0.0,) * dim))
        upper = tuple(float(v) for v in (upper if upper is not None else (1.0,) * dim))
        periodic = tuple(bool(p) for p in (periodic if periodic is not None else (False,) * dim))
        if len(lower) != dim or len(upper) != dim or len(periodic) != dim:
            raise ValueError("lower, upper and periodic need one entry per axis")
        if any(u <= lo for lo, u in zip(lower, upper)):
            raise ValueError(f"upper {upper} must exceed lower {lower} on every axis")
        for d in range(dim):
            if periodic[d] and shape[d] < 2:
                raise ValueError(f"periodic axis {AXES[d]} needs at least 2 cells")
        axes = [np.linspace(lower[d], upper[d], shape[d] + 1) for d in range(dim)]
        grids = np.meshgrid(*axes, indexing="ij")
        vertices = np.stack([g.ravel(order="F") for g in grids], axis=1)
        return cls(shape, lower, upper, periodic, vertices)

    @classmethod
    def rectilinear(cls, axes, periodic=None) -> "StructuredMesh":
        """Tensor-product mesh with the vertex coordinates ``axes[d]`` (strictly increasing, at least
        two values) along axis ``d``: graded cells, e.g. fine near an obstacle and coarse far away.
        Periodic axes must be uniform."""
        axes = [np.asarray(a, dtype=float) for a in axes]
        if len(axes) not in (2, 3) or any(a.ndim != 1 or a.size < 2 or np.any(np.diff(a) <= 0) for a in axes):
            raise ValueError("a rectilinear mesh needs 2 or 3 strictly increasing coordinate arrays "
                             "of at least two values each")
        mesh = cls.box([a.size - 1 for a in axes], [a[0] for a in axes], [a[-1] for a in axes], periodic)
        for d, a in enumerate(axes):
            if mesh.periodic[d] and not np.allclose(np.diff(a), np.diff(a)[0]):
                raise ValueError(f"periodic axis {AXES[d]} must be uniform")
        grids = np.meshgrid(*axes, indexing="ij")
        vertices = np.stack([g.ravel(order="F") for g in grids], axis=1)
        return cls(mesh.shape, mesh.lower, mesh.upper, mesh.periodic, vertices)

    def __post_init__(self):
        n_vertices = int(np.prod([n + 1 for n in self.shape]))
        if self.vertices.shape != (n_vertices, self.dim):
            raise ValueError(f"vertices must have shape {(n_vertices, self.dim)}")

    # -- sizes --------------------------------------------------------------------------------
    @property
    def dim(self) -> int:
        return len(self.shape)

    @property
    def n_cells(self) -> int:
        return int(np.prod(self.shape))

    @property
    def n_vertices(self) -> int:
        return self.vertices.shape[0]

    @property
    def vertex_shape(self) -> tuple[int, ...]:
        return tuple(n + 1 for n in self.shape)

    @property
    def spacing(self) -> np.ndarray:
        """Nominal cell size per axis, ``(upper - lower) / shape``, (dim,) float64."""
        return (np.array(self.upper) - np.array(self.lower)) / np.array(self.shape)

    @property
    def finest_spacing(self) -> np.ndarray:
        """Smallest cell size per axis, (dim,) float64: :attr:`spacing` on a uniform mesh, the
        fine zone's cells on a graded one (where the particles are meant to move)."""
        axes = self.axis_coordinates
        if axes is None:
            return self.spacing
        return np.array([float(np.diff(a).min()) for a in axes])

    def cell_size_at(self, points) -> np.ndarray:
        """Size per axis of the cell holding each point, (n, dim) float64 for ``points`` (n, dim)
        (a point outside the mesh: the nearest boundary cell's)."""
        points = np.atleast_2d(np.asarray(points, dtype=float))
        axes = self.axis_coordinates
        if axes is None:
            return np.broadcast_to(self.spacing, points.shape).copy()
        sizes = np.empty_like(points)
        for d, a in enumerate(axes):
            k = np.clip(np.searchsorted(a, points[:, d]) - 1, 0, a.size - 2)
            sizes[:, d] = a[k + 1] - a[k]
        return sizes

    @property
    def periods(self) -> np.ndarray:
        """Period of every axis, (dim,) float64: ``upper - lower`` on a periodic axis, the whole
        mesh's period along an axis of a piece of it (:attr:`images`), 0 elsewhere: the period
        of the minimum-image convention."""
        own = np.where(self.periodic, np.array(self.upper) - np.array(self.lower), 0.0)
        return own if self.images is None else np.where(self.periodic, own, np.array(self.images))

    @property
    def tags(self) -> tuple[str, ...]:
        """Boundary face tags of the non-periodic directions."""
        return tuple(t for t in face_tags(self.dim) if not self.periodic[AXES.index(t[0])])

    # -- topology -----------------------------------------------------------------------------
    def cell_indices(self) -> np.ndarray:
        """Logical index of every cell, (n_cells, dim) int64."""
        idx = np.indices(self.shape).reshape(self.dim, -1, order="F").T
        return np.ascontiguousarray(idx, dtype=np.int64)

    @cached_property
    def cell_vertices(self) -> np.ndarray:
        """Vertex numbers of every cell, (n_cells, 2**dim) int64, local order x fastest."""
        idx = self.cell_indices()
        local = np.indices((2,) * self.dim).reshape(self.dim, -1, order="F").T
        strides = np.cumprod((1,) + self.vertex_shape[:-1])
        return ((idx[:, None, :] + local[None, :, :]) * strides).sum(axis=2)

    def cell_coordinates(self) -> np.ndarray:
        """Vertex coordinates per cell, (n_cells, 2**dim, dim) float64."""
        return self.vertices[self.cell_vertices]

    def cell_colours(self) -> list[list[np.ndarray]]:
        """Cells grouped into independent slabs for race-free parallel assembly.

        A slab is one layer of cells normal to the last axis (a row of cells in 2D, a plane in
        3D), in lexicographic order. Slabs ``s`` and ``s + 2`` share no vertex, so the slabs of one
        colour (even / odd layers; a periodic last axis with an odd count gives its last layer a
        third colour) may be processed in parallel, each sequentially in cache-friendly order.

        Returns a list over colours of lists of (cells_per_slab,) int64 arrays.
        """
        n_last = self.shape[-1]
        per_slab = self.n_cells // n_last
        colour = np.arange(n_last) % 2
        if self.periodic[-1] and n_last % 2 == 1:
            colour[-1] = 2
        return [[np.arange(s * per_slab, (s + 1) * per_slab) for s in np.flatnonzero(colour == c)]
                for c in np.unique(colour)]

    def cell_parity_classes(self, modulus: int = 2) -> list[np.ndarray]:
        """Cells grouped by their index modulo ``modulus`` on every axis.

        With ``modulus = 2`` cells of one class share no vertex; with ``modulus = 3`` they do not
        even share a neighbour, so the matrix rows of one cell's DOFs never involve another cell's
        DOFs of the same class. On a periodic axis whose cell count is not a multiple of
        ``modulus`` the trailing layers get classes of their own. Returns a list of (n,) int64
        arrays (at most ``(modulus + 1)**dim``).
        """
        idx = self.cell_indices()
        key = np.zeros(self.n_cells, dtype=np.int64)
        base = modulus + 2
        for d in range(self.dim):
            c_d = idx[:, d] % modulus
            n = self.shape[d]
            if self.periodic[d] and n % modulus:
                tail = idx[:, d] >= n - n % modulus
                c_d[tail] = modulus + (idx[tail, d] - (n - n % modulus))
            key += c_d * base**d
        return [np.flatnonzero(key == k) for k in np.unique(key)]

    # -- geometry -----------------------------------------------------------------------------
    def map_to_physical(self, xi: np.ndarray, cells: np.ndarray | None = None) -> np.ndarray:
        """Multilinear map of reference points ``xi in [-1, 1]^dim``.

        Parameters
        ----------
        xi : (n_points, dim) float64
        cells : (n_sel,) int64, optional, default all cells

        Returns
        -------
        (n_sel, n_points, dim) float64
        """
        coords = self.cell_coordinates() if cells is None else self.vertices[self.cell_vertices[cells]]
        return np.einsum("pv,cvd->cpd", q1_basis(xi), coords)

    @property
    def is_uniform(self) -> bool:
        """True when the vertices still sit on the uniform box lattice (point location by index)."""
        ref = StructuredMesh.box(self.shape, self.lower, self.upper, self.periodic).vertices
        return bool(np.allclose(ref, self.vertices, rtol=0, atol=1e-12 * np.max(self.spacing)))

    @cached_property
    def axis_coordinates(self) -> tuple[np.ndarray, ...] | None:
        """Vertex coordinates per axis, ``(n_d + 1,)`` each, when the mesh is a tensor product of
        axes (uniform or graded, :meth:`rectilinear`); None for a deformed mesh."""
        lattice = self.vertices.reshape(self.vertex_shape + (self.dim,), order="F")
        axes = tuple(np.moveaxis(lattice[..., d], d, 0).reshape(self.vertex_shape[d], -1)[:, 0].copy()
                     for d in range(self.dim))
        grids = np.meshgrid(*axes, indexing="ij")
        expected = np.stack([g.ravel(order="F") for g in grids], axis=1)
        if not np.allclose(expected, self.vertices, rtol=0, atol=1e-12 * np.max(self.spacing)):
            return None
        return axes

    def refine(self) -> "StructuredMesh":
        """Uniform refinement: every cell splits into ``2**dim`` children.

        New vertices are placed by the current multilinear cell maps, so a moved mesh refines into
        a nested mesh of the same geometry.
        """
        fine_shape = tuple(2 * n for n in self.shape)
        fine = StructuredMesh.box(fine_shape, self.lower, self.upper, self.periodic)
        # each fine vertex = coarse vertex lattice at half index; evaluate coarse map there
        fidx = np.indices(fine.vertex_shape).reshape(self.dim, -1, order="F").T
        cell = np.minimum(fidx // 2, np.array(self.shape) - 1)
        xi = (fidx - 2 * cell).astype(float) - 1.0  # in {-1, 0, 1}
        strides = np.cumprod((1,) + self.shape[:-1])
        cell_id = (cell * strides).sum(axis=1)
        basis = q1_basis(xi)  # (n_fine_vertices, 2**dim), row per point
        coords = self.vertices[self.cell_vertices[cell_id]]  # (n, 2**dim, dim)
        vertices = np.einsum("pv,pvd->pd", basis, coords)
        return StructuredMesh(fine_shape, self.lower, self.upper, self.periodic, vertices, self.images)

    def coarsen(self) -> "StructuredMesh":
        """The mesh whose :meth:`refine` is this one: half the cells per axis, every other vertex.

        Raises ValueError when an axis has an odd number of cells (or a periodic axis would keep
        fewer than 2).
        """
        if any(n % 2 for n in self.shape):
            raise ValueError(f"cannot coarsen shape {self.shape}: every axis needs an even cell count")
        coarse_shape = tuple(n // 2 for n in self.shape)
        if any(p and n < 2 for n, p in zip(coarse_shape, self.periodic)):
            raise ValueError("cannot coarsen: a periodic axis needs at least 2 cells")
        idx = np.indices(tuple(n + 1 for n in coarse_shape)).reshape(self.dim, -1, order="F").T
        strides = np.cumprod((1,) + self.vertex_shape[:-1])
        vertices = self.vertices[(2 * idx * strides).sum(axis=1)]
        return StructuredMesh(coarse_shape, self.lower, self.upper, self.periodic, vertices, self.images)

    def hierarchy(self, levels: int) -> list["StructuredMesh"]:
        """``[self, self.refine(), ...]`` with ``levels + 1`` nested meshes."""
        meshes = [self]
        for _ in range(levels):
            meshes.append(meshes[-1].refine())
        return meshes

    def boundary_vertices(self, tag: str) -> np.ndarray:
        """Vertex numbers on the box face ``tag`` (e.g. ``'xmin'``), (n,) int64."""
        axis, side = self._parse_tag(tag)
        idx = np.indices(self.vertex_shape).reshape(self.dim, -1, order="F").T
        target = 0 if side == "min" else self.shape[axis]
        return np.flatnonzero(idx[:, axis] == target)

    def _parse_tag(self, tag: str) -> tuple[int, str]:
        if tag not in self.tags:
            raise ValueError(f"unknown boundary tag {tag!r}; this mesh has {', '.join(self.tags)}")
        return AXES.index(tag[0]), tag[1:]


def graded_axis(lower: float, upper: float, fine: tuple[float, float], h: float, ratio: float = 1.3,
                multiple: int = 2) -> np.ndarray:
    """Vertex coordinates of one axis of a :meth:`StructuredMesh.rectilinear` mesh: cells of size
    about ``h`` on the interval ``fine = (a, b)``, growing by ``ratio`` per cell towards
    ``lower`` and ``upper``.

    Each side gets the fewest (even) number ``n`` of cells whose sizes ``h ratio^k`` (k = 1..n)
    cover it; the growth factor is then lowered (to no less than 1) until they fit it exactly, so
    side cells grow smoothly from ``h`` (they are smaller than ``h`` only when the side is shorter
    than ``n h``). The fine zone gets ``ceil((b - a) / h)`` cells of size ``h``, rounded up to an
    even number (so the mesh coarsens at least once, for multigrid): the zone widens about its
    centre to fit them, shifted to stay inside ``[lower, upper]`` (its cells shrink only when the
    whole axis is shorter). The longer side then gets the extra cells (a gentler growth) that
    make the cell count a multiple of ``multiple`` (even), so that the mesh coarsens
    ``log2(multiple)`` times. Returns (n + 1,) float64, strictly increasing.
    """
    a, b = fine
    if not (lower <= a < b <= upper and h > 0 and ratio >= 1.0 and multiple >= 2 and multiple % 2 == 0):
        raise ValueError(f"need lower <= a < b <= upper, h > 0, ratio >= 1 and an even multiple; got "
                         f"{lower}, {fine}, {upper}, h = {h}, ratio = {ratio}, multiple = {multiple}")

    def side(length, extra=0):  # cell sizes from the fine zone outwards
        if length <= 1e-12 * (upper - lower):
            return np.zeros(0)
        n = 2
        while h * np.sum(ratio ** np.arange(1, n + 1)) < length:
            n += 2
        n += extra
        lo, hi = 1.0, ratio  # the growth factor that fits the side exactly with n cells
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if h * np.sum(mid ** np.arange(1, n + 1)) < length else (lo, mid)
        sizes = h * hi ** np.arange(1, n + 1)
        return sizes * (length / sizes.sum())

    n_fine = int(np.ceil((b - a) / h - 1e-9))
    n_fine += n_fine % 2
    width = n_fine * h  # widen the zone about its centre to whole cells h, kept inside the axis
    if b - a < width * (1 - 1e-9) and width <= upper - lower:  # (an exact zone keeps its ends)
        a = min(max(0.5 * (a + b) - 0.5 * width, lower), upper - width)
        b = a + width
    middle = np.linspace(a, b, n_fine + 1)
    left, right = side(a - lower), side(upper - b)
    deficit = -(n_fine + left.size + right.size) % multiple
    if deficit and max(a - lower, upper - b) > 1e-12 * (upper - lower):
        if a - lower > upper - b:
            left = side(a - lower, deficit)
        else:
            right = side(upper - b, deficit)
    elif deficit:  # no sides: the fine zone takes them (smaller cells)
        n_fine += deficit
        middle = np.linspace(a, b, n_fine + 1)
    axis = np.concatenate([a - np.cumsum(left)[::-1], middle, b + np.cumsum(right)])
    axis[0], axis[-1] = lower, upper
    return axis


def q1_basis(xi: np.ndarray) -> np.ndarray:
    """Multilinear basis on ``[-1, 1]^dim`` at points ``xi (n, dim)`` -> (n, 2**dim) float64."""
    xi = np.atleast_2d(xi)
    dim = xi.shape[1]
    local = np.indices((2,) * dim).reshape(dim, -1, order="F").T  # (2**dim, dim) in {0,1}
    sign = 2 * local - 1
    return np.prod(0.5 * (1.0 + sign[None, :, :] * xi[:, None, :]), axis=2)
