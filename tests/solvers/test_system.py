"""Orphaned pressure modes: the Gram pre-filter of the rank test against the SVD, and the fine
system sharing the modes its Newton solve computed for the residual."""
import dataclasses

import numpy as np
import pytest
from sharp_disk import sharp_disk_problem

from fbmflow.solvers import DirectSolver
from fbmflow.solvers import system as system_module
from fbmflow.solvers.system import _rank_deficient, without_orphaned_modes


def test_the_gram_prefilter_decides_as_the_svd():
    """Blocks (3 x 18, as a 2D cell's B) with planted singular values from 1e-16 to 1 times the
    largest, around the threshold among them, at scales from 1e-8 to 1e8, some zero or with two
    non-zero columns only: the pre-filtered test flags exactly the blocks whose SVD has a singular
    value at most the threshold."""
    rng = np.random.default_rng(7)
    n, m, k = 3000, 3, 18
    U = np.linalg.qr(rng.standard_normal((n, m, m)))[0]
    V = np.linalg.qr(rng.standard_normal((n, k, m)))[0]
    smallest = 10.0 ** rng.uniform(-16, 0, n)
    smallest[:200] = 1e-10 * (1 + rng.uniform(-1e-3, 1e-3, 200))  # at the threshold
    sv = np.stack([np.ones(n), rng.uniform(0.1, 1, n), smallest], axis=1)
    scale = 10.0 ** rng.uniform(-8, 8, n)
    blocks = np.einsum("cij,cj,ckj->cik", U, sv * scale[:, None], V)
    blocks[:50] = 0.0  # a cell inside a particle: no private velocity at all
    blocks[50:300, :, 2:] = 0.0  # a cut cell with two private velocities: rank 2 at most
    for s in (1e-8, 1.0, 1e8):  # one threshold per call, as in orphan_pressure_modes
        pick = np.flatnonzero(np.isclose(scale, s, rtol=0.9) | (np.arange(n) < 300))
        threshold = 1e-10 * s
        ref = (np.linalg.svd(blocks[pick], compute_uv=False) <= threshold).any(axis=1)
        assert ref.any() and not ref.all()
        assert np.array_equal(_rank_deficient(blocks[pick], threshold), ref)


@pytest.mark.parametrize("cells", [[1], [0, 2]])
def test_removing_the_modes_keeps_the_divergence_pattern_where_it_can(cells):
    """``B^T - C B^T`` for a projector ``C`` onto one mode: on ``B^T``'s own index arrays when the
    mode lives on one cell (its rows change within their pattern), a new matrix when it spans two
    cells that share no velocity (cells 0 and 2); the values equal the dense product either way,
    and the other rows keep their entries, an explicit zero (a wall's zeroed column) included."""
    import scipy.sparse as sp
    rng = np.random.default_rng(3)
    npl, width, n_cells = 3, 6, 3
    cols = np.repeat(3 * np.arange(n_cells)[:, None] + np.arange(width), npl, axis=0)  # cells overlap
    BT = sp.csr_matrix((rng.normal(size=cols.size), cols.ravel(), np.arange(0, cols.size + 1, width)),
                       shape=(n_cells * npl, 3 * n_cells + 3))
    BT.data[npl * width + 4] = 0.0  # cell 1's first row
    q = np.zeros(BT.shape[0])
    for c in cells:
        q[c * npl:(c + 1) * npl] = rng.normal(size=npl)
    q /= np.linalg.norm(q)
    C = sp.csr_matrix(np.outer(q, q))
    out = without_orphaned_modes(BT, C)
    assert np.allclose(out.toarray(), BT.toarray() - C.toarray() @ BT.toarray(), rtol=0, atol=1e-14)
    assert np.shares_memory(out.indices, BT.indices) == (len(cells) == 1)
    other = np.setdiff1d(np.arange(n_cells), cells)
    rows = (npl * other[:, None] + np.arange(npl)).ravel()
    assert np.array_equal(np.diff(out.indptr)[rows], np.diff(BT.indptr)[rows])
    assert not np.shares_memory(out.data, BT.data)


