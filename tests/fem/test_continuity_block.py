"""The continuity block: the level's divergence and the rows that differ, against the same
changes made to an assembled CSR copy."""
import numpy as np
import pytest
import scipy.sparse as sp

from fbmflow.fem.continuity_block import ContinuityBlock, splice_rows, zero_columns


def _divergence(rng, n_cells=6, npl=3, width=5, explicit_zeros=False):
    """A random (n_cells npl, 3 n_cells + 3) CSR with ``width`` sorted columns per row, the rows
    of a cell sharing theirs (the divergence's cell-local pattern)."""
    cols = np.repeat(3 * np.arange(n_cells)[:, None] + np.arange(width), npl, axis=0)
    data = rng.normal(size=cols.size)
    if explicit_zeros:
        data[::7] = 0.0
    return sp.csr_matrix((data, cols.ravel(), np.arange(0, cols.size + 1, width)),
                         shape=(n_cells * npl, 3 * n_cells + 3))


def _same(a: sp.csr_matrix, b: sp.csr_matrix) -> bool:
    """Entry for entry, explicit zeros and order included."""
    return (a.shape == b.shape and np.array_equal(a.indptr, b.indptr) and np.array_equal(a.indices, b.indices)
            and np.array_equal(a.data, b.data))


def _changed(rng):
    """A block with all kinds of changes and the CSR copy changed the same way."""
    BT = _divergence(rng, explicit_zeros=True)
    D, M = ContinuityBlock(BT), BT
    rows = np.array([1, 2, 7])
    inside = sp.csr_matrix(BT[rows].multiply(rng.normal(size=BT[rows].shape)))  # in the rows' pattern
    D, M = D.splice(rows, inside), splice_rows(M, rows, inside)
    rows = np.array([4, 9])
    outside = sp.csr_matrix(rng.normal(size=(2, BT.shape[1])) * (rng.random((2, BT.shape[1])) < 0.3))
    D, M = D.splice(rows, outside), splice_rows(M, rows, outside)
    columns = np.array([0, 5, 11])
    return D.zero_columns(columns), zero_columns(M, columns), BT


def test_changes_match_the_assembled_copy():
    """splice (inside and outside the rows' pattern, twice on one row) and zero_columns give the
    CSR matrix that splice_rows and zero_columns give, entry for entry; the base is not written;
    rows, nnz and the changed rows in place agree."""
    rng = np.random.default_rng(0)
    D, M, BT = _changed(rng)
    before = BT.data.copy()
    assert _same(D.tocsr(), M)
    assert np.array_equal(BT.data, before) and D.base is BT
    assert D.nnz == M.nnz
    assert 0 < D.dofs.size < BT.shape[0]
    rows = np.array([9, 0, 4, 4, 13])
    assert _same(D[rows], M[rows].tocsr())
    assert _same(D[np.isin(np.arange(BT.shape[0]), rows)], M[np.unique(rows)].tocsr())
    changed = D.changed_rows()
    assert np.array_equal(np.flatnonzero(np.diff(changed.indptr)), np.intersect1d(D.dofs, np.flatnonzero(
        np.diff(M.indptr))))
    assert _same(ContinuityBlock(BT).tocsr(), BT) and ContinuityBlock(BT).tocsr() is BT
    kept = ContinuityBlock(BT).zero_columns(np.array([3, 8]))  # every changed row in its pattern
    assert _same(kept.tocsr(), zero_columns(BT, np.array([3, 8])))
    M = kept.tocsr()
    assert np.shares_memory(M.indices, BT.indices) and not np.shares_memory(M.data, BT.data)


@pytest.mark.parametrize("kind", ["vector", "dense", "sparse"])
def test_products_match_the_assembled_copy(kind):
    """D @ v for vectors (the parallel kernel: the same sums, bit for bit), dense and sparse
    matrices, and S @ D for a sparse S (the same sums in the same order: bit for bit)."""
    rng = np.random.default_rng(1)
    D, M, _ = _changed(rng)
    n_p, n_u = M.shape
    if kind == "vector":
        v = rng.normal(size=n_u)
        assert np.array_equal(D @ v, M @ v)
    elif kind == "dense":
        V = rng.normal(size=(n_u, 3))
        assert np.allclose(D @ V, M @ V, rtol=0, atol=1e-14)
    else:
        V = sp.random(n_u, 4, density=0.4, random_state=2, format="csr")
        out = D @ V
        assert sp.issparse(out) and abs(out - M @ V).max() < 1e-14
        # a lifting's few non-zero rows: the rows of the base that reach them only, the same sums
        few = sp.csr_matrix(V.multiply(np.isin(np.arange(n_u), [1, n_u // 2])[:, None]))
        out = D @ few
        assert 0 < np.count_nonzero(np.diff(out.indptr)) < n_p
        assert np.array_equal(out.toarray(), (M @ few).toarray())
    S = sp.random(5, n_p, density=0.15, random_state=3, format="csr")
    assert _same((S @ D).tocsr(), (S @ M).tocsr())


def test_splice_needs_ascending_rows_of_the_right_shape():
    rng = np.random.default_rng(4)
    BT = _divergence(rng)
    with pytest.raises(ValueError, match="changed rows"):
        ContinuityBlock(BT, np.array([1, 2]), sp.csr_matrix((1, BT.shape[1])))
    ragged = sp.csr_matrix((np.ones(3), np.array([0, 1, 2]), np.array([0, 1, 3])), shape=(2, 4))
    with pytest.raises(ValueError, match="same number of entries"):
        ContinuityBlock(ragged)
