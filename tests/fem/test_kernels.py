"""Numba kernels and the assembled Q2/P1disc operators against plain NumPy references.

House rule: every kernel of ``fbmflow.fem._kernels`` is compared with a straightforward NumPy
reference on a tiny mesh (2x2 in 2D, 2x2x2 in 3D) to 1e-12. The meshes are deformed (random
interior vertex moves of ~10 % of h plus a global shear) so that the Jacobians differ between
cells and quadrature points and are not symmetric.

The assembled operators are compared with a dense reference assembly: element matrices by direct
quadrature with physical gradients from ``numpy.linalg.inv`` of the Jacobian, scattered through
``cell_dofs`` into dense arrays.
"""
import numpy as np
import pytest

from fbmflow.fem import (
    FlowSpace,
    _kernels,
    assemble_convection,
    assemble_divergence,
    assemble_laplace,
    assemble_load,
    assemble_mass,
    pressure_mean_weights,
)
from fbmflow.fem.constraints import DirichletConstraints
from fbmflow.fem.elements import ElementQ1, ElementQ2
from fbmflow.fem.quadrature import gauss_tensor
from fbmflow.mesh import StructuredMesh

RTOL = 1e-12
#: float32 storage's rounding (2^-24 = 6e-8 relative per value), summed over a cell's terms
F32 = 1e-6
UPPER = (1.0, 0.75, 1.25)
SHEAR = {2: np.array([[1.0, 0.2], [-0.1, 1.0]]),
         3: np.array([[1.0, 0.2, -0.1], [-0.1, 1.0, 0.15], [0.05, -0.2, 1.0]])}


# -- helpers ----------------------------------------------------------------------------------
def deformed_mesh(dim, periodic=None, shape=None, seed=0, amount=0.1):
    """Tiny box mesh with interior vertices moved randomly by up to ``amount * h`` and sheared.

    Boundary vertices stay on the box faces before the shear; on a periodic axis the two sides
    receive the same displacement, so the mesh stays periodic.
    """
    shape = shape or (2,) * dim
    periodic = periodic or (False,) * dim
    mesh = StructuredMesh.box(shape, upper=UPPER[:dim], periodic=periodic)
    rng = np.random.default_rng(seed)
    disp = amount * mesh.spacing * rng.uniform(-1, 1, size=mesh.vertex_shape + (dim,))
    for d in range(dim):
        sl_lo = [slice(None)] * dim
        sl_hi = [slice(None)] * dim
        sl_lo[d], sl_hi[d] = 0, shape[d]
        if periodic[d]:
            disp[tuple(sl_hi)] = disp[tuple(sl_lo)]
        else:
            disp[tuple(sl_lo)] = 0.0
            disp[tuple(sl_hi)] = 0.0
    # lattice (i, j[, k]) -> vertex number with x fastest: Fortran-order ravel of the lattice axes
    vertices = mesh.vertices + np.moveaxis(disp, -1, 0).reshape(dim, -1, order="F").T
    vertices = vertices @ SHEAR[dim].T
    return StructuredMesh(mesh.shape, mesh.lower, mesh.upper, mesh.periodic, vertices)


def assert_rel(actual, expected, rtol=RTOL):
    actual = np.asarray(actual)
    expected = np.asarray(expected)
    assert actual.shape == expected.shape, (actual.shape, expected.shape)
    scale = max(np.max(np.abs(expected)), 1e-300)
    err = np.max(np.abs(actual - expected)) if expected.size else 0.0
    assert err <= rtol * scale, f"max error {err:.3e} vs scale {scale:.3e}"


def q1_reference(xi):
    """Q1 basis and reference gradients by explicit formulas: (nq, 2**d), (nq, 2**d, d)."""
    nq, dim = xi.shape
    nv = 2**dim
    N = np.ones((nq, nv))
    dN = np.ones((nq, nv, dim))
    for v in range(nv):
        s = np.array([2 * ((v >> d) & 1) - 1 for d in range(dim)], dtype=float)  # x fastest
        f = 0.5 * (1.0 + s[None, :] * xi)  # (nq, d)
        N[:, v] = np.prod(f, axis=1)
        for k in range(dim):
            dN[:, v, k] = 0.5 * s[k] * np.prod(np.delete(f, k, axis=1), axis=1)
    return N, dN


def reference_geometry(mesh, points, weights):
    """detJ w, J^{-1} (c, q, l, i) and physical quadrature points with NumPy linear algebra."""
    N, dN = q1_reference(points)
    X = mesh.cell_coordinates()
    J = np.einsum("cvi,qvl->cqil", X, dN)
    detJ = np.linalg.det(J)
    assert np.all(detJ > 0), "deformed mesh must keep positive Jacobians"
    return detJ * weights[None, :], np.linalg.inv(J), np.einsum("qv,cvi->cqi", N, X)


