"""Geometric multigrid (issue 3): grid transfer, Vanka kernels, convergence factors and
level-independent cycle counts for Stokes and Oseen/Newton systems, periodic directions."""
import dataclasses

import numpy as np
import pytest
import scipy.sparse as sp

from fbmflow.fem import FlowSpace
from fbmflow.fem.functions import sample_pressure, sample_velocity
from fbmflow.flow import Dirichlet, DoNothing, NavierStokesProblem, NoSlip, Slip
from fbmflow.flow.levels import NewtonBlock
from fbmflow.mesh import StructuredMesh
from fbmflow.scenes.cavity import recirculating_state
from fbmflow.solvers import DirectSolver, MultigridSettings, MultigridSolver
from fbmflow.solvers.direct import factorize
from fbmflow.solvers.system import as_csr
from fbmflow.solvers.transfer import injection_q2, prolongation_p1disc, prolongation_q2

#: float32 storage's rounding (6e-8 relative per value), summed over a cell's terms
F32 = 1e-6


# -- grid transfer -----------------------------------------------------------------------------
@pytest.mark.parametrize("shape, periodic", [((2, 3), (False, False)), ((2, 2), (True, False)),
                                             ((2, 1, 2), (False, False, True))])
def test_prolongation_is_exact_interpolation(shape, periodic):
    coarse = StructuredMesh.box(shape, upper=(2.0,) * len(shape), periodic=periodic)
    fine = coarse.refine()
    sc, sf = FlowSpace(coarse), FlowSpace(fine)
    P = prolongation_q2(sc.V, sf.V)
    Pp = prolongation_p1disc(sc.Q, sf.Q)
    rng = np.random.default_rng(1)
    uc, pc = rng.standard_normal(sc.n_u), rng.standard_normal(sc.n_p)
    uf = np.concatenate([P @ part for part in uc.reshape(sc.dim, -1)])
    pts = rng.random((40, sc.dim)) * 1.999
    assert np.allclose(sample_velocity(sc, uc, pts), sample_velocity(sf, uf, pts), atol=1e-13)
    assert np.allclose(sample_pressure(sc, pc, pts), sample_pressure(sf, Pp @ pc, pts), atol=1e-13)
    assert np.allclose(P.sum(axis=1), 1.0)  # partition of unity
    inj = injection_q2(sc.V, sf.V)
    assert np.allclose(sf.V.coordinates[inj], sc.V.coordinates)


def test_coarsen_inverts_refine():
    mesh = StructuredMesh.box((2, 4), periodic=(True, False))
    assert np.array_equal(mesh.refine().coarsen().vertices, mesh.vertices)
    with pytest.raises(ValueError, match="even cell count"):
        StructuredMesh.box((3, 4)).coarsen()


# -- Vanka kernels against a dense NumPy reference ---------------------------------------------
def _tiny_system(dim, newton, slip=False):
    mesh = StructuredMesh.box((3,) * dim)
    bcs = {t: NoSlip() for t in mesh.tags}
    bcs["ymax"] = Dirichlet((1.0,) + (0.0,) * (dim - 1))
    if slip:  # a symmetry plane: its nodes' normal rows unit rows, their tangential rows free
        bcs["xmin"] = Slip()
    prob = NavierStokesProblem(mesh, 0.05, bcs, linear_solver=DirectSolver())
    x = prob.zero_state()
    x[:prob.space.n_u] += 0.3 * np.random.default_rng(3).standard_normal(prob.space.n_u)
    con = prob.constraints()
    con.apply_to_vector(x)
    system = prob.fine.system(x[:prob.space.n_u], 2.0, 1.0, 1.0, prob.mu, True, con, newton=newton)
    return prob.space, system


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("variant",
                         ["vanka-full", "vanka-diagonal", "vanka-factored", "vanka-factored-single"])
@pytest.mark.parametrize("newton, slip", [(True, False), (False, False), (False, True)],
                         ids=["coupled", "block-diagonal", "block-diagonal-slip"])
def test_vanka_corrections_match_numpy(dim, variant, newton, slip):
    """Each cell's correction solves its local block (single precision storage: to 1e-5)."""
    from fbmflow.solvers import VankaSmoother
    from fbmflow.solvers.vanka import FactoredVankaSmoother
    space, system = _tiny_system(dim, newton, slip)
    K = system.matrix().toarray()[:system.n_u + system.n_p, :system.n_u + system.n_p]
    rng = np.random.default_rng(4)
    b, x = rng.standard_normal(K.shape[0]), rng.standard_normal(K.shape[0])
    if variant.startswith("vanka-factored"):
        single = variant.endswith("single")
        smoother = FactoredVankaSmoother(system, precision="single" if single else "double")
        # block-diagonal rows: cells whose nodes all have one scalar row go through the Schur
        # complement of that scalar block, cells at the symmetry plane (unit rows in one
        # component) through that of the d component blocks; coupled (Newton) rows: LU of the
        # whole block
        kinds = set(smoother.blocks[:space.mesh.n_cells].tolist())
        assert kinds == ({0} if newton else {1, dim} if slip else {1})
        # every cell's continuity rows are the divergence's in its pattern: no Schur factor stores D
        schur = smoother.blocks > 0
        assert np.array_equal(smoother.d_read, schur)
    else:
        smoother = VankaSmoother(system, variant)
    rtol = 1e-5 if variant.endswith("single") else 1e-9
    cells = space.mesh.cell_parity_classes(3)[0]  # cells that share no matrix row
    x_new = x.copy()
    smoother.update(cells, b, x_new, omega=1.0)
    r = b - K @ x
    diag = np.diag(K)[:system.n_u]
    for e, c in enumerate(cells):
        dofs = space.V.cell_dofs[c]
        idx = np.concatenate([i * space.n_v + dofs for i in range(dim)]
                             + [system.n_u + c * (dim + 1) + np.arange(dim + 1)])
        Kc = K[np.ix_(idx, idx)].copy()
        nu_loc = dim * dofs.size
        if variant == "vanka-diagonal":
            Kc[:nu_loc, :nu_loc] = np.diag(diag[idx[:nu_loc]])
        ref = np.linalg.lstsq(Kc, r[idx], rcond=1e-12)[0]
        assert np.allclose(x_new[idx] - x[idx], ref, rtol=rtol,
                           atol=rtol / 10 * np.abs(ref).max()), (c, variant)


