"""The sweep order of the Vanka smoothers (slabs and blocks) and the parallel mat-vec."""
import numba
import numpy as np
import pytest
import scipy.sparse as sp

from fbmflow.mesh import StructuredMesh
from fbmflow.solvers import ordering
from fbmflow.solvers.sparse import PARALLEL_NNZ, matvec


def _groups(phases):
    """Per phase, the list of its groups' patch indices."""
    return [[order[gptr[g]:gptr[g + 1]] for g in range(gptr.size - 1)] for gptr, order in phases]


@pytest.mark.parametrize("shape, periodic, reach, blocks", [
    ((40, 40, 64), (False, False, False), 2, True),      # ten Cate level 1: blocks
    ((20, 20, 32), (False, False, False), 2, False),     # too small for blocks
    ((48, 48, 32), (True, False, True), 2, True),        # periodic axes
    ((160, 128), (False, False), 6, True),               # 2D, a wider reach
    ((32, 96), (False, True), 2, False),
])
def test_groups_of_a_phase_are_independent(shape, periodic, reach, blocks):
    """Every cell is swept once, each group in lexicographic order; two cells of different
    groups of one phase lie at least ``gap`` layers apart along some axis (modulo the period),
    so that no group touches a DOF another reads."""
    mesh = StructuredMesh.box(shape, periodic=periodic)
    index = mesh.cell_indices()
    phases = ordering.slab_phases(mesh.shape, mesh.periodic, index, np.arange(mesh.n_cells), reach)
    assert (len(phases) == 4) == blocks
    swept = np.concatenate([order for _, order in phases])
    assert np.array_equal(np.sort(swept), np.arange(mesh.n_cells))
    gap = int(np.floor(1 + reach / 2)) + 1
    n = np.array(shape)
    for groups in _groups(phases):
        assert len(groups) >= 2
        for g in groups:
            assert np.all(np.diff(g) > 0)  # lexicographic
        # per group and axis: the set of layers it occupies
        layers = [[np.unique(index[g, a]) for a in range(mesh.dim)] for g in groups]
        for i in range(len(groups)):
            for j in range(i + 1, len(groups)):
                apart = False
                for a in range(mesh.dim):
                    diff = np.abs(layers[i][a][:, None] - layers[j][a][None, :])
                    if periodic[a]:
                        diff = np.minimum(diff, n[a] - diff)
                    apart |= bool(diff.min() >= gap)
                assert apart, (i, j)


def test_a_sweep_does_not_depend_on_the_number_of_threads(monkeypatch):
    """Blocks on a small mesh (the thresholds lowered): a factored Vanka smoother gives the same
    bits at one thread as at two, those of the sequential sweep in the phases' order."""
    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("needs two Numba threads")
    from fbmflow.flow import Dirichlet, NavierStokesProblem, NoSlip
    from fbmflow.scenes.cavity import recirculating_state
    from fbmflow.solvers.vanka import FactoredVankaSmoother
    monkeypatch.setattr(ordering, "BLOCK_CELLS", 16)
    monkeypatch.setattr(ordering, "MIN_SLAB_LAYERS", 2)
    mesh = StructuredMesh.box((24, 24))
    bcs = {t: NoSlip() for t in mesh.tags}
    bcs["ymax"] = Dirichlet((1.0, 0.0))
    prob = NavierStokesProblem(mesh, 0.01, bcs)
    x0, con = recirculating_state(prob), prob.constraints()
    b = -prob.residual(x0, 10.0, 1.0, prob.load(), con)
    system = prob.linear_system(x0, 10.0, 1.0, con)
    smoother = FactoredVankaSmoother(system)
    assert len(smoother.sweeps[0]) == 4
    out = []
    before = numba.get_num_threads()
    try:
        for threads in (1, 2):
            numba.set_num_threads(threads)
            x = np.zeros_like(b)
            smoother.smooth(b, x, 2)
            out.append(x)
    finally:
        numba.set_num_threads(before)
    assert np.array_equal(out[0], out[1])
    # the sequential block Gauss-Seidel sweep in the phases' order, twice
    sequential = np.concatenate([order for _, order in smoother.sweeps[0]])
    x = np.zeros_like(b)
    for _ in range(2):
        smoother.update(sequential, b, x)
    assert np.array_equal(out[0], x)


@pytest.mark.parametrize("n", [1000, 3 * PARALLEL_NNZ // 10])
def test_matvec_matches_scipy(n):
    """Below the threshold SciPy's product, above it the parallel kernel: the same sums in the
    same order, so the same bits."""
    rng = np.random.default_rng(3)
    M = sp.random(n, n, density=20 / n, format="csr", random_state=rng) + sp.eye(n, format="csr")
    x = rng.standard_normal(n)
    assert (M.nnz >= PARALLEL_NNZ) == (n > 1000)
    assert np.array_equal(matvec(M.tocsr(), x), M @ x)
    assert np.array_equal(matvec(M.tocsc(), x), M.tocsc() @ x)