class DenseReference:
    """Element matrices by direct quadrature, scattered into dense arrays via ``cell_dofs``."""

    def __init__(self, space):
        self.space = space
        mesh = space.mesh
        self.d = d = mesh.dim
        self.n_v = space.n_v
        self.cd = space.V.cell_dofs
        self.points, self.weights = gauss_tensor(d, 3)
        self.phi, self.dphi = ElementQ2(d).tabulate(self.points)
        self.W, self.Jinv, self.xq = reference_geometry(mesh, self.points, self.weights)
        # physical gradients G[c, q, a, i] = sum_l dphi_a/dxi_l dxi_l/dx_i
        self.G = np.einsum("qal,cqli->cqai", self.dphi, self.Jinv)
        X = mesh.cell_coordinates()
        centre = X.mean(axis=1)
        scale = 0.5 * (X.max(axis=1) - X.min(axis=1))
        rel = (self.xq - centre[:, None, :]) / scale[:, None, :]
        self.psi = np.concatenate([np.ones(rel.shape[:2] + (1,)), rel], axis=2)  # (c, q, d+1)

    def _scalar(self, element_matrix):
        A = np.zeros((self.n_v, self.n_v))
        for c, dofs in enumerate(self.cd):
            A[np.ix_(dofs, dofs)] += element_matrix(c)
        return A

    def mass(self):
        return self._scalar(lambda c: np.einsum("q,qa,qb->ab", self.W[c], self.phi, self.phi))

    def laplace(self):
        return self._scalar(lambda c: np.einsum("q,qai,qbi->ab", self.W[c], self.G[c], self.G[c]))

    def _velocity(self, u, c):
        ul = u.reshape(self.d, self.n_v)[:, self.cd[c]]  # (d, nl)
        return np.einsum("ia,qa->qi", ul, self.phi), np.einsum("ia,qak->qik", ul, self.G[c])

    def convection(self, u):
        def element(c):
            uq, _ = self._velocity(u, c)
            return np.einsum("q,qa,qi,qbi->ab", self.W[c], self.phi, uq, self.G[c])
        return self._scalar(element)

    def newton(self, u):
        d, n = self.d, self.n_v
        R = np.zeros((d * n, d * n))
        for c, dofs in enumerate(self.cd):
            _, gu = self._velocity(u, c)
            for i in range(d):
                for k in range(d):
                    local = np.einsum("q,qa,qb,q->ab", self.W[c], self.phi, self.phi, gu[:, i, k])
                    R[np.ix_(i * n + dofs, k * n + dofs)] += local
        return R

    def divergence_t(self):
        d, n = self.d, self.n_v
        BT = np.zeros(((d + 1) * len(self.cd), d * n))
        for c, dofs in enumerate(self.cd):
            local = -np.einsum("q,qm,qai->mia", self.W[c], self.psi[c], self.G[c])
            for m in range(d + 1):
                for i in range(d):
                    BT[c * (d + 1) + m, i * n + dofs] += local[m, i]
        return BT

    def load(self, values):
        F = np.zeros((self.d, self.n_v))
        for c, dofs in enumerate(self.cd):
            F[:, dofs] += np.einsum("q,qi,qa->ia", self.W[c], values[c], self.phi)
        return F.ravel()

    def pressure_weights(self):
        return np.einsum("cq,cqm->cm", self.W, self.psi).ravel()


MESHES = {
    "2d": dict(dim=2),
    "3d": dict(dim=3),
    "2d-periodic-x": dict(dim=2, periodic=(True, False)),
    "2d-periodic-xy": dict(dim=2, periodic=(True, True)),
    "3d-periodic-x": dict(dim=3, periodic=(True, False, False)),
}


@pytest.fixture(scope="module", params=list(MESHES))
def case(request):
    mesh = deformed_mesh(**MESHES[request.param], seed=len(request.param))
    space = FlowSpace(mesh)
    return space, DenseReference(space)


@pytest.fixture(scope="module", params=[2, 3], ids=["2d", "3d"])
def space(request):
    """The house-rule tiny mesh: 2x2 / 2x2x2, deformed."""
    return FlowSpace(deformed_mesh(request.param, seed=10 + request.param))