def test_saddle_point_csr_matches_scipy():
    from fbmflow.solvers.vanka import saddle_point_csr
    _, system, _ = _ball_system("sharp", linearisation="newton")  # ghost rows and a pressure block
    assert system.pressure_block is not None
    ptr, idx, val = saddle_point_csr(system, np.float64)
    n = system.n_u + system.n_p
    K = sp.csr_matrix((val, idx, ptr), shape=(n, n))
    ref = sp.bmat([[system.A, system.gradient], [as_csr(system.BT), system.pressure_block]], format="csr")
    assert abs(K - ref).max() == 0.0
    # some velocity rows left empty, no continuity rows: the rows in parallel at their pointers
    keep = np.random.default_rng(4).random(system.n_u) < 0.5
    ptr, idx, val = saddle_point_csr(system, np.float32, keep, continuity=False)
    K = sp.csr_matrix((val, idx, ptr), shape=(n, n))
    rows = np.concatenate([keep, np.ones(system.n_p, dtype=bool)]).astype(float)
    ref = sp.diags(rows) @ sp.bmat([[system.A, system.gradient], [None, system.pressure_block]], format="csr")
    assert K.dtype == np.float32 and abs(K - ref.astype(np.float32)).max() == 0.0


def test_patch_max_against_numpy():
    """The per-patch maximum over the patches' unknowns against NumPy's ``reduceat``."""
    from fbmflow.solvers._kernels import patch_max
    rng = np.random.default_rng(6)
    sizes = rng.integers(1, 9, 40)
    ptr = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    dofs = rng.integers(0, 100, ptr[-1]).astype(np.int32)
    for values in (rng.integers(0, 7, 100), (rng.random(100) < 0.1).astype(np.uint8)):
        assert np.array_equal(patch_max(ptr, dofs, values), np.maximum.reduceat(values[dofs], ptr[:-1]))


# -- convergence -------------------------------------------------------------------------------
def _cavity_system(n, dim=2, re=None, cycle="V", smoother="vanka-full", krylov="none"):
    """The Stokes (re None) or Newton/Oseen system of the lid-driven cavity at the lid flow."""
    mesh = StructuredMesh.box((n,) * dim)
    bcs = {t: NoSlip() for t in mesh.tags}
    bcs["ymax"] = Dirichlet((1.0,) + (0.0,) * (dim - 1))
    mg = MultigridSolver(MultigridSettings(cycle=cycle, smoother=smoother, krylov=krylov,
                                           max_iterations=80))
    prob = NavierStokesProblem(mesh, 1.0 if re is None else 1.0 / re, bcs, convection=re is not None,
                               linear_solver=mg)
    x = prob.zero_state() if re is None else recirculating_state(prob)
    con = prob.constraints()
    F = prob.residual(x, 0.0, 1.0, prob.load(), con)
    return prob, mg, x, con, F


def _solve(prob, mg, x, con, F, m=0.0):
    system = prob.linear_system(x, m, 1.0, con)
    du, dp, rep = mg.solve(system, -F[:system.n_u], -F[system.n_u:])
    true = np.linalg.norm(np.concatenate([-F[:system.n_u], -F[system.n_u:]])
                          - system.apply(np.concatenate([du, dp])))
    return rep, true / np.linalg.norm(F)


@pytest.mark.parametrize("dim, n, bound", [(2, 32, 0.2), (3, 8, 0.3)])
@pytest.mark.parametrize("smoother", ["vanka-full", "vanka-diagonal"])
def test_stokes_convergence_factor(dim, n, bound, smoother):
    rep, rel = _solve(*_cavity_system(n, dim, smoother=smoother))
    res = np.array(rep.residuals)
    factors = res[1:] / res[:-1]
    assert rel < 1e-8
    assert factors.max() <= bound, factors
    assert rep.smoothing_sweeps >= 4 * rep.iterations  # pre + post on the finest level at least


