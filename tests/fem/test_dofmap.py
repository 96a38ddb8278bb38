"""Q2 and P1disc DOF maps on structured meshes, periodic directions included."""
import itertools

import numpy as np
import pytest

from fbmflow.fem import DofMap, PressureDofMap
from fbmflow.mesh import StructuredMesh

CASES = [
    ((2, 3), (False, False)),
    ((2, 3), (True, False)),
    ((3, 2), (False, True)),
    ((2, 2), (True, True)),
    ((2, 2, 3), (False, False, False)),
    ((2, 3, 2), (True, False, True)),
    ((2, 2, 2), (True, True, True)),
]
IDS = ["x".join(map(str, s)) + "-p" + "".join("xyz"[d] for d in range(len(s)) if p[d])
       for s, p in CASES]


def _moved(mesh, seed=0, amount=0.1):
    """Move the interior vertices randomly (boundary vertices stay on the box)."""
    rng = np.random.default_rng(seed)
    idx = np.stack(np.unravel_index(np.arange(mesh.n_vertices), mesh.vertex_shape, order="F"), axis=1)
    interior = np.all((idx > 0) & (idx < np.array(mesh.shape)), axis=1)
    v = mesh.vertices.copy()
    v[interior] += amount * mesh.spacing * rng.uniform(-1, 1, size=(interior.sum(), mesh.dim))
    return StructuredMesh(mesh.shape, mesh.lower, mesh.upper, mesh.periodic, v)


def _local_numbers(dim, fixed_axis, value):
    """Local Q2 node numbers whose index along ``fixed_axis`` equals ``value``, in lattice order."""
    out = []
    for idx in itertools.product(*[range(3)] * dim):
        if idx[fixed_axis] == value:
            out.append(sum(idx[d] * 3**d for d in range(dim)))
    return np.sort(np.array(out))


@pytest.mark.parametrize("shape,periodic", CASES, ids=IDS)
def test_sizes(shape, periodic):
    mesh = StructuredMesh.box(shape, periodic=periodic)
    V = DofMap(mesh)
    expected_lattice = tuple(2 * n if p else 2 * n + 1 for n, p in zip(shape, periodic))
    assert V.lattice_shape == expected_lattice
    assert V.n_dofs == np.prod(expected_lattice)
    dim = len(shape)
    assert V.cell_dofs.shape == (mesh.n_cells, 3**dim)
    assert V.cell_dofs.dtype == np.int64
    # every DOF is used, and no cell repeats a DOF
    assert np.array_equal(np.unique(V.cell_dofs), np.arange(V.n_dofs))
    for row in V.cell_dofs:
        assert np.unique(row).size == row.size
    assert V.lattice.shape == (V.n_dofs, dim)
    assert V.coordinates.shape == (V.n_dofs, dim)
    assert "n_dofs=" in repr(V)


def test_sizes_explicit():
    assert DofMap(StructuredMesh.box((2, 3))).n_dofs == 5 * 7
    assert DofMap(StructuredMesh.box((2, 3), periodic=(True, False))).n_dofs == 4 * 7
    assert DofMap(StructuredMesh.box((2, 3), periodic=(True, True))).n_dofs == 4 * 6
    assert DofMap(StructuredMesh.box((2, 2, 2))).n_dofs == 125
    assert DofMap(StructuredMesh.box((2, 2, 2), periodic=(False, True, False))).n_dofs == 5 * 4 * 5


@pytest.mark.parametrize("shape,periodic", CASES, ids=IDS)
def test_cell_dofs_lattice_numbering(shape, periodic):
    """Cell (a, b[, c]) owns lattice points (2a + i, ...) mod lattice shape, DOF I + L_x (J + L_y K)."""
    mesh = StructuredMesh.box(shape, periodic=periodic)
    V = DofMap(mesh)
    dim = len(shape)
    L = V.lattice_shape
    cidx = mesh.cell_indices()
    for c in range(mesh.n_cells):
        for loc in itertools.product(*[range(3)] * dim):
            a = sum(loc[d] * 3**d for d in range(dim))
            lat = [(2 * cidx[c, d] + loc[d]) % L[d] for d in range(dim)]
            dof = lat[0] + L[0] * (lat[1] + L[1] * (lat[2] if dim == 3 else 0))
            assert V.cell_dofs[c, a] == dof
            np.testing.assert_array_equal(V.lattice[dof], lat)