# -- the scalar pattern ---------------------------------------------------------------------------
def test_the_scalar_pattern_is_numpys(case):
    """``scalar_pattern`` and ``pattern_offsets`` against a sort of every cell's node pairs (the
    NumPy construction they replaced), on every mesh, the periodic ones included, and with more
    chunks than nodes."""
    space, _ = case
    cd, n = space.V.cell_dofs, space.n_v
    keys = (cd[:, :, None] * n + cd[:, None, :]).ravel()
    unique = np.unique(keys)
    indptr = np.concatenate([[0], np.cumsum(np.bincount(unique // n, minlength=n))])
    offsets = np.searchsorted(unique, keys).reshape(cd.shape + cd.shape[1:]) - indptr[cd][:, :, None]
    for chunks in (1, 3, n + 5):
        got_ptr, got_idx = _kernels.scalar_pattern(cd, n, chunks)
        assert np.array_equal(got_ptr, indptr) and np.array_equal(got_idx, unique % n)
    assert np.array_equal(space.offsets, offsets)
    assert space.offsets.dtype == np.uint8 and space.indices.dtype == np.int32


# -- the mesh used here is really deformed ------------------------------------------------------
@pytest.mark.parametrize("dim", [2, 3])
def test_deformed_mesh_is_general(dim):
    mesh = deformed_mesh(dim)
    pts, w = gauss_tensor(dim, 3)
    W, Jinv, _ = reference_geometry(mesh, pts, w)
    # Jacobians vary between points of one cell and are not symmetric
    detJ = W[0] / w
    assert np.ptp(detJ) > 1e-2 * detJ.mean()
    assert np.max(np.abs(Jinv - np.swapaxes(Jinv, 2, 3))) > 1e-2
    # total volume = box volume * det(shear) (boundary vertices stay on the sheared box)
    assert_rel(W.sum(), np.prod(UPPER[:dim]) * np.linalg.det(SHEAR[dim]))


# -- kernels ----------------------------------------------------------------------------------
def test_cell_geometry(space):
    mesh = space.mesh
    pts, w = space.points, space.weights
    _, dN = ElementQ1(mesh.dim).tabulate(pts)
    np.testing.assert_allclose(dN, q1_reference(pts)[1], rtol=0, atol=1e-15)
    detJw, Jinv = _kernels.cell_geometry(mesh.cell_coordinates(), dN, w)
    W_ref, Jinv_ref, _ = reference_geometry(mesh, pts, w)
    assert detJw.shape == (mesh.n_cells, len(w))
    assert Jinv.shape == (mesh.n_cells, len(w), mesh.dim, mesh.dim)
    assert_rel(detJw, W_ref)
    assert_rel(Jinv, Jinv_ref)
    # the space stores exactly these
    assert_rel(space.detJw, W_ref)
    assert_rel(space.Jinv, Jinv_ref)


def test_cell_geometry_orientation():
    """|det J| is used: a mirrored cell has the same weights."""
    mesh = deformed_mesh(2)
    pts, w = gauss_tensor(2, 2)
    _, dN = ElementQ1(2).tabulate(pts)
    X = mesh.cell_coordinates()
    mirrored = X * np.array([-1.0, 1.0])
    detJw, Jinv = _kernels.cell_geometry(X, dN, w)
    detJw_m, Jinv_m = _kernels.cell_geometry(np.ascontiguousarray(mirrored), dN, w)
    assert_rel(detJw_m, detJw)
    J_m = np.einsum("cvi,qvl->cqil", mirrored, dN)
    assert_rel(Jinv_m, np.linalg.inv(J_m))


@pytest.mark.parametrize("chunks", [1, 3, 16])  # one, some, more chunks than cells
@pytest.mark.parametrize("newton", [True, False])
def test_convection_coefficients(space, newton, chunks):
    d, nq = space.dim, len(space.weights)
    rng = np.random.default_rng(20)
    u = np.ascontiguousarray(rng.normal(size=(d, space.n_v)))
    cells = np.array([3, 0, -1, 2], dtype=np.int64)  # any subset, any order, -1 = padding
    conv, react = _kernels.convection_coefficients(cells, u, space.V.cell_dofs, space.phi,
                                                   space.dphi, space.detJw, space.Jinv, newton, chunks)
    conv_ref = np.zeros((len(cells), nq * d))
    react_ref = np.zeros((len(cells) * d * d, nq))
    for e, c in enumerate(cells):
        if c < 0:
            continue
        ul = u[:, space.V.cell_dofs[c]]  # (d, nl)
        for q in range(nq):
            uq = ul @ space.phi[q]  # (d,)
            gref = ul @ space.dphi[q]  # (d, d): d u_i / d xi_l
            conv_ref[e, q * d:(q + 1) * d] = space.detJw[c, q] * space.Jinv[c, q] @ uq
            grad = gref @ space.Jinv[c, q]  # d u_i / d x_k
            for i in range(d):
                for k in range(d):
                    react_ref[(e * d + i) * d + k, q] = space.detJw[c, q] * grad[i, k]
    assert_rel(conv, conv_ref)
    if newton:
        assert_rel(react, react_ref)
    else:
        assert react.shape == (0, nq)


def test_mass_laplace_coefficients(space):
    out = _kernels.mass_laplace_coefficients(space.detJw, space.Jinv, 2.0, -0.5)
    d = space.dim
    ref = -0.5 * np.einsum("cq,cqli,cqmi->cqlm", space.detJw, space.Jinv, space.Jinv)
    upper = np.triu_indices(d)
    n, nq = space.detJw.shape
    assert_rel(out[:, :nq], 2.0 * space.detJw)
    assert_rel(out[:, nq:], ref[:, :, upper[0], upper[1]].reshape(n, -1))


@pytest.mark.parametrize("chunks", [1, 3, 7])
def test_rows_times_is_the_matrix_product(chunks):
    """Chunks of rows, one BLAS product each, in parallel: ``a @ b`` whatever the chunks (7 chunks
    of 5 rows: two empty)."""
    rng = np.random.default_rng(3)
    a, b = rng.standard_normal((5, 4)), rng.standard_normal((4, 6))
    out = np.full((5, 6), np.nan)
    _kernels.rows_times(a, b, out, chunks)
    assert_rel(out, a @ b)



def test_stack_rows_and_continuity_rows_against_scipy():
    """stack_rows: the rows of two CSR matrices in any order (empty rows among them) as SciPy's
    vstack and row selection give them; continuity_rows: rows of a uniform-width base or of the
    changed rows, with and without zeroed columns, as SciPy and np.where give them."""
    import scipy.sparse as sp

    rng = np.random.default_rng(8)

    def random_csr(m, n):
        M = sp.random(m, n, density=0.3, random_state=rng, format="csr")
        M.sort_indices()
        return M

    A, B = random_csr(5, 9), random_csr(5, 9)
    second = np.array([True, False, False, True, True, False, True])
    pos = np.array([3, 0, 4, 0, 2, 2, 1])
    expected = sp.vstack([A, B], format="csr")[np.where(second, A.shape[0] + pos, pos)]
    ptr = np.zeros(pos.size + 1, dtype=np.int64)
    ptr[1:] = np.cumsum(np.where(second, np.diff(B.indptr)[pos], np.diff(A.indptr)[pos]))
    idx, val = np.empty(ptr[-1], dtype=np.int32), np.empty(ptr[-1])
    _kernels.stack_rows(second, pos, A.indptr, A.indices, A.data, B.indptr, B.indices, B.data, ptr, idx, val)
    assert np.array_equal(ptr, expected.indptr) and np.array_equal(idx, expected.indices)
    assert np.array_equal(val, expected.data)

    width, n_rows = 3, 6
    columns = np.sort(np.argsort(rng.random((n_rows, 9)), axis=1)[:, :width], axis=1)  # distinct, sorted
    base = sp.csr_matrix((rng.normal(size=n_rows * width), columns.ravel(),
                          np.arange(0, n_rows * width + 1, width)), shape=(n_rows, 9))
    position = np.array([-1, 1, -1, 0, -1, -1], dtype=np.int32)  # rows 3 and 1: B's rows 0 and 1
    rows = np.array([5, 1, 3, 0, 3])
    for zero in (np.zeros(0, dtype=bool), rng.random(9) < 0.4):
        lengths = np.where(position[rows] >= 0, np.diff(B.indptr)[np.maximum(position[rows], 0)], width)
        ptr = np.concatenate([[0], np.cumsum(lengths)])
        idx, val = np.empty(ptr[-1], dtype=np.int32), np.empty(ptr[-1])
        _kernels.continuity_rows(rows, position, width, base.indices, base.data, B.indptr, B.indices, B.data,
                                 zero, ptr, idx, val)
        own = [B[position[r]] if position[r] >= 0 else base[r] for r in rows]
        assert np.array_equal(idx, np.concatenate([m.indices for m in own]))
        data = np.concatenate([m.data for m in own])
        if zero.size:
            data = np.where(zero[idx], 0.0, data)
        assert np.array_equal(val, data)

def _dense_scalar(space, data):
    return space.scalar_matrix(data).toarray()


def _batches(space):
    """The space's own batches plus a hand-made one: a single group with padding inside."""
    yield from space.batches
    first = space.mesh.cell_colours()[0][0]
    yield np.array([[first[0], -1, first[-1]]], dtype=np.int64)


def test_scatter_scalar(space):
    rng = np.random.default_rng(21)
    nl = space.V.cell_dofs.shape[1]
    out = rng.normal(size=space.nnz)
    ref = _dense_scalar(space, out.copy())
    for cells in _batches(space):
        local = rng.normal(size=(cells.size, nl * nl))
        _kernels.scatter_scalar(cells, local, space.offsets, space.V.cell_dofs, space.indptr, out)
        for e, c in enumerate(cells.ravel()):
            if c < 0:
                continue
            dofs = space.V.cell_dofs[c]
            ref[np.ix_(dofs, dofs)] += local[e].reshape(nl, nl)
    assert_rel(_dense_scalar(space, out), ref)


def test_scatter_coupled(space):
    rng = np.random.default_rng(22)
    d, n = space.dim, space.n_v
    nl = space.V.cell_dofs.shape[1]
    _, sym = space.table_mass_upper
    ia, ib = np.triu_indices(nl)
    out = rng.normal(size=d * d * space.nnz)
    ref = space.coupled_matrix(out.copy()).toarray()
    for cells in _batches(space):
        conv = rng.normal(size=(cells.size, nl * nl))
        react = rng.normal(size=(cells.size * d * d, ia.size))
        _kernels.scatter_coupled(cells, conv, react, sym, space.offsets, space.V.cell_dofs,
                                 space.indptr, d, out)
        for e, c in enumerate(cells.ravel()):
            if c < 0:
                continue
            dofs = space.V.cell_dofs[c]
            for i in range(d):
                for k in range(d):
                    block = np.zeros((nl, nl))
                    block[ia, ib] = react[(e * d + i) * d + k]
                    block[ib, ia] = react[(e * d + i) * d + k]
                    if i == k:
                        block += conv[e].reshape(nl, nl)
                    ref[np.ix_(i * n + dofs, k * n + dofs)] += block
    assert_rel(space.coupled_matrix(out).toarray(), ref)


def test_divergence_local(space):
    rng = np.random.default_rng(24)
    d = space.dim
    n_cells = space.mesh.n_cells
    nl = space.V.cell_dofs.shape[1]
    npl = d + 1
    rank = np.stack([rng.permutation(nl) for _ in range(n_cells)]).astype(np.int64)
    out = np.full(n_cells * npl * d * nl, np.nan)
    _kernels.divergence_local(space.dphi, space.detJw, space.Jinv, space.psi, rank, out)
    ref = np.full_like(out, np.nan)
    for c in range(n_cells):
        grad = np.einsum("qal,qli->qai", space.dphi, space.Jinv[c])
        for m in range(npl):
            for i in range(d):
                for a in range(nl):
                    ref[(c * npl + m) * d * nl + i * nl + rank[c, a]] = \
                        -np.sum(space.psi[c, :, m] * grad[:, a, i] * space.detJw[c])
    assert not np.isnan(out).any()
    assert_rel(out, ref)


def test_set_identity_rows(space):
    rng = np.random.default_rng(25)
    A = space.coupled_matrix(rng.normal(size=space.dim**2 * space.nnz))
    rows = np.sort(rng.choice(space.n_u, size=space.n_u // 3, replace=False)).astype(np.int64)
    ref = A.toarray()
    ref[rows] = 0.0
    ref[rows, rows] = 1.0
    _kernels.set_identity_rows(A.indptr, A.indices, rows, A.data)
    assert_rel(A.toarray(), ref)
    # the same through DirichletConstraints.zero_rows on the scalar pattern
    S = space.scalar_matrix(rng.normal(size=space.nnz))
    rows = space.V.all_boundary_dofs() if space.mesh.tags else np.arange(3, dtype=np.int64)
    ref = S.toarray()
    ref[rows] = 0.0
    ref[rows, rows] = 1.0
    DirichletConstraints(rows, np.zeros(rows.size)).zero_rows(S)
    assert_rel(S.toarray(), ref)


# -- sparsity pattern -------------------------------------------------------------------------
def test_patterns(case):
    space, ref = case
    cd = space.V.cell_dofs
    coupling = np.zeros((space.n_v, space.n_v), dtype=bool)
    for dofs in cd:
        coupling[np.ix_(dofs, dofs)] = True
    S = space.scalar_matrix(np.ones(space.nnz))
    assert S.has_sorted_indices
    np.testing.assert_array_equal(S.toarray() != 0, coupling)
    C = space.coupled_matrix(np.ones(space.dim**2 * space.nnz))
    assert C.has_sorted_indices
    np.testing.assert_array_equal(C.toarray() != 0, np.tile(coupling, (space.dim, space.dim)))
    # the offsets point at the (row, col) entry of the pattern, within the row
    slots = space.indptr[cd][:, :, None] + space.offsets
    assert space.offsets.dtype == np.uint8
    assert np.all(space.offsets < np.diff(space.indptr)[cd][:, :, None])
    np.testing.assert_array_equal(space.indices[slots], np.broadcast_to(cd[:, None, :], slots.shape))


# -- assembled operators vs dense reference ---------------------------------------------------
@pytest.mark.parametrize("batch_size", [None, 1])
def test_assemble_mass(case, batch_size):
    space, ref = case
    if batch_size:
        space = FlowSpace(space.mesh, batch_size=batch_size)
    assert_rel(_dense_scalar(space, assemble_mass(space)), ref.mass())


def test_assemble_laplace(case):
    space, ref = case
    K = _dense_scalar(space, assemble_laplace(space))
    assert_rel(K, ref.laplace())
    assert_rel(K, K.T)
    np.testing.assert_allclose(K.sum(axis=1), 0.0, atol=1e-12 * np.abs(K).max())


@pytest.mark.parametrize("mass_laplace", [None, (2.0, -0.5)], ids=["convection", "with-mass-laplace"])
@pytest.mark.parametrize("newton", [True, False])
@pytest.mark.parametrize("batch_size", [None, 1])
def test_assemble_convection(case, newton, batch_size, mass_laplace):
    """The convection (and Newton) terms added to what is there; with ``mass_laplace`` the mass
    and Laplace terms from the same products (on every diagonal block of the coupled matrix)."""
    space, ref = case
    if batch_size:
        space = FlowSpace(space.mesh, batch_size=batch_size)
    rng = np.random.default_rng(30)
    d = space.dim
    u = rng.normal(size=d * space.n_v)
    scale = -1.3
    scalar0 = rng.normal(size=space.nnz)
    coupled0 = rng.normal(size=d * d * space.nnz)
    K = np.zeros((space.n_v, space.n_v)) if mass_laplace is None else (
        mass_laplace[0] * ref.mass() + mass_laplace[1] * ref.laplace())
    if newton:
        newton_out = coupled0.copy()
        assemble_convection(space, u, scale, newton_out=newton_out, mass_laplace=mass_laplace)
        assert_rel(space.coupled_matrix(newton_out).toarray() - space.coupled_matrix(coupled0).toarray(),
                   scale * (np.kron(np.eye(d), ref.convection(u)) + ref.newton(u)) + np.kron(np.eye(d), K))
    else:
        scalar_out = scalar0.copy()
        assemble_convection(space, u, scale, scalar_out=scalar_out, mass_laplace=mass_laplace)
        assert_rel(_dense_scalar(space, scalar_out) - _dense_scalar(space, scalar0),
                   scale * ref.convection(u) + K)


def test_assemble_convection_needs_one_output(case):
    space, _ = case
    with pytest.raises(ValueError, match="exactly one"):
        assemble_convection(space, np.zeros(space.n_u), 1.0)


def test_convection_newton_is_jacobian(case):
    """kron(I, N(u)) + R(u) is the derivative of u -> N(u) u (exact central difference)."""
    space, _ = case
    d, n = space.dim, space.n_v
    rng = np.random.default_rng(31)
    u, du = rng.normal(size=d * n), rng.normal(size=d * n)

    def residual(w):
        S = np.zeros(space.nnz)
        assemble_convection(space, w, 1.0, scalar_out=S)
        return (space.scalar_matrix(S) @ w.reshape(d, n).T).T.ravel()

    Jd = np.zeros(d * d * space.nnz)
    assemble_convection(space, u, 1.0, newton_out=Jd)
    eps = 1e-3  # residual is quadratic: the central difference is exact up to round-off
    fd = (residual(u + eps * du) - residual(u - eps * du)) / (2 * eps)
    assert_rel(space.coupled_matrix(Jd) @ du, fd, rtol=1e-9)


def test_assemble_divergence(case):
    space, ref = case
    BT = assemble_divergence(space)
    assert BT.shape == (space.n_p, space.n_u)
    assert BT.has_sorted_indices
    assert_rel(BT.toarray(), ref.divergence_t())
    # B = B^T.T is the gradient operator
    assert_rel(BT.T.toarray(), ref.divergence_t().T)


def test_divergence_of_polynomial_fields(case):
    """B^T u = 0 for constant u; for u = x_i e_i (in Q2 on Q1-mapped cells) B^T u = -int psi."""
    space, _ = case
    BT = assemble_divergence(space)
    d, n = space.dim, space.n_v
    x = space.V.coordinates
    for i in range(d):
        const = np.zeros((d, n))
        const[i] = 1.0
        np.testing.assert_allclose(BT @ const.ravel(), 0.0, atol=1e-13)
        if any(space.mesh.periodic):
            continue  # x is not a periodic field
        lin = np.zeros((d, n))
        lin[i] = x[:, i]
        assert_rel(BT @ lin.ravel(), -pressure_mean_weights(space))


def test_assemble_load(case):
    space, ref = case
    rng = np.random.default_rng(33)
    values = rng.normal(size=space.xq.shape)
    assert space.xq.shape == (space.mesh.n_cells, len(space.weights), space.dim)
    assert_rel(space.xq, ref.xq)
    F = assemble_load(space, values)
    assert F.shape == (space.n_u,)
    assert_rel(F, ref.load(values))
    # a constant load integrates to volume * f
    ones = np.ones_like(values)
    assert_rel(assemble_load(space, ones).reshape(space.dim, -1).sum(axis=1),
               np.full(space.dim, ref.W.sum()))


def test_pressure_mean_weights(case):
    space, ref = case
    w = pressure_mean_weights(space)
    assert w.shape == (space.n_p,)
    assert_rel(space.psi, ref.psi)
    assert_rel(w, ref.pressure_weights())
    p_one = np.zeros(space.n_p)
    p_one[::space.dim + 1] = 1.0
    assert_rel(w @ p_one, ref.W.sum())


# -- matrix-free operators ----------------------------------------------------------------------
def test_reaction_coefficients(space):
    d = space.dim
    u = np.random.default_rng(40).normal(size=(d, space.n_v))
    react = _kernels.reaction_coefficients(u, space.V.cell_dofs, space.phi, space.dphi, space.detJw,
                                           space.Jinv)
    gref = np.einsum("icb,qbl->cqil", u[:, space.V.cell_dofs], space.dphi)
    assert react.dtype == np.float32  # stored rounded: a Jacobian's term
    assert_rel(react, np.einsum("cqil,cqlk,cq->cqik", gref, space.Jinv, space.detJw), rtol=F32)


def test_apply_mass_laplace(case):
    """The cell-by-cell product equals the dense reference's ``(alpha M + beta L) u_i`` per component."""
    from fbmflow.fem import apply_mass_laplace
    space, ref = case
    u = np.random.default_rng(43).normal(size=space.n_u)
    out = apply_mass_laplace(space, 2.0, -0.5, u)
    K = 2.0 * ref.mass() - 0.5 * ref.laplace()
    assert_rel(out, (K @ u.reshape(space.dim, -1).T).T.ravel())


def test_apply_mass_laplace_with_convection_is_the_sum_of_its_terms(case):
    """The residual's one pass: ``(alpha M + beta L + gamma N(u)) u`` is the products' sum."""
    from fbmflow.fem import apply_convection, apply_mass_laplace
    space, _ = case
    u = np.random.default_rng(44).normal(size=space.n_u)
    want = apply_mass_laplace(space, 2.0, -0.5, u)
    apply_convection(space, u, 0.7, want)
    assert_rel(apply_mass_laplace(space, 2.0, -0.5, u, convection=0.7), want)


def test_assemble_mass_laplace(case):
    from fbmflow.fem import assemble_mass_laplace
    space, ref = case
    K = _dense_scalar(space, assemble_mass_laplace(space, 2.0, -0.5))
    assert_rel(K, 2.0 * ref.mass() - 0.5 * ref.laplace())


@pytest.mark.parametrize("axes", [([0.0, 0.3, 1.0], [0.0, 0.2, 0.3, 0.75]),
                                  ([0.0, 0.3, 1.0], [0.0, 0.5, 0.75], [0.0, 0.1, 0.4, 1.25])],
                         ids=["2d", "3d"])
def test_assemble_mass_laplace_on_axis_aligned_cells(axes):
    """Graded box cells take the few-coefficient table (``cell_axes``); the result is the dense
    reference's. The deformed meshes of ``case`` take the general one (the test above)."""
    from fbmflow.fem import assemble_mass, assemble_mass_laplace
    space = FlowSpace(StructuredMesh.rectilinear(axes))
    ref = DenseReference(space)
    assert space.cell_axes is not None and space.cell_axes.shape == (space.mesh.n_cells, 1 + space.dim)
    K = _dense_scalar(space, assemble_mass_laplace(space, 2.0, -0.5))
    assert_rel(K, 2.0 * ref.mass() - 0.5 * ref.laplace())
    assert_rel(_dense_scalar(space, assemble_mass(space)), ref.mass())
    u = np.random.default_rng(33).normal(size=space.n_u)
    S = np.zeros(space.nnz)
    assemble_convection(space, u, 0.7, scalar_out=S, mass_laplace=(2.0, -0.5))
    assert_rel(_dense_scalar(space, S), 0.7 * ref.convection(u) + 2.0 * ref.mass() - 0.5 * ref.laplace())
    assert FlowSpace(deformed_mesh(space.dim, seed=3)).cell_axes is None


def test_apply_reaction_is_the_newton_term(case):
    """``R(u) w`` without a matrix equals the assembled Newton blocks times ``w``, over all cells
    and over only the cells that touch the support of ``w``."""
    from fbmflow.fem import apply_reaction, reaction_coefficients
    space, ref = case
    rng = np.random.default_rng(41)
    u, w = rng.normal(size=space.n_u), rng.normal(size=space.n_u)
    react = reaction_coefficients(space, u)
    out = rng.normal(size=space.n_u)
    expected = out + 0.7 * ref.newton(u) @ w
    apply_reaction(space, react, w, 0.7, out)
    assert_rel(out, expected, rtol=F32)
    local = np.zeros(space.n_u)
    local[[0, space.n_v + 1]] = 1.0  # two nodes of a corner cell
    cells = np.flatnonzero(np.isin(space.V.cell_dofs, [0, 1]).any(axis=1))
    out = np.zeros(space.n_u)
    apply_reaction(space, react, local, 1.0, out, cells=cells)
    assert_rel(out, ref.newton(u) @ local, rtol=F32)


def test_apply_convection_is_n_of_u_times_u(case):
    from fbmflow.fem import apply_convection
    space, ref = case
    d, n = space.dim, space.n_v
    u = np.random.default_rng(42).normal(size=space.n_u)
    out = np.ones(space.n_u)
    apply_convection(space, u, -1.5, out)
    expected = 1.0 - 1.5 * (ref.convection(u) @ u.reshape(d, n).T).T.ravel()
    assert_rel(out, expected)


def test_velocity_coefficients(space):
    from fbmflow.fem import velocity_coefficients
    u = np.random.default_rng(44).normal(size=space.n_u)
    uq = np.einsum("icb,qb->cqi", u.reshape(space.dim, space.n_v)[:, space.V.cell_dofs], space.phi)
    assert_rel(velocity_coefficients(space, u), uq * space.detJw[:, :, None])


def test_apply_convection_by_another_velocity_is_n_of_c_times_w(case):
    """``N(c) w`` with a convecting field other than the convected one (the Newton block's
    drift), over all cells and over the cells of a local field only."""
    from fbmflow.fem import apply_convection, velocity_coefficients
    space, ref = case
    d, n = space.dim, space.n_v
    rng = np.random.default_rng(45)
    c, w = rng.normal(size=space.n_u), rng.normal(size=space.n_u)
    conv = velocity_coefficients(space, c)
    out = np.ones(space.n_u)
    apply_convection(space, w, 0.7, out, conv=conv)
    assert_rel(out, 1.0 + 0.7 * (ref.convection(c) @ w.reshape(d, n).T).T.ravel())
    local = np.zeros(space.n_u)
    local[[0, n + 1]] = 1.0  # two nodes of a corner cell
    cells = np.flatnonzero(np.isin(space.V.cell_dofs, [0, 1]).any(axis=1))
    out = np.zeros(space.n_u)
    apply_convection(space, local, 1.0, out, conv=conv, cells=cells)
    assert_rel(out, (ref.convection(c) @ local.reshape(d, n).T).T.ravel())


def test_cell_groups_hold_the_kept_cells_once_in_dof_disjoint_rows(case):
    """The groups of a particle's neighbourhood: every kept cell once, no other cell, the rows
    of a batch sharing no DOF; the convection applied through them equals the sequential one."""
    from fbmflow.fem import apply_convection, velocity_coefficients
    space, _ = case
    keep = np.zeros(space.mesh.n_cells, dtype=bool)
    keep[space.mesh.n_cells // 3: space.mesh.n_cells // 3 + 5] = True
    everything = space.cell_groups(np.ones(space.mesh.n_cells, dtype=bool))
    assert all(np.array_equal(a, b) for a, b in zip(everything, space.colour_groups, strict=True))
    groups = space.cell_groups(keep)
    held = np.concatenate([g[g >= 0] for g in groups])
    assert np.array_equal(np.sort(held), np.flatnonzero(keep))
    for g in groups:
        rows = [set(space.V.cell_dofs[r[r >= 0]].ravel()) for r in g]
        assert all(not (a & b) for i, a in enumerate(rows) for b in rows[i + 1:])
    rng = np.random.default_rng(46)
    conv, w = velocity_coefficients(space, rng.normal(size=space.n_u)), rng.normal(size=space.n_u)
    grouped, sequential = np.zeros(space.n_u), np.zeros(space.n_u)
    apply_convection(space, w, 0.7, grouped, conv=conv, groups=groups)
    apply_convection(space, w, 0.7, sequential, conv=conv, cells=np.flatnonzero(keep))
    assert_rel(grouped, sequential)


def test_balanced_pieces_share_the_cells_not_the_slabs():
    """Slabs of 1, 1, 1, 10, 10, 1 cells between two threads: 13 and 11 cells (cutting by slab
    count, as before, gave 3 and 21), the runs consecutive; never an empty run."""
    from fbmflow.fem.space import _balanced_pieces
    slabs = [np.arange(n) for n in (1, 1, 1, 10, 10, 1)]
    pieces = _balanced_pieces(slabs, 2)
    assert [sum(s.size for s in p) for p in pieces] == [13, 11]
    assert [s for p in pieces for s in p] == slabs
    assert [len(p) for p in _balanced_pieces(slabs[:1], 4)] == [1]
    assert [len(p) for p in _balanced_pieces([np.arange(4)] * 32, 2)] == [16, 16]


@pytest.mark.parametrize("dim", [2, 3])
def test_free_node_components_equal_scipy_on_the_masked_cell_graph(dim):
    """The union-find kernel against scipy.sparse.csgraph on the graph of free nodes that share a
    cell: the nodes of two distant cells and one node between them free (several components)."""
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import connected_components

    from fbmflow.mesh import StructuredMesh

    space = FlowSpace(StructuredMesh.box((4,) * dim))
    free = np.zeros(space.n_v, dtype=bool)  # every node of two cells apart from each other, and one more
    for cell in (0, space.mesh.n_cells - 1):
        free[space.V.cell_dofs[cell]] = True
    free[space.V.cell_dofs[space.mesh.n_cells // 2][0]] = True
    rows = np.repeat(np.arange(space.n_v), np.diff(space.indptr))
    for free in (free, np.random.default_rng(dim).random(space.n_v) < 0.15):  # and a random few
        labels = space.free_node_components(free)
        assert np.all(labels[~free] == -1)
        keep = free[rows] & free[space.indices]
        graph = csr_matrix((np.ones(keep.sum()), (rows[keep], space.indices[keep])), shape=(space.n_v,) * 2)
        n, reference = connected_components(graph, directed=False)
        ours = labels[free]
        assert np.unique(ours).size == np.unique(reference[free]).size > 1
        # the same partition: each of our labels maps to one reference label and back
        pairs = np.unique(np.column_stack([ours, reference[free]]), axis=0)
        assert len(pairs) == np.unique(ours).size
        for label in np.unique(ours):  # the component's smallest node
            assert label == np.flatnonzero(labels == label)[0]


def test_uniform_rows_apply_and_rows_touching(space):
    """The divergence's rows (the same number of entries in each, the continuity block's base):
    the parallel product and the rows that touch a column mask, against NumPy."""
    BT = assemble_divergence(space)
    width = BT.indptr[1] - BT.indptr[0]
    rng = np.random.default_rng(5)
    x = rng.normal(size=BT.shape[1])
    out = np.empty(BT.shape[0])
    _kernels.uniform_rows_apply(BT.indices, BT.data, width, x, out)
    assert_rel(out, (BT.data.reshape(-1, width) * x[BT.indices.reshape(-1, width)]).sum(axis=1))
    mask = np.zeros(BT.shape[1], dtype=bool)
    mask[0] = True  # the first node's first component: the rows of the cells at that corner
    touched = _kernels.rows_touching(BT.indices, BT.shape[0], width, mask)
    assert np.array_equal(touched, mask[BT.indices.reshape(-1, width)].any(axis=1))
    assert 0 < touched.sum() < BT.shape[0]