@pytest.mark.parametrize("case", ["stokes-2d", "oseen-re100", "stokes-3d"])
def test_cycles_are_level_independent(case):
    if case == "stokes-2d":
        counts = [_solve(*_cavity_system(n))[0].iterations for n in (16, 32, 64)]
    elif case == "oseen-re100":
        counts = [_solve(*_cavity_system(n, re=100, krylov="fgmres"))[0].iterations for n in (16, 32, 64)]
    else:
        counts = [_solve(*_cavity_system(n, dim=3, smoother="vanka-diagonal"))[0].iterations
                  for n in (4, 8, 16)]
    assert max(counts) - min(counts) <= 2, counts
    assert max(counts) <= 20, counts


@pytest.mark.slow
def test_newton_re1000_cycles_on_fine_levels():
    counts = [_solve(*_cavity_system(n, re=1000, krylov="fgmres"))[0].iterations for n in (64, 128)]
    assert counts[1] <= counts[0] + 2, counts  # no growth under refinement (measured: 18, 15)
    assert max(counts) <= 20, counts


def test_periodic_taylor_green_oseen_system():
    """Periodic in both directions (pressure fixed by its mean): level-independent cycles."""
    from fbmflow.scenes.taylor_green import TaylorGreen2D
    counts = []
    for level in (1, 2, 3):
        mg = MultigridSolver(MultigridSettings(krylov="fgmres"))
        prob = NavierStokesProblem(TaylorGreen2D.mesh(level), 0.01, {}, linear_solver=mg)
        x = TaylorGreen2D.initial_state(prob, 0.01)
        con = prob.constraints()
        rhs = (1.0 / 0.05) * prob.apply_mass(x[:prob.space.n_u])
        F = prob.residual(x, 1.0 / 0.05, 1.0, rhs, con)
        rep, rel = _solve(prob, mg, x, con, F, m=1.0 / 0.05)
        assert rel < 1e-8
        counts.append(rep.iterations)
    assert max(counts) - min(counts) <= 2, counts


def test_channel_3d_newton_system():
    counts = []
    for n in (2, 4):
        mesh = StructuredMesh.box((4 * n, n, n), upper=(4.0, 1.0, 1.0))
        bcs = {t: NoSlip() for t in mesh.tags}
        bcs["xmin"] = Dirichlet(lambda x, t: np.stack([16 * x[:, 1] * (1 - x[:, 1]) * x[:, 2] * (1 - x[:, 2]),
                                                       0 * x[:, 0], 0 * x[:, 0]], axis=1))
        bcs["xmax"] = DoNothing()
        mg = MultigridSolver(MultigridSettings(krylov="fgmres", smoother="vanka-diagonal"))
        prob = NavierStokesProblem(mesh, 0.02, bcs, linear_solver=mg, coarse_cells=4)
        x = prob.zero_state()
        con = prob.constraints()
        F = prob.residual(x, 0.0, 1.0, prob.load(), con)
        rep, rel = _solve(prob, mg, x, con, F)
        assert rel < 1e-8
        counts.append(rep.iterations)
    assert max(counts) - min(counts) <= 2, counts


@pytest.mark.parametrize("scene, level", [("cavity-2d", 1), ("channel-2d", 1), ("channel-3d", 1),
                                          ("taylor-green-2d", 1)])
def test_scenes_agree_with_the_direct_solver(scene, level):
    from fbmflow.config import from_dict
    from fbmflow.scenes import get_scene
    sc = get_scene(scene)
    out = {}
    for linear in ("direct", "multigrid"):
        data = {"solver": {"linear": linear}}
        if scene == "taylor-green-2d":
            data["time"] = {"t_end": 0.1}
        out[linear] = sc.run(from_dict(sc.Params, data), level).quantities
    for key, value in out["direct"].items():
        a, b = np.asarray(value, dtype=float), np.asarray(out["multigrid"][key], dtype=float)
        assert np.allclose(a, b, rtol=1e-6, atol=1e-8), key


# -- fictitious boundaries -----------------------------------------------------------------------
def _ball_system(fbm, n=16, coarse_obstacle="nodes", dim=2, closed=False, linearisation="auto"):
    """First Newton system of a backward-Euler step (dt 0.01) with a disk of radius 0.15 moving
    down at 1 in the unit square (no-slip walls, do-nothing top unless ``closed``, a smooth body
    force; ``fbm`` "none": no disk): (problem, system, rhs). ``linearisation`` of the multigrid
    hierarchy: "auto" gives the Picard hierarchy and a matrix-free Newton block, "newton" the
    assembled Newton system."""
    from fbmflow.coupling import node_owner, rigid_body_constraints, sharp_boundary
    from fbmflow.particles import Ball
    mesh = StructuredMesh.box((n,) * dim)
    bcs = {t: NoSlip() for t in mesh.tags}
    if not closed:
        bcs["ymax" if dim == 2 else "zmax"] = DoNothing()
    centre, shapes = np.array([[0.513] + [0.521] * (dim - 1)]), [Ball(0.15, dim)]
    vel = np.zeros((1, dim))
    vel[0, -1] = -1.0
    ang = np.zeros(1) if dim == 2 else np.zeros((1, 3))

    def ball(V, t):
        owner = node_owner(V, centre, shapes)
        rigid = rigid_body_constraints(V, owner, centre, vel, ang)
        if fbm == "sharp" and V is prob.space.V:
            return sharp_boundary(prob.space, owner, centre, shapes).constraints(rigid, vel, ang)
        return rigid

    mg = MultigridSolver(MultigridSettings(smoother="vanka-factored", coarse_obstacle=coarse_obstacle,
                                           linearisation=linearisation))

    def force(x, t):  # smooth, so that the system without the disk has a right-hand side too
        return np.stack([np.sin(3 * x[:, 0] + 1) * np.cos(2 * x[:, 1])]
                        + [np.cos(4 * x[:, k] * x[:, 0]) for k in range(1, dim)], axis=1)

    prob = NavierStokesProblem(mesh, 0.01, bcs, body_force=force, linear_solver=mg,
                               extra_constraints=None if fbm == "none" else ball)
    x, con = prob.zero_state(), prob.constraints()
    F = prob.residual(x, 100.0, 1.0, prob.load(), con, prob.orphans(con))
    system = prob.linear_system(x, 100.0, 1.0, con)
    if linearisation == "newton":  # the assembled system (FGMRES applies it through a NewtonBlock)
        system = system.preconditioner
    return prob, system, -F


