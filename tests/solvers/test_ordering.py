"""The sweep order of the Vanka smoothers (slabs and blocks) and the parallel mat-vec."""
import numba
import numpy as np
import pytest
import scipy.sparse as sp
from sharp_disk import sharp_disk_problem

from fbmflow.fem.continuity_block import ContinuityBlock
from fbmflow.fem.velocity_block import VelocityBlock
from fbmflow.mesh import StructuredMesh
from fbmflow.solvers import MultigridSolver, ordering, vanka
from fbmflow.solvers.sparse import PARALLEL_NNZ, matvec, rmatvec
from fbmflow.solvers.system import as_csr


def _groups(phases):
    """Per phase, the list of its groups' patch indices."""
    return [[order[gptr[g]:gptr[g + 1]] for g in range(gptr.size - 1)] for gptr, order in phases]


def _phases(order, shape, periodic, reach):
    """``order``'s phases (:func:`~fbmflow.solvers.ordering.slab_phases` or ``colour_phases``) of
    every cell of a box, checked to sweep each cell once: (cell indices, phases, the gap in
    layers that keeps two patches independent, the cells per axis)."""
    mesh = StructuredMesh.box(shape, periodic=periodic)
    index = mesh.cell_indices()
    phases = order(mesh.shape, mesh.periodic, index, np.arange(mesh.n_cells), reach)
    swept = np.concatenate([cells for _, cells in phases])
    assert np.array_equal(np.sort(swept), np.arange(mesh.n_cells))
    return index, phases, int(np.floor(1 + reach / 2)) + 1, np.array(shape)


@pytest.mark.parametrize("shape, periodic, reach, n_phases", [
    ((40, 40, 64), (False, False, False), 2, 4),     # 16 slabs, then 8 along y: 32 blocks per phase
    ((12, 12, 64), (False, False, False), 2, 4),     # ten Cate level 1: 16 blocks per phase
    ((12, 12, 64), (False, False, False), 6, 4),     # ... with the sphere's reach: 4 per phase
    ((20, 20, 32), (False, False, False), 2, 4),
    ((48, 48, 32), (True, False, True), 2, 4),       # periodic axes
    ((160, 128), (False, False), 6, 4),              # 2D, a wider reach
    ((64, 128), (False, False), 2, 2),               # slabs along y; never cut along x
    ((32, 96), (False, True), 2, 2),                 # too small for blocks
])
def test_groups_of_a_phase_are_independent(shape, periodic, reach, n_phases):
    """Every cell is swept once, each group in lexicographic order; two cells of different
    groups of one phase lie at least ``gap`` layers apart along some axis (modulo the period),
    so that no group touches a DOF another reads."""
    index, phases, gap, n = _phases(ordering.slab_phases, shape, periodic, reach)
    assert len(phases) == n_phases
    for groups in _groups(phases):
        assert len(groups) >= 2
        for g in groups:
            assert np.all(np.diff(g) > 0)  # lexicographic
        # per group and axis: the set of layers it occupies
        layers = [[np.unique(index[g, a]) for a in range(len(shape))] for g in groups]
        for i in range(len(groups)):
            for j in range(i + 1, len(groups)):
                apart = False
                for a in range(len(shape)):
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
    monkeypatch.setattr(vanka, "SERIAL_CELLS_PER_THREAD", 0)  # the phases in parallel on this small mesh
    monkeypatch.setattr(ordering, "MIN_SLAB_LAYERS", 2)
    monkeypatch.setattr(ordering, "MIN_BLOCK_LAYERS", 2)
    mesh = StructuredMesh.box((24, 16))  # slabs along x, blocks along y
    bcs = {t: NoSlip() for t in mesh.tags}
    bcs["ymax"] = Dirichlet((1.0, 0.0))
    prob = NavierStokesProblem(mesh, 0.01, bcs)
    x0, con = recirculating_state(prob), prob.constraints()
    b = -prob.residual(x0, 10.0, 1.0, prob.load(), con)
    system = prob.linear_system(x0, 10.0, 1.0, con)
    smoother = FactoredVankaSmoother(system)
    assert len(smoother.sweeps[0][0]) == 4
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
    # the sequential block Gauss-Seidel sweep in the phases' order, then the far patches, twice
    phases, far = smoother.sweeps[0]
    sequential = np.concatenate([order for _, order in phases] + [far])
    x = np.zeros_like(b)
    for _ in range(2):
        smoother.update(sequential, b, x)
    assert np.array_equal(out[0], x)
    # a level below SERIAL_CELLS_PER_THREAD cells per thread sweeps its phases on one thread: the
    # same bits
    monkeypatch.setattr(vanka, "SERIAL_CELLS_PER_THREAD", 10**9)
    x = np.zeros_like(b)
    smoother.smooth(b, x, 2)
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