@pytest.mark.parametrize("shape,periodic", CASES, ids=IDS)
def test_neighbours_share_face_dofs(shape, periodic):
    mesh = StructuredMesh.box(shape, periodic=periodic)
    V = DofMap(mesh)
    dim = len(shape)
    cidx = mesh.cell_indices()
    strides = np.cumprod((1,) + shape[:-1])
    for c in range(mesh.n_cells):
        for d in range(dim):
            nb_idx = cidx[c].copy()
            nb_idx[d] += 1
            if nb_idx[d] == shape[d]:
                if not periodic[d]:
                    continue
                nb_idx[d] = 0
            nb = int((nb_idx * strides).sum())
            upper_face = V.cell_dofs[c, _local_numbers(dim, d, 2)]
            lower_face = V.cell_dofs[nb, _local_numbers(dim, d, 0)]
            np.testing.assert_array_equal(upper_face, lower_face)
            shared = np.intersect1d(V.cell_dofs[c], V.cell_dofs[nb])
            if shape[d] == 2 and periodic[d]:
                # two cells on a periodic axis touch on both sides
                assert shared.size == 2 * 3 ** (dim - 1)
            else:
                assert shared.size == 3 ** (dim - 1)
                np.testing.assert_array_equal(np.sort(upper_face), shared)


@pytest.mark.parametrize("dim", [2, 3])
def test_cells_sharing_only_an_edge_or_vertex(dim):
    mesh = StructuredMesh.box((2,) * dim)
    V = DofMap(mesh)
    # diagonal neighbours 0 and 3 (2D: share one vertex; 3D: share an edge of 3 nodes)
    shared = np.intersect1d(V.cell_dofs[0], V.cell_dofs[3])
    assert shared.size == (1 if dim == 2 else 3)
    # the corner node (2, 2[, .]) of cell 0 is node (0, 0[, .]) of cell 3
    assert V.cell_dofs[0, 2 + 3 * 2] == V.cell_dofs[3, 0]


@pytest.mark.parametrize("dim", [2, 3])
def test_periodic_identification(dim):
    shape = (3,) + (2,) * (dim - 1)
    periodic = (True,) + (False,) * (dim - 1)
    mesh = StructuredMesh.box(shape, periodic=periodic)
    V = DofMap(mesh)
    L = V.lattice_shape
    assert L[0] == 6
    last = np.flatnonzero(mesh.cell_indices()[:, 0] == shape[0] - 1)
    first = np.flatnonzero(mesh.cell_indices()[:, 0] == 0)
    for c_last, c_first in zip(last, first):
        right = V.cell_dofs[c_last, _local_numbers(dim, 0, 2)]
        left = V.cell_dofs[c_first, _local_numbers(dim, 0, 0)]
        np.testing.assert_array_equal(right, left)
        # the identified layer has lattice x index 0
        assert np.all(V.lattice[right, 0] == 0)
    # the lattice never reaches index 2 n along x
    assert V.lattice[:, 0].max() == 2 * shape[0] - 1


@pytest.mark.parametrize("shape,periodic", CASES, ids=IDS)
def test_coordinates_match_cell_map(shape, periodic):
    mesh = StructuredMesh.box(shape, upper=(2.0, 1.0, 1.5)[:len(shape)], periodic=periodic)
    if not any(periodic):
        mesh = _moved(mesh, seed=1)
    V = DofMap(mesh)
    x_cell = mesh.map_to_physical(V.element.nodes)  # (n_cells, nl, dim)
    x_dof = V.coordinates[V.cell_dofs]
    period = np.array(mesh.upper) - np.array(mesh.lower)
    diff = x_cell - x_dof
    for d in range(mesh.dim):
        if periodic[d]:
            # identified nodes carry the lower-side coordinate: differ by exactly one period
            wrapped = np.isclose(diff[..., d], period[d], rtol=0, atol=1e-12)
            diff[..., d] = np.where(wrapped, 0.0, diff[..., d])
            assert wrapped.any()
    np.testing.assert_allclose(diff, 0.0, rtol=0, atol=1e-13)
    # every coordinate lies in the box, the lower side for periodic axes
    assert np.all(V.coordinates >= np.array(mesh.lower) - 1e-13)
    for d in range(mesh.dim):
        if periodic[d]:
            assert np.all(V.coordinates[:, d] < mesh.upper[d] - 1e-13)