@pytest.mark.parametrize("dim, n", [(2, 32), (3, 8)])
def test_a_picard_hierarchy_preconditions_the_newton_time_step(dim, n):
    """In a time step (dt 0.01, Re 100, recirculating flow) the hierarchy of the Picard
    linearisation, with ``dim`` times fewer velocity entries, takes at most one FGMRES cycle more
    than the Newton one to solve the Newton system to 1e-8 (measured: 2D 7 against 6, 3D 9 and 9);
    steady solves keep the Newton hierarchy under ``auto``. FGMRES applies the Newton operator
    through a :class:`NewtonBlock` on either, which moves to another velocity without an
    assembly."""

    def time_step_system(linearisation, x=None):
        prob, mg, x0, con, F = _cavity_system(n, dim, re=100, smoother="vanka-factored", krylov="fgmres")
        mg.settings = dataclasses.replace(mg.settings, linearisation=linearisation)
        system = prob.linear_system(x0 if x is None else x, 100.0, 1.0, con)
        assert isinstance(system.A, NewtonBlock) and system.A.newton_base == (linearisation == "newton")
        return (prob, mg, x0, con, F), system

    def cycles(prob, mg, x, con, F):
        rep, rel = _solve(prob, mg, x, con, F, m=100.0)
        assert rel < 1e-7
        return rep.iterations

    counts = {}
    args, system = time_step_system("newton")
    assembled = system.preconditioner
    assembled = dataclasses.replace(assembled, A=assembled.A.copy())  # the next call overwrites A
    v = np.random.default_rng(3).standard_normal(system.n_u + system.n_p)

    def same(a, b):  # the matrix-free Newton term's coefficients are stored in float32
        return np.allclose(a, b, rtol=0, atol=F32 * np.abs(b).max())

    assert same(system.apply(v), assembled.apply(v))
    counts["newton"] = cycles(*args)
    args, system = time_step_system("picard")
    # the matrix-free Newton block is the assembled one
    assert same(system.apply(v), assembled.apply(v))
    assert system.preconditioner.A.nnz < assembled.A.nnz / (dim - 0.5)
    counts["picard"] = cycles(*args)
    assert counts["picard"] <= counts["newton"] + 1, counts
    # moved to another velocity, either block is the one assembled there (the assembled block
    # and its hierarchy stay where they were); the velocity changed in one corner (the drift's
    # convection is applied there only)
    _, _, x, con, _ = args
    space = args[0].space
    corner = np.all(space.V.coordinates < 0.4, axis=1)
    assert 0 < corner.sum() < space.n_v / 4
    x1 = x.copy()
    x1[:system.n_u] += np.tile(corner, dim) * np.random.default_rng(4).random(system.n_u)
    con.apply_to_vector(x1)
    _, at_x1 = time_step_system("newton", x1)
    for linearisation in ("picard", "newton"):
        _, moved = time_step_system(linearisation)
        moved.A.relinearise(x1[:system.n_u])
        assert same(moved.apply(v), at_x1.preconditioner.apply(v)), linearisation
    prob, mg, x, con, F = _cavity_system(n, dim, re=100, smoother="vanka-factored", krylov="fgmres")
    assert prob.linear_system(x, 0.0, 1.0, con).A.newton_base  # steady: auto keeps Newton


