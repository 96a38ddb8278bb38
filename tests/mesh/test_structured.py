"""StructuredMesh: sizes, numbering, boundary tags, colouring, refinement."""
import itertools

import numpy as np
import pytest

from fbmflow.mesh import StructuredMesh, face_tags, q1_basis

SHAPES = {2: (3, 2), 3: (2, 3, 2)}


def _lattice_index(mesh, vertex):
    """Multi-index (..., dim) of vertex numbers (x fastest)."""
    return np.stack(np.unravel_index(vertex, mesh.vertex_shape, order="F"), axis=-1)


def _bilinear_map(x):
    """A smooth multilinear map of the unit box onto itself-ish (injective for the factors used)."""
    y = x.copy()
    if x.shape[1] == 2:
        y[:, 0] = x[:, 0] + 0.2 * x[:, 0] * x[:, 1] - 0.1 * x[:, 1]
        y[:, 1] = x[:, 1] + 0.15 * x[:, 0] * x[:, 1] + 0.05 * x[:, 0]
    else:
        y[:, 0] = x[:, 0] + 0.2 * x[:, 0] * x[:, 1] - 0.1 * x[:, 1] * x[:, 2]
        y[:, 1] = x[:, 1] + 0.15 * x[:, 0] * x[:, 2] + 0.05 * x[:, 0] * x[:, 1] * x[:, 2]
        y[:, 2] = x[:, 2] + 0.1 * x[:, 0] * x[:, 1] - 0.1 * x[:, 1]
    return y


def _moved(mesh, vertices):
    return StructuredMesh(mesh.shape, mesh.lower, mesh.upper, mesh.periodic, vertices)


def _random_interior_move(mesh, seed=0, amount=0.1):
    rng = np.random.default_rng(seed)
    idx = _lattice_index(mesh, np.arange(mesh.n_vertices))
    interior = np.all((idx > 0) & (idx < np.array(mesh.shape)), axis=1)
    v = mesh.vertices.copy()
    v[interior] += amount * mesh.spacing * rng.uniform(-1, 1, size=(interior.sum(), mesh.dim))
    return _moved(mesh, v)


# -- sizes and numbering ----------------------------------------------------------------------
@pytest.mark.parametrize("dim", [2, 3])
def test_counts(dim):
    shape = SHAPES[dim]
    mesh = StructuredMesh.box(shape)
    assert mesh.dim == dim
    assert mesh.n_cells == np.prod(shape)
    assert mesh.n_vertices == np.prod([n + 1 for n in shape])
    assert mesh.vertex_shape == tuple(n + 1 for n in shape)
    assert mesh.vertices.shape == (mesh.n_vertices, dim)
    assert mesh.cell_vertices.shape == (mesh.n_cells, 2**dim)
    assert mesh.cell_vertices.dtype == np.int64
    assert mesh.cell_coordinates().shape == (mesh.n_cells, 2**dim, dim)
    np.testing.assert_allclose(mesh.spacing, 1.0 / np.array(shape))
    assert mesh.is_uniform
    # every vertex is used by some cell
    assert np.array_equal(np.unique(mesh.cell_vertices), np.arange(mesh.n_vertices))


@pytest.mark.parametrize("dim", [2, 3])
def test_vertex_numbering_x_fastest(dim):
    shape = SHAPES[dim]
    lower = (-1.0, 0.5, 2.0)[:dim]
    upper = (2.0, 1.5, 4.0)[:dim]
    mesh = StructuredMesh.box(shape, lower, upper)
    h = (np.array(upper) - np.array(lower)) / np.array(shape)
    for idx in itertools.product(*[range(n + 1) for n in shape]):
        number = idx[0] + (shape[0] + 1) * (idx[1] + (shape[1] + 1) * (idx[2] if dim == 3 else 0))
        np.testing.assert_allclose(mesh.vertices[number], np.array(lower) + np.array(idx) * h,
                                   rtol=0, atol=1e-14)
    np.testing.assert_allclose(mesh.vertices.min(axis=0), lower)
    np.testing.assert_allclose(mesh.vertices.max(axis=0), upper)