@pytest.mark.parametrize("sharp", [False, True])
def test_a_newton_solve_finds_the_orphaned_modes_once(sharp, monkeypatch):
    """A disk moving down in a closed box, one backward-Euler Newton solve with the direct solver:
    its residuals and its linear systems share one search for orphaned pressure modes, and the
    system's modes are the ones it would find itself."""
    from fbmflow.coupling import node_owner, rigid_body_constraints, sharp_boundary
    from fbmflow.flow import NavierStokesProblem, NoSlip
    from fbmflow.mesh import StructuredMesh
    from fbmflow.particles import Ball

    mesh = StructuredMesh.box((16, 16))
    centre, shapes = np.array([[0.513, 0.521]]), [Ball(0.15, 2)]
    vel, ang = np.array([[0.0, -1.0]]), np.zeros(1)

    def disk(V, t):
        rigid = rigid_body_constraints(V, node_owner(V, centre, shapes), centre, vel, ang)
        if sharp:
            owner = node_owner(V, centre, shapes)
            return sharp_boundary(prob.space, owner, centre, shapes).constraints(rigid, vel, ang)
        return rigid

    prob = NavierStokesProblem(mesh, 0.01, {t: NoSlip() for t in mesh.tags}, linear_solver=DirectSolver(),
                               extra_constraints=disk)
    calls = []
    search = system_module.orphan_pressure_modes

    def counted(*args, **kwargs):
        calls.append(1)
        return search(*args, **kwargs)

    monkeypatch.setattr(system_module, "orphan_pressure_modes", counted)
    monkeypatch.setattr("fbmflow.flow.levels.orphan_pressure_modes", counted)
    x, report = prob.solve(prob.zero_state(), 100.0, 1.0, prob.load(), 0.0)
    assert report.converged and report.iterations >= 1
    assert len(calls) == 1
    system = prob._linearisation[4]
    assert system.orphans is not None and system.orphans.nnz > 0
    own = dataclasses.replace(system, orphans=None)  # the system's own search
    assert len(calls) == 2 and abs(own.orphans - system.orphans).max() == 0.0


def _assembled_continuity(BT, con, orphans):
    """The system's continuity rows made on an assembled copy of the divergence ``BT``: the cut
    cells' rows written in, the extension's transfer, the fixed columns zeroed, the orphaned
    modes' rows removed (the changes the continuity block makes, as CSR operations)."""
    import scipy.sparse as sp

    from fbmflow.fem.continuity_block import splice_rows, zero_columns
    npl = con.continuity.data.shape[1]
    values = BT.data.copy().reshape(-1, npl, con.continuity.data.shape[2])
    values[con.continuity.cells] = con.continuity.data
    M = sp.csr_matrix((values.ravel(), BT.indices, BT.indptr), shape=BT.shape)
    E = con.extension
    ET = E.matrix.T.tocsr()
    rows = np.union1d(E.dofs, np.flatnonzero(np.diff(ET.indptr)))
    keep = np.ones(rows.size)
    keep[np.isin(rows, E.dofs)] = 0.0
    M = zero_columns(splice_rows(M, rows, sp.diags(keep) @ (M[rows] + ET[rows] @ M)), con.fixed)
    return M if orphans is None else without_orphaned_modes(M, orphans)