@pytest.mark.parametrize("dim, n", [(2, 16), (3, 6)])
def test_a_moved_newton_block_times_a_sparse_matrix_makes_coefficients_near_its_columns(dim, n):
    """The rigid responses' product ``A W`` with a sparse ``W`` (a few nodes' columns): the
    Newton terms' coefficients computed on the cells the columns touch only, the whole mesh's
    left unmade (a GPU's solves need none on the CPU), and the product the dense one's."""
    prob, mg, x, con, F = _cavity_system(n, dim, re=100, smoother="vanka-factored", krylov="fgmres")
    system = prob.linear_system(x, 100.0, 1.0, con)
    A, space = system.A, prob.space
    assert isinstance(A, NewtonBlock)
    rng = np.random.default_rng(5)
    A.relinearise(x[:system.n_u] + rng.standard_normal(system.n_u))  # Newton term and drift
    nodes = np.flatnonzero(np.all(np.abs(space.V.coordinates - 0.5) < 0.2, axis=1))
    rows = np.concatenate([nodes + k * space.n_v for k in range(dim)])
    W = sp.csc_matrix((rng.standard_normal(rows.size), (rows, rng.integers(0, 3, rows.size))),
                      shape=(system.n_u, 3))
    sparse = A @ W
    assert A._react is None and A._drift is None  # nothing made on the whole mesh
    dense = A @ W.toarray()  # the whole mesh's coefficients
    assert A._react is not None and A._drift is not None
    assert np.abs(sparse - dense).max() <= 1e-13 * np.abs(dense).max()
    assert np.abs(A @ W - dense).max() <= 1e-13 * np.abs(dense).max()  # from the whole mesh's now


def test_factored_vanka_takes_the_cycles_of_vanka_full():
    counts = {s: _solve(*_cavity_system(32, re=100, smoother=s, krylov="fgmres"))[0].iterations
              for s in ("vanka-full", "vanka-factored")}
    assert counts["vanka-factored"] == counts["vanka-full"], counts


def test_factored_vanka_smooths_the_sharp_boundary():
    """Cut cells whose pressures are continued from a neighbour join its patch; every sweep then
    reduces the residual of the sharp system (cell patches alone made it grow 10^3-fold per
    sweep, measured), the first two by a factor above three (the rough part)."""
    from fbmflow.solvers.vanka import FactoredVankaSmoother
    _, system, b = _ball_system("sharp", linearisation="newton")
    smoother = FactoredVankaSmoother(system)
    assert smoother.merged.size > 0
    x = np.zeros_like(b)
    norms = [np.linalg.norm(b)]
    for _ in range(20):
        smoother.smooth(b, x, 1)
        norms.append(np.linalg.norm(b - system.apply(x)))
    assert norms[2] < 0.3 * norms[0], norms
    assert max(np.array(norms[1:]) / np.array(norms[:-1])) < 1.0, norms


def test_the_factors_by_bisection_are_the_factors_by_the_map():
    """The local factors with each entry's place in its patch found by bisection (the GPU's way,
    ``loc`` None, compiled here for the CPU) are those the set-up computes with its map, bit for
    bit, on the sharp ball's patches (agglomerated LU ones and cell patches)."""
    from fbmflow._jit import njit
    from fbmflow.solvers._kernels import factor_patch
    from fbmflow.solvers.vanka import FactoredVankaSmoother

    @njit
    def factors_by_bisection(patches, op, schur_tol, width):
        nl, d = patches[7], patches[8]
        npl = d + 1
        work, A, Ainv = np.empty((width, width)), np.empty((nl, nl)), np.empty((d, nl, nl))
        Y, Sc, Sinv = np.empty((d * nl, npl)), np.empty((npl, npl)), np.empty((npl, npl))
        p_work, e, col = np.empty(width, dtype=np.int32), np.empty(width), np.empty(width)
        for k in range(patches[0].shape[0] - 1):
            factor_patch(k, patches, op, schur_tol, None, work, A, Ainv, Y, Sc, Sinv, p_work, e, col)

    _, system, _ = _ball_system("sharp", linearisation="newton")
    s = FactoredVankaSmoother(system)
    assert s.merged.size > 0 and (s.blocks == 0).any()
    store, piv = np.full_like(s.store, np.nan), np.zeros_like(s.piv)
    nl, d, width, n_v, n_u = s.shape
    factors_by_bisection((s.ptr, s.dofs, s.lu_ptr, store, piv, s.blocks, s.d_read, nl, d, n_v, n_u), s.op,
                         s.schur_tol, width)
    assert np.array_equal(store, s.store) and np.array_equal(piv, s.piv)


@pytest.mark.parametrize("fbm", ["nodes", "sharp"])
def test_block_transfers_are_the_truncated_block_matrix(fbm):
    """Prolongation and restriction from the scalar blocks equal the products with the
    assembled truncated block prolongation and its transpose; the dropped rows get nothing."""
    from fbmflow.solvers.galerkin import truncated_prolongation
    _, system, _ = _ball_system(fbm)
    fine = system if system.preconditioner is None else system.preconditioner
    transfer = truncated_prolongation(fine, *fine.prolongation)
    P = transfer.tocsr()
    assert P.shape == transfer.shape and not transfer.keep.all()
    rng = np.random.default_rng(6)
    e, r = rng.standard_normal(P.shape[1]), rng.standard_normal(P.shape[0])
    assert np.allclose(transfer.prolongate(e), P @ e, rtol=0.0, atol=1e-14 * np.abs(P @ e).max())
    assert np.all(transfer.prolongate(e)[~transfer.keep] == 0.0)
    assert np.allclose(transfer.restrict(r), P.T @ r, rtol=0.0, atol=1e-13 * np.abs(P.T @ r).max())