@pytest.mark.parametrize("dim", [2, 3])
def test_cell_vertices_local_order(dim):
    shape = SHAPES[dim]
    mesh = StructuredMesh.box(shape)
    h = mesh.spacing
    cidx = mesh.cell_indices()
    assert cidx.shape == (mesh.n_cells, dim)
    for c in range(mesh.n_cells):
        # cell numbering: a + n_x (b + n_y c)
        expected_c = cidx[c, 0] + shape[0] * (cidx[c, 1] + shape[1] * (cidx[c, 2] if dim == 3 else 0))
        assert expected_c == c
        for loc in itertools.product(*[range(2)] * dim):
            local_number = sum(loc[d] * 2**d for d in range(dim))  # di + 2 dj + 4 dk
            x = mesh.vertices[mesh.cell_vertices[c, local_number]]
            np.testing.assert_allclose(x, (cidx[c] + np.array(loc)) * h, rtol=0, atol=1e-14)


@pytest.mark.parametrize("dim", [2, 3])
def test_map_to_physical_on_box(dim):
    mesh = StructuredMesh.box(SHAPES[dim], upper=(2.0, 3.0, 4.0)[:dim])
    rng = np.random.default_rng(1)
    xi = rng.uniform(-1, 1, size=(5, dim))
    x = mesh.map_to_physical(xi)
    assert x.shape == (mesh.n_cells, 5, dim)
    h = mesh.spacing
    lower_corner = mesh.cell_indices() * h
    np.testing.assert_allclose(x, lower_corner[:, None, :] + 0.5 * (xi[None] + 1) * h, atol=1e-14)
    # subset of cells
    sel = np.array([1, 0])
    np.testing.assert_array_equal(mesh.map_to_physical(xi, sel), x[sel])
    # the corners of the reference cell map onto the cell vertices in local order
    corners = np.indices((2,) * dim).reshape(dim, -1, order="F").T * 2.0 - 1.0
    np.testing.assert_allclose(mesh.map_to_physical(corners), mesh.cell_coordinates(), atol=1e-14)


@pytest.mark.parametrize("dim", [2, 3])
def test_q1_basis(dim):
    rng = np.random.default_rng(2)
    xi = rng.uniform(-1, 1, size=(7, dim))
    b = q1_basis(xi)
    assert b.shape == (7, 2**dim)
    np.testing.assert_allclose(b.sum(axis=1), 1.0)
    corners = np.indices((2,) * dim).reshape(dim, -1, order="F").T * 2.0 - 1.0
    np.testing.assert_allclose(q1_basis(corners), np.eye(2**dim), atol=1e-15)


# -- boundary tags ----------------------------------------------------------------------------
def test_face_tags():
    assert face_tags(2) == ("xmin", "xmax", "ymin", "ymax")
    assert face_tags(3) == ("xmin", "xmax", "ymin", "ymax", "zmin", "zmax")


@pytest.mark.parametrize("dim", [2, 3])
def test_boundary_vertices(dim):
    shape = SHAPES[dim]
    lower = (-1.0, 0.5, 2.0)[:dim]
    upper = (2.0, 1.5, 4.0)[:dim]
    mesh = StructuredMesh.box(shape, lower, upper)
    assert mesh.tags == face_tags(dim)
    for tag in mesh.tags:
        axis = "xyz".index(tag[0])
        value = lower[axis] if tag.endswith("min") else upper[axis]
        bv = mesh.boundary_vertices(tag)
        expected = np.flatnonzero(np.isclose(mesh.vertices[:, axis], value, rtol=0, atol=1e-12))
        np.testing.assert_array_equal(bv, expected)
        assert bv.size == np.prod([n + 1 for d, n in enumerate(shape) if d != axis])
    with pytest.raises(ValueError, match="unknown boundary tag"):
        mesh.boundary_vertices("wmin")


@pytest.mark.parametrize("dim,periodic,tags", [
    (2, (True, False), ("ymin", "ymax")),
    (2, (False, True), ("xmin", "xmax")),
    (2, (True, True), ()),
    (3, (True, False, True), ("ymin", "ymax")),
    (3, (False, True, False), ("xmin", "xmax", "zmin", "zmax")),
])
def test_tags_omit_periodic_axes(dim, periodic, tags):
    mesh = StructuredMesh.box(SHAPES[dim], periodic=periodic)
    assert mesh.tags == tags
    assert mesh.periodic == periodic
    for d in range(dim):
        if periodic[d]:
            for side in ("min", "max"):
                with pytest.raises(ValueError, match="unknown boundary tag"):
                    mesh.boundary_vertices("xyz"[d] + side)
    for tag in tags:
        assert mesh.boundary_vertices(tag).size > 0
    # a periodic mesh still stores both sides of the box
    assert mesh.n_vertices == np.prod([n + 1 for n in SHAPES[dim]])