def test_the_continuity_block_is_the_assembled_one():
    """A sharp-boundary disk system: its continuity block (the level's divergence and the rows
    that differ, ContinuityBlock) is entry for entry the CSR matrix the same changes make on a
    copy, holds only the rows a change touches, and the level's divergence is untouched."""
    from fbmflow.fem.continuity_block import ContinuityBlock
    from fbmflow.mesh import StructuredMesh
    prob, con = sharp_disk_problem(StructuredMesh.box((16, 16)), [0.513, 0.47], 0.17)
    assert con.continuity is not None and con.extension is not None and con.fixed.size
    before = prob.BT.data.copy()
    system = prob.linear_system(prob.zero_state(), 100.0, 1.0, con)
    system = system.preconditioner or system
    D = system.BT
    assert isinstance(D, ContinuityBlock) and D.base is prob.BT
    ref = _assembled_continuity(prob.BT, con, system.orphans)
    M = D.tocsr()
    for a, b in ((M.indptr, ref.indptr), (M.indices, ref.indices), (M.data, ref.data)):
        assert np.array_equal(a, b)
    # the changed rows are exactly those a change touches: the fixed columns' rows (the walls,
    # the disk's inner nodes), the cut cells', the extension's, the orphaned modes'
    npl = 3
    fixed = np.zeros(system.n_u, dtype=bool)
    fixed[con.fixed] = True
    touched = fixed[prob.BT.indices].reshape(D.shape[0], -1).any(axis=1)
    touched[(con.continuity.cells[:, None] * npl + np.arange(npl)).ravel()] = True
    touched[con.extension.dofs] = True
    touched[np.diff(con.extension.matrix.T.tocsr().indptr) > 0] = True
    if system.orphans is not None:
        touched[np.diff(system.orphans.indptr) > 0] = True
    assert np.array_equal(D.dofs, np.flatnonzero(touched)) and D.dofs.size < D.shape[0]
    assert np.array_equal(prob.BT.data, before)
    u = np.random.default_rng(0).normal(size=system.n_u)
    assert np.array_equal(D @ u, ref @ u)


@pytest.mark.parametrize("closed", [False, True])
def test_orphaned_modes_from_a_column_mask_equal_those_of_the_zeroed_copy(closed):
    """orphan_pressure_modes with the constrained columns named (no copy of B^T) gives the
    projector of the copy with those columns zeroed: a sharp-boundary disk (cells inside it, cut
    cells) and the walls."""
    from fbmflow.fem.continuity_block import zero_columns
    from fbmflow.mesh import StructuredMesh
    prob, con = sharp_disk_problem(StructuredMesh.box((16, 16)), [0.513, 0.47], 0.17)
    ref = system_module.orphan_pressure_modes(zero_columns(prob.BT, con.dofs), 3, closed=closed)
    out = system_module.orphan_pressure_modes(prob.BT, 3, closed=closed, zero=con.dofs)
    assert ref is not None and ref.nnz
    assert abs(out - ref).max() < 1e-13


def test_balance_volume_keeps_its_vectors_by_identity():
    """balance_volume against the formula made afresh, for one and several right-hand sides: the
    same bits on the first call and on a call that finds ``q`` and ``w`` kept; other orphans (a
    new matrix, equal to the first in pattern but not in values) and a pressure extension made
    afresh; the kept vectors read-only."""
    import scipy.sparse as sp

    from fbmflow.solvers.system import _null_and_expansion, balance_volume

    rng = np.random.default_rng(5)
    npl, n = 4, 40
    weights = rng.random(n)

    def fresh(g, orphans, extension=None):
        q = np.zeros(n)
        q[::npl] = 1.0
        q = q - orphans @ q
        w = weights - orphans @ weights
        if extension is not None:
            q[extension.dofs] = 0.0
            w = extension.transfer(w)
        lam = (q @ g) / (q @ w)
        return g - np.multiply.outer(w, lam)

    class Extension:  # continued cells: their rows moved to their neighbours'
        dofs = np.array([8, 9, 10, 11])

        def transfer(self, r):
            out = r.copy()
            out[:4] += r[self.dofs]
            out[self.dofs] = 0.0
            return out

    for values in (0.5, 0.25):
        orphans = sp.csr_matrix((np.full(2, values), ([4, 5], [4, 5])), shape=(n, n))
        for extension in (None, Extension()):
            for g in (rng.normal(size=n), rng.normal(size=(n, 3))):
                first = balance_volume(g, weights, orphans, npl, extension)
                again = balance_volume(g, weights, orphans, npl, extension)
                assert np.array_equal(first, fresh(g, orphans, extension)) and np.array_equal(again, first)
            q, w, _ = _null_and_expansion(weights, orphans, npl, extension)
            assert q is _null_and_expansion(weights, orphans, npl, extension)[0]
            assert not q.flags.writeable and not w.flags.writeable and weights.flags.writeable