@pytest.mark.parametrize("fbm", ["nodes", "sharp"])
def test_galerkin_coarse_rows_are_the_truncated_product(fbm):
    """Near the ball the coarse rows are ``P_t^T K P_t`` (elsewhere the re-discretisation equals
    it on nested meshes), and the coarse system is nonsingular."""
    from fbmflow.solvers.galerkin import truncated_prolongation
    _, system, _ = _ball_system(fbm, coarse_obstacle="galerkin")
    fine = system if system.preconditioner is None else system.preconditioner  # the hierarchy's top
    coarse = fine.coarser
    P = truncated_prolongation(fine, *fine.prolongation).tocsr()
    G = (P.T @ fine.matrix(bordered=False) @ P).toarray()
    K = coarse.matrix(bordered=False).toarray()
    free = np.ones(K.shape[0], dtype=bool)
    free[coarse.fixed] = False
    if coarse.orphans is not None:
        free[coarse.n_u + np.unique(coarse.orphans.indices)] = False
    assert np.abs((K - G)[np.ix_(free, free)]).max() < 1e-12 * np.abs(G).max()
    x = np.random.default_rng(5).standard_normal(K.shape[0])
    x[~free] = 0.0
    b = coarse.apply(x)
    u, p = factorize(coarse, "superlu")(b[:coarse.n_u], b[coarse.n_u:])
    assert np.linalg.norm(b - coarse.apply(np.concatenate([u, p]))) < 1e-10 * np.linalg.norm(b)


@pytest.mark.parametrize("fbm, coarse_obstacle",
                         [("nodes", "nodes"), ("sharp", "nodes"), ("sharp", "galerkin")])
def test_multigrid_cycles_with_a_moving_ball(fbm, coarse_obstacle):
    """FGMRES with V(2,2) cycles on the moving-disk system converges to 1e-8 in at most 1.5 times
    the cycles of the same mesh without the disk (measured at 32^2: 7 without, 8 / 9 / 9 with,
    thanks to the two extra sweeps at the interface; 11 / 13 / 13 without those; before the
    prolongation was truncated on the constrained DOFs: 100, not converged)."""
    _, system, b = _ball_system(fbm, n=32, coarse_obstacle=coarse_obstacle)
    mg = MultigridSolver(MultigridSettings(smoother="vanka-factored", coarse_obstacle=coarse_obstacle))
    du, dp, rep = mg.solve(system, b[:system.n_u], b[system.n_u:])
    x = np.concatenate([du, dp])
    assert np.linalg.norm(b - system.apply(x)) <= 1e-7 * np.linalg.norm(b)
    _, plain_system, plain_b = _ball_system("none", n=32)
    plain = mg.solve(plain_system, plain_b[:plain_system.n_u], plain_b[plain_system.n_u:])[2].iterations
    assert rep.iterations <= 1.5 * plain, (rep.iterations, plain)


@pytest.mark.parametrize("dim, n", [(2, 32), (3, 8)])
def test_the_scalar_velocity_blocks_solve_as_the_assembled_ones(dim, n):
    """The Picard hierarchy's velocity blocks, stored once per scalar
    (:class:`~fbmflow.fem.velocity_block.VelocityBlock`), give the solve of the same hierarchy
    with assembled blocks: the same cycles and the same solution to round-off, with the sharp
    boundary's ghost rows on the fine level."""
    from fbmflow.fem.velocity_block import VelocityBlock
    _, system, b = _ball_system("sharp", n=n, dim=dim)
    level, assembled = system.preconditioner, None
    chain = []
    while level is not None:
        assert isinstance(level.A, VelocityBlock)
        chain.append(dataclasses.replace(level, A=level.A.tocsr(), coarser=None))
        level = level.coarser
    assert system.preconditioner.rows is not None
    for finer, coarser in zip(chain, chain[1:]):
        finer.coarser = coarser
    assembled = dataclasses.replace(system, preconditioner=chain[0])
    mg = MultigridSolver(MultigridSettings(smoother="vanka-factored"))
    out = [mg.solve(s, b[:system.n_u], b[system.n_u:]) for s in (system, assembled)]
    assert out[0][2].iterations == out[1][2].iterations
    for got, want in zip(out[0][:2], out[1][:2]):
        assert np.allclose(got, want, rtol=0.0, atol=1e-12 * np.abs(want).max())


@pytest.mark.parametrize("dim, n", [(2, 32), (3, 8)])
def test_a_solve_gives_the_same_bits_on_one_thread_and_on_two(dim, n, monkeypatch):
    """The set-up and the solve of a sharp-boundary ball's hierarchy on 1 and on 2 Numba threads:
    the same cycles and the same bits, so that ``multigrid.threads = "free"``
    (:mod:`fbmflow.cores`) may change the count between solves."""
    import numba

    from fbmflow.solvers import vanka
    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("needs two Numba threads")
    monkeypatch.setattr(vanka, "SERIAL_CELLS_PER_THREAD", 0)  # the phases in parallel on this small mesh
    _, system, b = _ball_system("sharp", n=n, dim=dim)
    mg = MultigridSolver(MultigridSettings(smoother="vanka-factored", threads="fixed"))
    out, before = [], numba.get_num_threads()
    try:
        for threads in (1, 2):
            numba.set_num_threads(threads)
            out.append(mg.solve(system, b[:system.n_u], b[system.n_u:]))
    finally:
        numba.set_num_threads(before)
    assert out[0][2].iterations == out[1][2].iterations
    assert np.array_equal(out[0][0], out[1][0]) and np.array_equal(out[0][1], out[1][1])