# -- errors -----------------------------------------------------------------------------------
@pytest.mark.parametrize("kwargs,match", [
    (dict(shape=(4,)), "2 or 3 axes"),
    (dict(shape=(2, 2, 2, 2)), "2 or 3 axes"),
    (dict(shape=(0, 2)), "at least one cell"),
    (dict(shape=(2, -1, 2)), "at least one cell"),
    (dict(shape=(2, 2), lower=(0.0,)), "one entry per axis"),
    (dict(shape=(2, 2), upper=(1.0, 1.0, 1.0)), "one entry per axis"),
    (dict(shape=(2, 2), periodic=(True,)), "one entry per axis"),
    (dict(shape=(2, 2), lower=(0.0, 1.0), upper=(1.0, 1.0)), "must exceed"),
    (dict(shape=(2, 2), lower=(0.0, 2.0), upper=(1.0, 1.0)), "must exceed"),
    (dict(shape=(1, 2), periodic=(True, False)), "periodic axis x"),
    (dict(shape=(2, 2, 1), periodic=(False, False, True)), "periodic axis z"),
])
def test_box_errors(kwargs, match):
    with pytest.raises(ValueError, match=match):
        StructuredMesh.box(**kwargs)


def test_vertex_array_shape_checked():
    mesh = StructuredMesh.box((2, 2))
    with pytest.raises(ValueError, match="vertices must have shape"):
        StructuredMesh(mesh.shape, mesh.lower, mesh.upper, mesh.periodic, mesh.vertices[:-1])
    with pytest.raises(ValueError, match="vertices must have shape"):
        StructuredMesh(mesh.shape, mesh.lower, mesh.upper, mesh.periodic,
                       np.zeros((mesh.n_vertices, 3)))


# -- colouring --------------------------------------------------------------------------------
@pytest.mark.parametrize("shape,periodic", [
    ((2, 2), (False, False)),
    ((3, 4), (False, False)),
    ((3, 4), (True, False)),
    ((4, 3), (False, True)),
    ((2, 2), (True, True)),
    ((3, 5), (True, True)),
    ((2, 2, 2), (False, False, False)),
    ((3, 2, 3), (True, False, True)),
    ((3, 3, 3), (True, True, True)),
    ((2, 4, 3), (True, True, True)),
])
def test_cell_colours_share_no_vertex(shape, periodic):
    """Slabs of one colour are vertex-disjoint; each slab is lexicographically ordered."""
    mesh = StructuredMesh.box(shape, periodic=periodic)
    slabs_by_colour = mesh.cell_colours()
    colours = [np.concatenate(slabs) for slabs in slabs_by_colour]
    # a partition of all cells
    all_cells = np.concatenate(colours)
    assert all(c.dtype == np.int64 for c in colours)
    assert np.array_equal(np.sort(all_cells), np.arange(mesh.n_cells))
    assert len(colours) <= 3
    for slabs in slabs_by_colour:
        for slab in slabs:
            assert np.all(np.diff(slab) == 1)
            assert slab.size == mesh.n_cells // mesh.shape[-1]
    # identified vertex: index n on a periodic axis is index 0
    vidx = _lattice_index(mesh, mesh.cell_vertices)  # (n_cells, 2**dim, dim)
    for d in range(mesh.dim):
        if periodic[d]:
            vidx[..., d] %= shape[d]
    key = np.ravel_multi_index(tuple(np.moveaxis(vidx, -1, 0)), mesh.vertex_shape, order="F")
    for slabs in slabs_by_colour:
        used = [np.unique(key[slab]) for slab in slabs]
        merged = np.concatenate(used)
        assert np.unique(merged).size == merged.size, "slabs of one colour share a vertex"


def test_cell_colours_count():
    assert len(StructuredMesh.box((4, 4)).cell_colours()) == 2
    assert len(StructuredMesh.box((4, 4, 4)).cell_colours()) == 2
    assert len(StructuredMesh.box((4, 3), periodic=(True, False)).cell_colours()) == 2
    # an odd periodic slab axis needs a third colour
    assert len(StructuredMesh.box((4, 3), periodic=(False, True)).cell_colours()) == 3


# -- refinement -------------------------------------------------------------------------------
@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("periodic", [False, True])
def test_refine_nested_uniform(dim, periodic):
    per = (periodic,) + (False,) * (dim - 1)
    coarse = StructuredMesh.box(SHAPES[dim], upper=(2.0, 1.0, 3.0)[:dim], periodic=per)
    fine = coarse.refine()
    assert fine.shape == tuple(2 * n for n in coarse.shape)
    assert fine.periodic == coarse.periodic
    assert fine.lower == coarse.lower and fine.upper == coarse.upper
    assert fine.n_cells == 2**dim * coarse.n_cells
    assert fine.is_uniform
    ref = StructuredMesh.box(fine.shape, fine.lower, fine.upper, fine.periodic)
    np.testing.assert_allclose(fine.vertices, ref.vertices, atol=1e-14)