@pytest.mark.parametrize("n", [1000, 3 * PARALLEL_NNZ // 10])
def test_transposed_matvec_matches_scipy_and_not_the_threads(n):
    """``M^T x`` without the transpose: SciPy's below the threshold, above it chunks of rows into
    vectors of their own, added in order: equal to SciPy's to rounding, and the same bits on 1
    and 2 threads."""
    import numba
    rng = np.random.default_rng(4)
    M = (sp.random(n, n // 4, density=80 / n, format="csr", random_state=rng)
         + sp.eye(n, n // 4, format="csr")).tocsr()
    x = rng.standard_normal(n)
    want = M.T @ x
    assert (M.nnz >= PARALLEL_NNZ) == (n > 1000)
    got = rmatvec(M, x)
    assert np.allclose(got, want, rtol=0.0, atol=1e-13 * np.abs(want).max())
    threads = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        assert np.array_equal(rmatvec(M, x), got)
    finally:
        numba.set_num_threads(threads)


def _sharp_ball_system(mesh, centre, radius, linear_solver=None):
    """The Picard system of a backward-Euler step (dt 0.01) in ``mesh`` (no-slip walls) with a
    sharp-boundary disk of ``radius`` at ``centre`` moving down at 1 (with multigrid: the finest
    level's, its velocity block stored once per scalar)."""
    prob, con = sharp_disk_problem(mesh, centre, radius, linear_solver)
    system = prob.linear_system(prob.zero_state(), 100.0, 1.0, con)
    return system.preconditioner or system


def _reach_from_coo(system, periods):
    """Every row's reach from the COO entries of the system's blocks (its built gradient)."""
    points = ordering.lattice_points(system.space)
    expected = np.zeros(len(points), dtype=np.int64)
    n_u = system.n_u
    velocity = system.A.parts() if isinstance(system.A, VelocityBlock) else [(system.A, 0)]
    others = [(system.gradient, 0, n_u), (as_csr(system.BT), n_u, 0), (system.pressure_block, n_u, n_u)]
    for M, r, c in [(M, r, r) for M, r in velocity] + others:
        if M is None:
            continue
        M = sp.coo_matrix(M)
        diff = points[c + M.col] - points[r + M.row]
        diff[:, 0] = (diff[:, 0] + periods[0] // 2) % periods[0] - periods[0] // 2
        np.maximum.at(expected, r + M.row, np.abs(diff).max(axis=1))
    return expected


@pytest.mark.parametrize("blocks", [False, True])
def test_unknown_reach_matches_numpy(blocks):
    """The reach of every row against the same from the COO entries of the blocks: a periodic
    mesh (distances modulo the period) with a sharp-boundary ball, whose ghost rows reach further;
    the patches that reach furthest are left out of the phases, at most FAR_SHARE of them. With
    ``blocks``, the multigrid's finest level, whose velocity block (every component's scalar
    pattern and the replaced rows) and continuity rows (the level's and the changed ones) give
    the reach of what they share from what the first call kept; the gradient's reach is kept
    from the level's divergence (``gradient_BT``), and without it found from the built ``B``."""
    import dataclasses
    mesh = StructuredMesh.box((12, 10), periodic=(True, False))
    system = _sharp_ball_system(mesh, [0.51, 0.47], 0.2, MultigridSolver() if blocks else None)
    assert isinstance(system.A, VelocityBlock) == blocks and isinstance(system.BT, ContinuityBlock)
    assert system.gradient_BT is not None
    periods = np.array([2 * mesh.shape[0], 0])
    reach = ordering.unknown_reach(system)
    assert np.array_equal(ordering.unknown_reach(system), reach)
    assert np.array_equal(reach, _reach_from_coo(system, periods))
    plain = dataclasses.replace(system, gradient_BT=None)  # B from its own B^T
    assert np.array_equal(ordering.unknown_reach(plain), _reach_from_coo(plain, periods))
    assert reach.max() > 2 and np.median(reach) == 2
    near = ordering.near_patches(reach)
    assert (~near).sum() <= ordering.FAR_SHARE * reach.size and near[reach == 2].all()


def test_reversed_phases_reverse_every_group_in_its_place():
    """The backward sweep against the same in Python: the phases in reverse, each group's patches
    in reverse, the groups where they were (groups of one patch, as in colour order, and of
    several)."""
    rng = np.random.default_rng(3)
    phases = []
    for sizes in ([1] * 7, [3, 1, 4, 2], [5]):
        gptr = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        phases.append((gptr, rng.permutation(100)[:gptr[-1]].astype(np.int64)))
    got = ordering.reversed_phases(phases)
    assert len(got) == len(phases)
    for (gptr, order), (rptr, rorder) in zip(phases[::-1], got):
        want = np.concatenate([order[gptr[g]:gptr[g + 1]][::-1] for g in range(gptr.size - 1)])
        assert np.array_equal(rptr, gptr) and np.array_equal(rorder, want)


def test_greedy_colours_match_python():
    """The kernel against the same greedy rule in Python, on a random symmetric graph: a proper
    colouring (no edge within a colour), each vertex the smallest colour its earlier neighbours
    leave."""
    from fbmflow.solvers._kernels import greedy_colours
    rng = np.random.default_rng(5)
    G = sp.random(300, 300, density=0.03, format="csr", random_state=rng)
    G = ((G + G.T) != 0).astype(float).tocsr()
    G.setdiag(0.0)
    G.eliminate_zeros()
    colour = greedy_colours(G.indptr, G.indices)
    expected = []
    for i in range(300):
        taken = {expected[j] for j in G.indices[G.indptr[i]:G.indptr[i + 1]] if j < i}
        expected.append(min(set(range(len(taken) + 1)) - taken))
    assert np.array_equal(colour, expected)
    rows, cols = G.nonzero()
    assert np.all(colour[rows] != colour[cols])


def test_agglomerated_patches_of_a_colour_touch_nothing_of_each_other():
    """The sharp boundary's agglomerated patches in colours: within a colour no patch writes an
    unknown another reads, so a colour's updates give the same bits in either order; every patch
    is in one colour, and the colours are fewer than the patches."""
    from fbmflow.solvers.vanka import FactoredVankaSmoother, saddle_point_csr
    system = _sharp_ball_system(StructuredMesh.box((24, 24)), [0.513, 0.521], 0.3)
    smoother = FactoredVankaSmoother(system)
    phases = smoother.merged_phases
    coloured = np.concatenate([order for _, order in phases])
    assert np.array_equal(np.sort(coloured), smoother.merged) and 1 < len(phases) < smoother.merged.size
    ptr, idx, _ = saddle_point_csr(system, np.float64)
    for _, order in phases:
        writes = [smoother.dofs[smoother.ptr[k]:smoother.ptr[k + 1]] for k in order]
        reads = [np.unique(np.concatenate([idx[ptr[q]:ptr[q + 1]] for q in w])) for w in writes]
        for i in range(len(order)):
            for j in range(len(order)):
                assert i == j or not np.intersect1d(writes[j], reads[i]).size, (i, j)
    b = np.random.default_rng(2).standard_normal(system.n_u + system.n_p)
    out = []
    for ordered in (phases, [(g, o[::-1].copy()) for g, o in phases]):
        x = np.zeros_like(b)
        smoother.sweep_phases(ordered, b, x)
        out.append(x)
    assert np.array_equal(out[0], out[1]) and np.any(out[0])


@pytest.mark.parametrize("shape, periodic, reach, n_colours", [
    ((12, 12, 64), (False, False, False), 2, 27),    # the plain discretisation: 3 x 3 x 3
    ((12, 12, 64), (False, False, False), 6, 125),   # a sharp boundary's reach: 5 layers apart
    ((10, 8, 7), (True, False, True), 2, 105),       # periodic: 5 (divides 10), 3, 7 (none below)
    ((7, 5), (False, False), 2, 9),
])
def test_cells_of_a_colour_are_independent(shape, periodic, reach, n_colours):
    """The GPU's order (:func:`~fbmflow.solvers.ordering.colour_phases`): every cell once, every
    patch a group of its own, and two cells of one colour at least ``gap`` layers apart along
    some axis (modulo the period)."""
    index, phases, gap, n = _phases(ordering.colour_phases, shape, periodic, reach)
    assert len(phases) == n_colours
    for gptr, order in phases:
        assert np.array_equal(gptr, np.arange(order.size + 1)) and np.all(np.diff(order) > 0)
        diff = np.abs(index[order][:, None, :] - index[order][None, :, :])
        diff = np.where(np.array(periodic), np.minimum(diff, n - diff), diff)
        apart = (diff >= gap).any(axis=2)
        assert np.all(apart | np.eye(order.size, dtype=bool))