@pytest.mark.parametrize("dim", [2, 3])
def test_the_gradient_applied_cell_by_cell_is_the_assembled_one(dim):
    """Where the system has the divergence in its cell pattern (the sharp boundary's fine level)
    it keeps no gradient matrix: ``B p`` comes from ``B^T`` cell by cell, colour by colour, and
    equals the assembled product; the whole operator equals the assembled matrix's."""
    from fbmflow.solvers.sparse import cell_transposed_matvec
    _, system, _ = _ball_system("sharp", n=16 if dim == 2 else 6, dim=dim)
    fine = system.preconditioner
    assert fine.gradient_BT is not None and fine._gradient is None
    rng = np.random.default_rng(5)
    p = rng.standard_normal(fine.n_p)
    B = fine.gradient
    assert fine._gradient is None  # built for the caller, not kept
    want = B @ p
    assert np.allclose(fine.apply_gradient(p), want, rtol=0.0, atol=1e-13 * np.abs(want).max())
    G = fine.gradient_BT
    assert np.allclose(cell_transposed_matvec(G, p, fine.space.colour_groups, dim + 1), G.T @ p,
                       rtol=0.0, atol=1e-13 * np.abs(want).max())
    x = rng.standard_normal(fine.n_u + fine.n_p)
    K = fine.matrix(bordered=False)
    assert np.allclose(fine.apply(x), K @ x, rtol=0.0, atol=1e-12 * np.abs(K @ x).max())


