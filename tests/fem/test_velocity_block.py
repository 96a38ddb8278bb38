"""The velocity block stored once per scalar against the assembled block it replaces.

The reference is the assembly the Picard path used before: ``d`` copies of ``S`` on the space's
block-diagonal pattern, the constrained rows turned into unit rows, the row constraints written
over them (:meth:`~fbmflow.fem.constraints.RowConstraints.write_rows`). Every operation of
:class:`~fbmflow.fem.velocity_block.VelocityBlock` must give that matrix's answer exactly.
"""
import numpy as np
import pytest
import scipy.sparse as sp

from fbmflow.fem import FlowSpace
from fbmflow.fem.constraints import DirichletConstraints, RowConstraints
from fbmflow.fem.velocity_block import VelocityBlock
from fbmflow.mesh import StructuredMesh
from fbmflow.solvers import _kernels as solver_kernels


def _case(dim, far: bool):
    """A space, ``S`` and constraints with every kind of row: nodes with all components fixed,
    one component fixed, a row-constraint stencil shared by all components (regular), one whose
    components differ (irregular), and (``far``) one that reaches outside the Q2 pattern."""
    space = FlowSpace(StructuredMesh.box((3,) * dim))
    rng = np.random.default_rng(dim)
    n_v, n_u = space.n_v, space.n_u
    S = rng.standard_normal(space.nnz)
    nodes = rng.permutation(n_v)
    full, partial, uniform, mixed = nodes[:4], nodes[4:6], nodes[6:8], nodes[8:9]
    fixed = np.concatenate([full + i * n_v for i in range(dim)] + [partial + n_v])
    rows, entries = [], []
    S_csr = space.scalar_matrix(S)
    for a in uniform:  # the node's own scalar stencil, the same for every component
        cols = S_csr.indices[S_csr.indptr[a]:S_csr.indptr[a + 1]][:3]
        vals = rng.standard_normal(cols.size)
        for i in range(dim):
            rows.append(i * n_v + a)
            entries.append((cols + i * n_v, vals))
    for i in range(dim):  # a different row for every component
        rows.append(i * n_v + mixed[0])
        own = i * n_v + mixed[0]
        entries.append((np.array([own, (own + 1) % n_u]), rng.standard_normal(2)))
    if far:  # a node whose row reaches node 0, outside its cells
        neighbours = S_csr.indices[S_csr.indptr[0]:S_csr.indptr[1]]
        a = int(next(b for b in nodes[9:] if b not in neighbours and b != 0))
        for i in range(dim):
            rows.append(i * n_v + a)
            entries.append((np.array([i * n_v, i * n_v + a]), np.array([0.5, 0.5])))
    order = np.argsort(rows)
    rows = np.array(rows, dtype=np.int64)[order]
    C = sp.csr_matrix((np.concatenate([entries[k][1] for k in order]),
                       (np.repeat(np.arange(rows.size), [entries[k][0].size for k in order]),
                        np.concatenate([entries[k][0] for k in order]))), shape=(rows.size, n_u))
    con = DirichletConstraints(np.sort(np.concatenate([fixed, rows])), np.zeros(fixed.size + rows.size),
                               rows=RowConstraints(rows, C, np.zeros(rows.size)))
    scale = rng.uniform(1.0, 2.0, rows.size)
    return space, S, con, scale


def _reference(space, S, con, scale):
    A = space.coupled_matrix(np.tile(S, space.dim))
    con.zero_rows(A)
    return con.rows.write_rows(A, scale)


@pytest.fixture(params=[(2, False), (2, True), (3, False), (3, True)], ids=["2d", "2d-far", "3d", "3d-far"])
def case(request):
    space, S, con, scale = _case(*request.param)
    block = VelocityBlock(space, S, con.fixed, con.rows.dofs, sp.diags(scale) @ con.rows.matrix)
    return space, block, _reference(space, S, con, scale)


def test_assembled_block_is_the_old_one(case):
    space, block, ref = case
    A = block.tocsr()
    assert (A != ref).nnz == 0
    assert np.array_equal(A.indptr, ref.indptr) and np.array_equal(A.indices, ref.indices)
    assert block.nnz >= ref.count_nonzero()


def test_products_match_the_assembled_block(case):
    space, block, ref = case
    rng = np.random.default_rng(7)
    x = rng.standard_normal(space.n_u)
    assert np.array_equal(block @ x, ref @ x)  # the same sums in the same order
    X = rng.standard_normal((space.n_u, 3))
    assert np.allclose(block @ X, ref @ X, rtol=1e-14, atol=1e-14)
    W = sp.random(space.n_u, 4, density=0.05, random_state=3, format="csc")
    assert abs(block @ W - ref @ W).max() < 1e-14
    local = [1, space.n_v + 1, 2 * space.n_v - 1]  # two nodes' columns: the rows near them only
    W = sp.csc_matrix((rng.standard_normal(3), (local, [0, 1, 1])), shape=(space.n_u, 2))
    assert abs(block @ W - ref @ W).max() == 0.0 and (block @ W).nnz > 0
    assert np.array_equal(block.diagonal(), ref.diagonal())


def test_rows_match_the_assembled_block(case):
    space, block, ref = case
    rows = np.random.default_rng(8).choice(space.n_u, 25, replace=False)
    assert abs(block[rows] - ref[rows]).max() == 0.0
    keep = np.zeros(space.n_u, dtype=bool)
    keep[rows] = True
    assert abs(block.select(keep) - sp.diags(keep.astype(float)) @ ref).max() == 0.0


def test_regular_nodes_and_their_scalar_rows(case):
    """The regular nodes are those the smoother finds in the assembled block; their scalar rows
    are the assembled block's component-0 rows."""
    space, block, ref = case
    regular = solver_kernels.regular_nodes(ref.indptr, ref.indices, ref.data, space.n_v, space.dim)
    assert np.array_equal(block.regular, regular)
    assert not regular.all()  # the case has irregular nodes
    ptr, idx, val = block.scalar_rows(regular, np.float32)
    got = sp.csr_matrix((val, idx, ptr), shape=(space.n_v, space.n_v))
    want = (sp.diags(regular.astype(float)) @ ref[:space.n_v, :space.n_v]).astype(np.float32)
    assert got.dtype == np.float32 and abs(got - want).max() == 0.0
    with pytest.raises(ValueError, match="irregular"):
        block.scalar_rows(~regular)


def test_parts_cover_the_block(case):
    """Every stored entry of the block lies in one of the parts (what the smoother's ordering
    reads to see how far rows reach)."""
    space, block, ref = case
    pattern = sp.csr_matrix(ref.shape)
    for M, offset in block.parts():
        M = sp.coo_matrix(M)
        pattern = pattern + sp.csr_matrix((np.ones(M.nnz), (M.row + offset, M.col + offset)), shape=ref.shape)
    assert ((abs(ref) > 0).astype(float) - (pattern > 0).astype(float)).max() <= 0.0
