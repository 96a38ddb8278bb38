"""Continuity rows replaced cell by cell: their product without a copy of ``B^T``."""
import numpy as np
import pytest
import scipy.sparse as sp

from fbmflow.fem.constraints import ContinuityRows
from fbmflow.fem.continuity_block import ContinuityBlock


@pytest.mark.parametrize("sparse", [False, True])
def test_the_replaced_rows_product_equals_the_copied_matrix(sparse):
    """``ContinuityRows.product(BT, U)`` equals ``apply(BT) @ U`` (dense and sparse ``U``, two
    columns) and leaves ``BT`` as it was; cells 1 and 3 of four replaced, overlapping columns."""
    rng = np.random.default_rng(5)
    npl, width, n_cells = 3, 6, 4
    cols = np.repeat(3 * np.arange(n_cells)[:, None] + np.arange(width), npl, axis=0)
    BT = sp.csr_matrix((rng.normal(size=cols.size), cols.ravel(), np.arange(0, cols.size + 1, width)),
                       shape=(n_cells * npl, 3 * n_cells + 3))
    before = BT.data.copy()
    rows = ContinuityRows(np.array([1, 3]), rng.normal(size=(2, npl, width)))
    U = rng.normal(size=(BT.shape[1], 2))
    if sparse:
        U[rng.random(U.shape) < 0.5] = 0.0
        U = sp.csr_matrix(U)
    out = rows.product(BT, U)
    ref = rows.apply(ContinuityBlock(BT)) @ U
    ref = ref.toarray() if sp.issparse(ref) else ref
    assert isinstance(out, np.ndarray) and out.shape == (n_cells * npl, 2)
    assert np.allclose(out, ref, rtol=0, atol=1e-14)
    assert not np.allclose(out, (BT @ U).toarray() if sparse else BT @ U)  # the rows were replaced
    assert np.array_equal(BT.data, before)