@pytest.mark.parametrize("dim", [2, 3])
def test_gradient_rows_read_cell_by_cell_are_the_built_ones(dim):
    """``gradient_rows`` reads rows of ``B`` from the divergence cell by cell (the sharp boundary's
    fine level): the same entries, pattern and order as the rows of the built ``B``, the zeroed
    rows (constrained velocities) included with their zeros, for rows in any order; a divergence
    out of its cell pattern (one column moved) is not read that way, and the rows are still the
    built ones."""
    import dataclasses

    from fbmflow.solvers.system import cell_local
    _, system, _ = _ball_system("sharp", n=16 if dim == 2 else 6, dim=dim)
    fine = system.preconditioner
    assert cell_local(fine.space, fine.gradient_BT)
    rng = np.random.default_rng(11)
    rows = rng.permutation(fine.n_u)[:fine.n_u // 3]
    rows = np.union1d(rows, fine.gradient_zero[:5])[::-1]  # descending, some zeroed rows
    got, want = fine.gradient_rows(rows), fine.gradient[rows]
    assert np.array_equal(got.indptr, want.indptr) and np.array_equal(got.indices, want.indices)
    assert np.array_equal(got.data, want.data)
    assert (fine.gradient_rows(fine.gradient_zero).data == 0.0).all()
    moved = fine.gradient_BT.copy()
    moved.indices[0], moved.indices[1] = moved.indices[1], moved.indices[0]
    assert not cell_local(fine.space, moved)
    odd = dataclasses.replace(fine, gradient_BT=moved)
    assert (odd.gradient_rows(rows) != odd.gradient[rows]).nnz == 0


@pytest.mark.parametrize("dim, n", [(2, 32), (3, 8)])
def test_multigrid_solves_the_sharp_boundary_in_a_closed_box(dim, n):
    """In a closed box the sharp system's left null vector has components on the ghost rows, so
    the balanced right-hand side still misses the range; FGMRES solves for the mean-pressure
    multiplier as the bordered direct solve does (without it: 100 iterations, reduction 3e-3).
    The cycles stay within 1.5x of the box without the ball (measured: 2D 32^2 6 / 9, 3D 8^3
    8 / 9; 6 / 13 and 8 / 10 before the extra sweeps at the interface), and the velocity is the
    direct solver's."""
    _, system, b = _ball_system("sharp", n=n, dim=dim, closed=True)
    assert system.mean_weights is not None and system.rows is not None
    mg = MultigridSolver(MultigridSettings(smoother="vanka-factored"))
    du, dp, rep = mg.solve(system, b[:system.n_u], b[system.n_u:])
    _, plain_system, plain_b = _ball_system("none", n=n, dim=dim, closed=True)
    plain = mg.solve(plain_system, plain_b[:plain_system.n_u], plain_b[plain_system.n_u:])[2].iterations
    assert rep.iterations <= 1.5 * plain, (rep.iterations, plain)
    _, newton_system, _ = _ball_system("sharp", n=n, dim=dim, closed=True, linearisation="newton")
    u, _ = factorize(newton_system, "superlu")(b[:system.n_u], b[system.n_u:])
    assert np.linalg.norm(du - u) <= 1e-6 * np.linalg.norm(u), np.linalg.norm(du - u) / np.linalg.norm(u)


def test_settings_refuse_galerkin_rows_with_a_smoother_that_cannot_see_them():
    """vanka-full / -diagonal re-assemble cell blocks from element matrices, not from the
    Galerkin rows (measured: overflow on the 3D ball); ``auto`` picks the factored blocks."""
    with pytest.raises(ValueError, match="vanka-factored"):
        MultigridSettings(smoother="vanka-full", coarse_obstacle="galerkin")
    _, system, _ = _ball_system("nodes", n=8, coarse_obstacle="galerkin")
    assert (MultigridSolver(MultigridSettings(coarse_obstacle="galerkin")).smoother_for(system)
            == "vanka-factored")
    assert MultigridSolver(MultigridSettings()).smoother_for(system) == "vanka-factored"
    assert MultigridSolver(MultigridSettings(smoother="vanka-full")).smoother_for(system) == "vanka-full"


def test_multigrid_solves_a_cylinder_spanning_the_box():
    """A fixed cylinder through the whole box along z leaves cut cells whose few free velocities
    only balance each other: orphaned pressure modes spread over a column of cells. One patch
    per such cluster smooths them (measured at this size: 7 cycles with the cluster patches, 20
    without; 7 against 60 and no convergence at twice the resolution)."""
    from fbmflow.coupling import FixedObstacles
    from fbmflow.particles import Cylinder
    from fbmflow.solvers.vanka import FactoredVankaSmoother
    mesh = StructuredMesh.box((32, 16, 4), upper=(2.0, 1.0, 0.25))
    bcs = {t: NoSlip() for t in mesh.tags}
    bcs["xmin"] = Dirichlet(lambda x, t: np.column_stack([256 * x[:, 1] * (1 - x[:, 1])
                                                          * x[:, 2] * (0.25 - x[:, 2]),
                                                          0 * x[:, 0], 0 * x[:, 0]]))
    bcs["xmax"] = DoNothing()
    mg = MultigridSolver(MultigridSettings(max_iterations=60))
    prob = NavierStokesProblem(mesh, 1e-2, bcs, linear_solver=mg, convection=False,
                               extra_constraints=FixedObstacles([Cylinder(0.1, 0.5)], [[0.51, 0.47, 0.125]]))
    x, con = prob.zero_state(), prob.constraints()
    F = prob.residual(x, 0.0, 1.0, prob.load(), con, prob.orphans(con))
    system = prob.linear_system(x, 0.0, 1.0, con)
    smoother = FactoredVankaSmoother(system)
    assert smoother.merged.size >= 2  # the clusters' patches
    # each cluster is one patch instead of its cells' (alternating both diverged on a coarse
    # level of 2 000 disks): every pressure DOF in exactly one patch
    pressures = smoother.dofs[smoother.dofs >= system.n_u] - system.n_u
    assert np.array_equal(np.bincount(pressures, minlength=system.n_p), np.ones(system.n_p, dtype=int))
    u, p, rep = mg.solve(system, -F[:system.n_u], -F[system.n_u:])
    assert rep.converged and rep.iterations <= 10, rep.iterations


def test_the_hierarchy_shows_its_levels_and_serves_scipy_as_a_preconditioner():
    """PyAMG's conveniences: the level table with the operator complexity, and one cycle as a
    SciPy LinearOperator, with which SciPy's GMRES solves the Stokes cavity as FGMRES does."""
    import scipy.sparse.linalg as spla

    prob, mg, x, con, F = _cavity_system(16)
    system = prob.linear_system(x, 0.0, 1.0, con)
    hierarchy = mg.factor(system)
    text = repr(hierarchy)
    assert "Number of levels:    3" in text and "(direct)" in text
    assert 1.0 < hierarchy.operator_complexity < 1.5  # each level about a quarter of the one above
    assert hierarchy.sweeps_per_cycle == 2 * (2 + 2)  # V(2,2) on the two smoothed levels
    K = system.matrix(bordered=False)
    b = np.concatenate([-F[:system.n_u], system.balance(-F[system.n_u:])])
    y, info = spla.gmres(K, b, M=hierarchy.aspreconditioner(), rtol=1e-8, restart=30, maxiter=60)
    assert info == 0
    u, p, report = hierarchy.solve(-F[:system.n_u], -F[system.n_u:])
    system.remove_pressure_mean(y)
    np.testing.assert_allclose(y[:system.n_u], u, atol=1e-6 * np.abs(u).max())


def test_two_solves_on_one_hierarchy_report_alike():
    """The hierarchy keeps no counter between solves: the same right-hand side twice gives the
    same cycles and sweeps."""
    for smoother in ("vanka-full", "vanka-factored"):
        prob, mg, x, con, F = _cavity_system(16, smoother=smoother)
        hierarchy = mg.factor(prob.linear_system(x, 0.0, 1.0, con))
        n_u = prob.space.n_u
        first = hierarchy.solve(-F[:n_u], -F[n_u:])[2]
        second = hierarchy.solve(-F[:n_u], -F[n_u:])[2]
        assert (first.iterations, first.smoothing_sweeps) == (second.iterations, second.smoothing_sweeps)
        assert first.setup_time_s > 0.0 and second.setup_time_s == 0.0  # the set-up billed once
        # the factored smoother's local factors are part of it, billed with it; vanka-full stores none
        stored = 0.0 < first.factor_time_s < first.setup_time_s
        assert (stored if smoother == "vanka-factored" else first.factor_time_s == 0.0), smoother
        assert second.factor_time_s == 0.0