@pytest.mark.parametrize("dim", [2, 3])
def test_coordinates_deformed(dim):
    mesh = _moved(StructuredMesh.box((2,) * dim), seed=2)
    assert not mesh.is_uniform
    V = DofMap(mesh)
    np.testing.assert_allclose(V.coordinates[V.cell_dofs], mesh.map_to_physical(V.element.nodes),
                               rtol=0, atol=1e-14)
    # vertices are Q2 nodes at even lattice positions
    vidx = np.stack(np.unravel_index(np.arange(mesh.n_vertices), mesh.vertex_shape, order="F"), axis=1)
    dofs = np.ravel_multi_index(tuple((2 * vidx).T), V.lattice_shape, order="F")
    np.testing.assert_allclose(V.coordinates[dofs], mesh.vertices, atol=1e-15)


@pytest.mark.parametrize("shape,periodic", CASES, ids=IDS)
def test_boundary_dofs(shape, periodic):
    lower = (-1.0, 0.0, 0.5)[:len(shape)]
    upper = (1.0, 2.0, 1.0)[:len(shape)]
    mesh = StructuredMesh.box(shape, lower, upper, periodic)
    V = DofMap(mesh)
    x = V.coordinates
    for tag in mesh.tags:
        axis = "xyz".index(tag[0])
        value = lower[axis] if tag.endswith("min") else upper[axis]
        b = V.boundary_dofs(tag)
        expected = np.flatnonzero(np.isclose(x[:, axis], value, rtol=0, atol=1e-12))
        np.testing.assert_array_equal(b, expected)
        assert b.size == np.prod([L for d, L in enumerate(V.lattice_shape) if d != axis])
        assert np.all(np.diff(b) > 0)
    for d in range(len(shape)):
        if periodic[d]:
            with pytest.raises(ValueError, match="unknown boundary tag"):
                V.boundary_dofs("xyz"[d] + "min")
    allb = V.all_boundary_dofs()
    expected = np.unique(np.concatenate([V.boundary_dofs(t) for t in mesh.tags])) if mesh.tags \
        else np.zeros(0, np.int64)
    np.testing.assert_array_equal(allb, expected)
    if not mesh.tags:
        assert allb.size == 0
    else:
        interior = np.ones(V.n_dofs, bool)
        interior[allb] = False
        on_face = np.zeros(V.n_dofs, bool)
        for d in range(len(shape)):
            if not periodic[d]:
                on_face |= np.isclose(x[:, d], lower[d]) | np.isclose(x[:, d], upper[d])
        np.testing.assert_array_equal(on_face, ~interior)


@pytest.mark.parametrize("dim", [2, 3])
def test_pressure_dofmap(dim):
    mesh = _moved(StructuredMesh.box((2,) * dim), seed=3)
    Q = PressureDofMap(mesh)
    assert Q.n_local == dim + 1
    assert Q.n_dofs == mesh.n_cells * (dim + 1)
    np.testing.assert_array_equal(Q.cell_dofs, np.arange(Q.n_dofs).reshape(mesh.n_cells, dim + 1))
    coords = mesh.cell_coordinates()
    np.testing.assert_allclose(Q.centre, coords.mean(axis=1))
    np.testing.assert_allclose(Q.scale, 0.5 * (coords.max(axis=1) - coords.min(axis=1)))


@pytest.mark.parametrize("shape", [(5, 4), (3, 4, 2)])
def test_node_cell_ranks_and_incidence(shape):
    """Every node's cells (ascending) and its place among each one's nodes in ascending order,
    against the cell-DOF table directly; the node-cell incidence is the same cells."""
    import scipy.sparse as sp

    from fbmflow.fem.space import FlowSpace
    s = FlowSpace(StructuredMesh.box(shape))
    cd = s.V.cell_dofs
    ptr, cells, ranks = s.node_cell_ranks
    nodes = np.repeat(np.arange(s.n_v), np.diff(ptr))
    assert np.array_equal(np.sort(cd, axis=1)[cells, ranks], nodes)
    assert np.array_equal(np.bincount(cd.ravel(), minlength=s.n_v), np.diff(ptr))
    assert all(np.all(np.diff(cells[ptr[a]:ptr[a + 1]]) > 0) for a in range(s.n_v))
    n_cells, nl = cd.shape
    ref = sp.csr_matrix((np.ones(n_cells * nl), (cd.ravel(), np.repeat(np.arange(n_cells), nl))),
                        shape=(s.n_v, n_cells))
    assert (s.node_cells != ref).nnz == 0