@pytest.mark.parametrize("dim", [2, 3])
def test_refine_nested_moved(dim):
    coarse = _random_interior_move(StructuredMesh.box(SHAPES[dim]), seed=3)
    assert not coarse.is_uniform
    fine = coarse.refine()
    # every coarse vertex reappears (at twice the lattice index)
    cidx = _lattice_index(coarse, np.arange(coarse.n_vertices))
    fnum = np.ravel_multi_index(tuple((2 * cidx).T), fine.vertex_shape, order="F")
    np.testing.assert_allclose(fine.vertices[fnum], coarse.vertices, rtol=0, atol=1e-14)
    # ... and is found among the fine vertices by coordinate
    dist = np.linalg.norm(coarse.vertices[:, None, :] - fine.vertices[None, :, :], axis=2)
    assert np.all(dist.min(axis=1) < 1e-14)


@pytest.mark.parametrize("dim", [2, 3])
def test_refine_keeps_multilinear_geometry(dim):
    """The fine cell maps coincide with the coarse multilinear maps (random interior moves)."""
    coarse = _random_interior_move(StructuredMesh.box(SHAPES[dim]), seed=4)
    fine = coarse.refine()
    rng = np.random.default_rng(5)
    xi_f = rng.uniform(-1, 1, size=(6, dim))
    fidx = fine.cell_indices()
    strides = np.cumprod((1,) + coarse.shape[:-1])
    for fc in range(fine.n_cells):
        cc = int(((fidx[fc] // 2) * strides).sum())
        xi_c = (xi_f - 1.0) / 2.0 + (fidx[fc] % 2)
        np.testing.assert_allclose(fine.map_to_physical(xi_f, np.array([fc]))[0],
                                   coarse.map_to_physical(xi_c, np.array([cc]))[0],
                                   rtol=0, atol=1e-14)


@pytest.mark.parametrize("dim", [2, 3])
def test_refine_bilinear_map(dim):
    """A mesh moved by a global multilinear map refines onto the same map of the finer lattice."""
    box = StructuredMesh.box(SHAPES[dim])
    coarse = _moved(box, _bilinear_map(box.vertices))
    meshes = coarse.hierarchy(2)
    assert len(meshes) == 3
    assert meshes[0] is coarse
    for level, mesh in enumerate(meshes):
        assert mesh.shape == tuple(n * 2**level for n in box.shape)
        uniform = StructuredMesh.box(mesh.shape)
        np.testing.assert_allclose(mesh.vertices, _bilinear_map(uniform.vertices), rtol=0, atol=1e-14)


def test_hierarchy_lengths():
    mesh = StructuredMesh.box((2, 2))
    assert mesh.hierarchy(0) == [mesh]
    h = mesh.hierarchy(3)
    assert len(h) == 4
    assert [m.shape for m in h] == [(2, 2), (4, 4), (8, 8), (16, 16)]


# -- rectilinear (graded) meshes --------------------------------------------------------------
@pytest.mark.parametrize("dim", [2, 3])
def test_rectilinear_axes_survive_refine_and_coarsen(dim):
    axes = [np.array([0.0, 0.1, 0.15, 0.5, 2.0]), np.array([-1.0, 0.0, 0.25, 1.0]),
            np.array([0.0, 3.0])][:dim]
    mesh = StructuredMesh.rectilinear(axes)
    assert mesh.shape == tuple(a.size - 1 for a in axes) and not mesh.is_uniform
    for a, b in zip(mesh.axis_coordinates, axes):
        np.testing.assert_array_equal(a, b)
    fine = mesh.refine()
    for a, b in zip(fine.axis_coordinates, axes):
        np.testing.assert_allclose(a[0::2], b, atol=1e-15)
        np.testing.assert_allclose(a[1::2], 0.5 * (b[:-1] + b[1:]), atol=1e-15)
    for a, b in zip(fine.coarsen().axis_coordinates, axes):
        np.testing.assert_allclose(a, b, atol=1e-15)
    assert _random_interior_move(StructuredMesh.box(SHAPES[dim]), seed=3).axis_coordinates is None


def test_rectilinear_errors():
    with pytest.raises(ValueError, match="strictly increasing"):
        StructuredMesh.rectilinear([np.array([0.0, 1.0, 0.5]), np.array([0.0, 1.0])])
    with pytest.raises(ValueError, match="periodic axis x must be uniform"):
        StructuredMesh.rectilinear([np.array([0.0, 0.2, 1.0]), np.array([0.0, 1.0])], periodic=(True, False))


def test_graded_axis_grows_smoothly_from_the_fine_zone():
    from fbmflow.mesh import graded_axis

    x = graded_axis(0.0, 2.5, (0.4, 0.6), 0.0125, ratio=1.3)
    dx = np.diff(x)
    assert x[0] == 0.0 and x[-1] == 2.5 and np.all(dx > 0)
    fine = (x[:-1] >= 0.4 - 1e-12) & (x[1:] <= 0.6 + 1e-12)
    np.testing.assert_allclose(dx[fine], 0.0125)
    left, right = dx[:np.argmax(fine)][::-1], dx[len(dx) - np.argmax(fine[::-1]):]
    for side in (left, right):  # growing outwards, by at most the ratio, from at least h
        growth = side[1:] / side[:-1]
        assert np.all(growth >= 1.0 - 1e-12) and np.all(growth <= 1.3 + 1e-12) and side[0] >= 0.0125
    assert all(n % 2 == 0 for n in (fine.sum(), left.size, right.size))
    with pytest.raises(ValueError, match="lower <= a < b <= upper"):
        graded_axis(0.0, 1.0, (0.5, 0.4), 0.1)


def test_graded_axis_widens_the_fine_zone_to_whole_cells():
    """A zone that is not a whole (even) number of cells h widens about its centre, and shifts to
    stay inside the axis; its cells are exactly h."""
    from fbmflow.mesh import graded_axis

    x = graded_axis(0.0, 1.0, (0.4, 0.63), 0.05)  # 4.6 cells -> 6 cells over [0.365, 0.665]
    h = np.diff(x)
    np.testing.assert_allclose(h[np.isclose(h, 0.05)].sum(), 0.3)
    assert np.isclose(x, 0.365).any() and np.isclose(x, 0.665).any()
    y = graded_axis(0.0, 1.0, (0.0, 0.13), 0.05)  # at the lower end: [0, 0.2]
    np.testing.assert_allclose(np.diff(y)[:4], 0.05)
    assert y[0] == 0.0 and np.diff(y)[4] > 0.05


def test_graded_axis_keeps_an_exact_zone_bit_for_bit():
    """A zone that already holds an even number of cells h keeps its end points exactly: a
    rounding shift of 1e-17 moves nodes lying on an obstacle's surface in or out of it (dfg-3d-1z
    at 2 cells/D: C_D 5.87 -> 6.87)."""
    from fbmflow.mesh import graded_axis

    x = graded_axis(0.0, 2.5, (0.4, 0.6), 0.05)
    assert 0.4 in x and 0.45 in x and 0.6 in x


def test_graded_axis_rounds_the_cell_count_to_a_multiple():
    """``multiple`` adds cells to the longer side (a gentler growth, the fine zone untouched) or,
    without sides, to the zone, so that the mesh coarsens ``log2(multiple)`` times."""
    from fbmflow.mesh import graded_axis

    plain = graded_axis(0.0, 0.16, (0.0, 0.1425), 0.0025)
    x = graded_axis(0.0, 0.16, (0.0, 0.1425), 0.0025, multiple=8)
    assert (plain.size - 1) % 8 != 0 and (x.size - 1) % 8 == 0
    np.testing.assert_array_equal(x[:58], plain[:58])  # the fine zone [0, 0.1425]
    assert np.all(np.diff(x) > 0) and np.diff(x).max() <= np.diff(plain).max()
    zone = graded_axis(0.0, 1.0, (0.0, 1.0), 0.1, multiple=4)
    assert zone.size - 1 == 12 and np.allclose(np.diff(zone), 1 / 12)
    with pytest.raises(ValueError, match="even multiple"):
        graded_axis(0.0, 1.0, (0.2, 0.4), 0.1, multiple=3)


def test_cell_size_at_reads_the_cell_that_holds_each_point():
    mesh = StructuredMesh.rectilinear([np.array([0.0, 1.0, 1.5, 1.75]), np.array([0.0, 2.0, 3.0])])
    sizes = mesh.cell_size_at([[0.5, 2.5], [1.6, 0.1], [9.0, -1.0]])
    assert np.array_equal(sizes, [[1.0, 1.0], [0.25, 2.0], [0.25, 2.0]])
    box = StructuredMesh.box((4, 2), upper=(2.0, 3.0))
    assert np.array_equal(box.cell_size_at([[0.1, 0.1]]), [[0.5, 1.5]])
