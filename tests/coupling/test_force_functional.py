"""The forces as linear functionals of the flow (all particles, any number of flows at once): the
kernels against NumPy on tiny meshes, many flows against one at a time, and the simulation's
lifting-response forces against the force of each response."""
import numpy as np
import pytest
import scipy.sparse as sp

from fbmflow.coupling import (
    SurfaceForces,
    _kernels,
    cut_cells,
    hydrodynamic_forces,
    mirror_images,
    node_owner,
    rigid_liftings,
)
from fbmflow.coupling.forces import volume_force_functional
from fbmflow.fem import FlowSpace
from fbmflow.mesh import StructuredMesh
from fbmflow.particles import Ball, Particles


def _two_balls(dim, n=4):
    space = FlowSpace(StructuredMesh.box((n,) * dim))
    centres = np.array([[0.5] * dim, [0.2] * dim])
    owner = node_owner(space.V, centres, [Ball(0.3, dim), Ball(0.12, dim)])
    return space, centres, owner


def _numpy_rows(space, owner, centres, cell, i):
    """Coefficients (r, d, nl) of mu u and (r, d + 1) of p in the force and torque rows of the
    pair (cell, particle i): plain NumPy, one Gauss point at a time."""
    d = space.dim
    r = 3 if d == 2 else 6
    dofs = space.V.cell_dofs[cell]
    alpha = (owner[dofs] == i).astype(float)
    wu, wp = np.zeros((r, d, len(dofs))), np.zeros((r, d + 1))
    for q in range(len(space.weights)):
        g = space.dphi[q] @ space.Jinv[cell, q]  # (nl, d)
        ga = alpha @ g
        w = space.detJw[cell, q]
        cu = np.zeros((d, d, len(dofs)))  # t_j = -w (-p ga_j + mu (grad u + grad u^T) ga)_j
        for j in range(d):
            cu[j, j] += -w * (g @ ga)
            for n in range(d):
                cu[j, n] += -w * g[:, j] * ga[n]
        cp = w * np.outer(ga, space.psi[cell, q])
        arm = np.zeros(3)
        arm[:d] = space.xq[cell, q] - centres[i]
        cu3 = np.zeros((3,) + cu.shape[1:])
        cu3[:d] = cu
        cp3 = np.zeros((3, d + 1))
        cp3[:d] = cp
        tu = np.cross(arm[:, None, None], cu3, axis=0)
        tp = np.cross(arm[:, None], cp3, axis=0)
        wu[:d] += cu
        wp[:d] += cp
        wu[d:] += tu[2:] if d == 2 else tu
        wp[d:] += tp[2:] if d == 2 else tp
    return wu, wp


@pytest.mark.parametrize("dim", [2, 3])
def test_volume_force_rows_kernel_matches_numpy(dim):
    space, centres, owner = _two_balls(dim)
    pairs = [(c, i) for c in cut_cells(space, owner) for i in range(2)
             if 0 < np.sum(owner[space.V.cell_dofs[c]] == i) < space.V.cell_dofs.shape[1]]
    cells, particles = (np.array(a, dtype=np.int64) for a in zip(*pairs))
    assert set(particles) == {0, 1}
    if dim == 2:
        assert len(set(cells)) < len(cells)  # a cell with nodes of both balls
    wu, wp = _kernels.volume_force_rows(cells, particles, owner, centres, space.V.cell_dofs, space.dphi,
                                        space.detJw, space.Jinv, space.psi, space.xq,
                                        space.mesh.periods)
    for e, (c, i) in enumerate(pairs):
        ref_u, ref_p = _numpy_rows(space, owner, centres, c, i)
        np.testing.assert_allclose(wu[e], ref_u, rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(wp[e], ref_p, rtol=1e-12, atol=1e-14)


def test_csr_apply_rows_kernel_matches_numpy():
    rng = np.random.default_rng(1)
    G = sp.random(7, 30, density=0.3, format="csr", random_state=2)
    for X in (rng.standard_normal((5, 40))[:, 3:33],  # rows of a larger array: not contiguous
              rng.standard_normal((30, 5)).T):        # a transpose: the flows side by side
        out = np.ones((5, 7))
        _kernels.csr_apply_rows(G.indptr, G.indices, G.data, X, 0.5, out)
        np.testing.assert_allclose(out, 1.0 + 0.5 * X @ G.toarray().T, rtol=1e-13, atol=1e-14)


@pytest.mark.parametrize("dim", [2, 3])
def test_force_functional_evaluates_many_flows_as_one_at_a_time(dim):
    space, centres, owner = _two_balls(dim)
    rng = np.random.default_rng(4)
    X = rng.standard_normal((4, space.n_dofs))
    U, P = X[:, :space.n_u], X[:, space.n_u:]
    mu = 0.7
    for rule in (volume_force_functional(space, owner, centres),
                 SurfaceForces(space, centres, [Ball(0.3, dim), Ball(0.12, dim)])):
        F, T = rule.many(U, P, mu)
        Fu, Tu = rule.many(U, None, mu)
        Fp, Tp = rule.many(None, P, mu)
        assert F.shape == (4, 2, dim) and T.shape == (4, 2, 3)
        for k in range(4):
            f, t = rule(U[k], P[k], mu)
            np.testing.assert_allclose(F[k], f, rtol=1e-12, atol=1e-12)
            np.testing.assert_allclose(T[k], t, rtol=1e-12, atol=1e-12)
            np.testing.assert_allclose(Fu[k] + Fp[k], f, rtol=1e-12, atol=1e-12)
            np.testing.assert_allclose(Tu[k] + Tp[k], t, rtol=1e-12, atol=1e-12)
            np.testing.assert_allclose(rule(U[k], None, mu)[0], Fu[k], rtol=1e-12, atol=1e-12)
        if dim == 2:
            assert np.all(T[..., :2] == 0.0)
    F, T = volume_force_functional(space, owner, centres)(U[0], P[0], mu)
    F_ref, T_ref = hydrodynamic_forces(space, owner, centres, U[0], P[0], mu)
    np.testing.assert_array_equal(F, F_ref)


@pytest.mark.parametrize("dim", [2, 3])
def test_own_response_is_each_particle_s_block_of_the_forces_of_its_liftings(dim):
    """``own_response``: particle i's force and torque rows of the functional applied to its own
    unit rigid motions, one column at a time through ``many`` on dense liftings (the rows of
    the other particle dropped, unselected components zero)."""
    space, centres, owner = _two_balls(dim)
    r = 3 if dim == 2 else 6
    free = np.ones((2, r), dtype=bool)
    free[1, 0] = False
    W = rigid_liftings(space.V, owner, centres, free)
    mu = 0.7
    rule = volume_force_functional(space, owner, centres)
    S = rule.own_response(W, free, mu)
    F, T = rule.many(W.toarray().T, None, mu)  # (k, 2, dim), (k, 2, 3)
    rows = np.concatenate([F, T[..., 2:] if dim == 2 else T], axis=2)  # (k, 2, r)
    expected = np.zeros((2, r, r))
    for k, (i, b) in enumerate(zip(*np.nonzero(free))):
        expected[i, :, b] = rows[k, i]
    assert np.abs(expected).max() > 0.0 and np.all(S[1, :, 0] == 0.0)
    np.testing.assert_allclose(S, expected, rtol=1e-12, atol=1e-12 * np.abs(expected).max())
    # a translation drags its particle back: negative diagonal
    assert np.all(np.diagonal(S[0])[:dim] < 0.0)


def _numpy_surface_force(rule_points, space, u, p, mu, n_particles):
    """The traction integrated point by point (the surface rule's points, normals, weights)."""
    cells, xi, normal, arm, weight, particle = rule_points
    dim = space.dim
    _, dphi = space.V.element.tabulate(xi)
    dphi = dphi / space.Q.scale[cells][:, None, :]
    F, T = np.zeros((n_particles, dim)), np.zeros((n_particles, 3))
    uu = u.reshape(dim, space.n_v)
    for k, c in enumerate(cells):
        grad = uu[:, space.V.cell_dofs[c]] @ dphi[k]  # du_i / dx_j
        pq = p.reshape(-1, dim + 1)[c] @ np.concatenate([[1.0], xi[k]])  # P1disc: 1, (x - x_c) / s
        t = weight[k] * (-pq * normal[k] + mu * (grad + grad.T) @ normal[k])
        F[particle[k]] += t
        a3, t3 = np.zeros(3), np.zeros(3)
        a3[:dim], t3[:dim] = arm[k], t
        T[particle[k]] += np.cross(a3, t3)
    return F, T


@pytest.mark.parametrize("dim", [2, 3])
def test_surface_force_functional_matches_the_traction_point_by_point(dim):
    from fbmflow.fem.functions import locate
    space = FlowSpace(StructuredMesh.box((5,) * dim))
    centres = np.array([[0.43] * dim, [0.8] * dim])
    balls = [Ball(0.23, dim), Ball(0.15, dim)]
    rule = SurfaceForces(space, centres, balls)
    # the rule's points, rebuilt: 2D trapezoidal rule in phi (3D: Gauss in cos theta) per ball
    h = float(space.mesh.finest_spacing.min())
    per_circle = 4 * int(np.ceil(4 * 2 * np.pi * 0.23 / h / 4))
    phi = (np.arange(per_circle) + 0.5) * 2 * np.pi / per_circle
    if dim == 2:
        unit = np.column_stack([np.cos(phi), np.sin(phi)])
        w_unit = np.full(per_circle, 2 * np.pi / per_circle)
    else:
        c, wc = np.polynomial.legendre.leggauss(per_circle // 2)
        C, Ph = np.meshgrid(c, phi, indexing="ij")
        S = np.sqrt(1 - C**2)
        unit = np.stack([S * np.cos(Ph), S * np.sin(Ph), C], -1).reshape(-1, 3)
        w_unit = np.outer(wc, np.full(per_circle, 2 * np.pi / per_circle)).ravel()
    radius = np.array([0.23, 0.15])
    particle = np.repeat([0, 1], len(unit))
    normal = np.tile(unit, (2, 1))
    arm = radius[particle, None] * normal
    weight = np.tile(w_unit, 2) * radius[particle] ** (dim - 1)
    x = centres[particle] + arm
    keep = np.all((x >= 0) & (x <= 1), axis=1)
    cells, xi = locate(space.mesh, x[keep])
    points = (cells, xi, normal[keep], arm[keep], weight[keep], particle[keep])
    rng = np.random.default_rng(6)
    u, p = rng.standard_normal(space.n_u), rng.standard_normal(space.n_p)
    F, T = rule(u, p, 0.7)
    F_ref, T_ref = _numpy_surface_force(points, space, u, p, 0.7, 2)
    np.testing.assert_allclose(F, F_ref, rtol=1e-11, atol=1e-12)
    np.testing.assert_allclose(T, T_ref, rtol=1e-11, atol=1e-12)


def test_mirror_images_of_many_flows_are_those_of_each():
    rng = np.random.default_rng(2)
    F, T = rng.standard_normal((3, 4, 3)), rng.standard_normal((3, 4, 3))
    FF, TT = mirror_images(F, T, (0, 1))
    for k in range(3):
        f, t = mirror_images(F[k], T[k], (0, 1))
        np.testing.assert_array_equal(FF[k], f)
        np.testing.assert_array_equal(TT[k], t)


@pytest.mark.parametrize("scheme, force", [("crank-nicolson", "volume"), ("backward-euler", "test-function")])
def test_lifting_response_forces_are_the_forces_of_each_response(scheme, force):
    """The implicit coupling's response forces, all responses at once (``evaluate_many``), equal
    the force of each response taken alone, with the pressure's part lagged (Crank–Nicolson)."""
    from fbmflow.coupling.settings import CouplingParams, FictitiousBoundaryParams
    from fbmflow.params import FluidParams, TimeParams
    from fbmflow.simulation import Simulation
    from fbmflow.solvers.settings import SolverParams

    mesh = StructuredMesh.box((12, 12))
    particles = Particles.at_rest([Ball(0.12, 2)] * 3, 1.5, [[0.3, 0.6], [0.65, 0.55], [0.5, 0.25]])
    sim = Simulation(mesh, particles, FluidParams(density=1.0, viscosity=0.1, gravity=9.8),
                     time=TimeParams(scheme=scheme), solver=SolverParams(linear="direct"),
                     coupling=CouplingParams(scheme="implicit"),
                     fbm=FictitiousBoundaryParams(boundary="nodes", force=force))
    sim.step(0.01)
    sim.particles.velocity[:] = [[0.1, -0.2], [0.0, -0.1], [-0.05, 0.0]]  # a lagged pressure rule
    dt = 0.01
    x, _, _, _ = sim.system.flow_and_forces(dt)
    free = np.ones((3, 3), dtype=bool)
    dX, dF, dT = sim.system.rigid_responses(x, free, dt)
    assert dX.shape[0] == 9 and dF.shape == (9, 3, 2) and dT.shape == (9, 3, 3)
    for k in range(len(dX)):
        f, t = sim.system.forces(dX[k], dt, about=x)
        np.testing.assert_allclose(dF[k], f, rtol=1e-10, atol=1e-12 * np.abs(dF).max())
        np.testing.assert_allclose(dT[k], t, rtol=1e-10, atol=1e-12 * np.abs(dT).max())
    assert np.abs(dF).max() > 0


@pytest.mark.parametrize("dim", [2, 3])
def test_test_function_linearisation_evaluates_many_responses_as_one_at_a_time(dim):
    from fbmflow.coupling import TestFunctionForces
    space = FlowSpace(StructuredMesh.box((6,) * dim))
    centres = np.array([[0.55] * dim, [0.2] * dim])
    shapes = [Ball(0.2, dim), Ball(0.12, dim)]
    owner = node_owner(space.V, centres, shapes)
    walls = np.flatnonzero(np.isclose(space.V.coordinates, 0.0).any(axis=1))
    tested = TestFunctionForces(space, owner, centres, shapes, walls=walls)
    rng = np.random.default_rng(8)
    about = rng.standard_normal(space.n_u)
    X = rng.standard_normal((3, space.n_dofs))
    mu, rho = 0.4, 1.7
    for dt in (0.05, None):
        F, T = tested.linearised(about, mu, rho, dt).many(X[:, :space.n_u], X[:, space.n_u:], 1.0)
        for k in range(3):
            f, t = tested(X[k, :space.n_u], X[k, space.n_u:], mu, rho, dt=dt, about=about)
            np.testing.assert_allclose(F[k], f, rtol=1e-10, atol=1e-12 * np.abs(F).max())
            np.testing.assert_allclose(T[k], t, rtol=1e-10, atol=1e-12 * np.abs(T).max())


@pytest.mark.parametrize("dim", [2, 3])
def test_forces_of_a_ball_straddling_periodic_sides_equal_those_of_the_ball_inside(dim):
    """A ball across the periodic sides feels what the same ball in the middle feels in the same
    (shifted) flow: the owner, the cut cells and the torque arm take the nearest image."""
    mesh = StructuredMesh.box((8,) * dim, periodic=(True,) * dim)
    space = FlowSpace(mesh)
    ball = Ball(0.2, dim)
    results = []
    for shift in (0.0, 0.5):  # half a period: the flow moves by whole cells
        centre = np.full((1, dim), 0.513)
        centre[0, 0] += shift  # 1.013: straddles x = 0 / 1 (and wraps beyond the box)
        rel = space.V.coordinates - centre[0]
        u = np.stack([np.sin(2 * np.pi * (rel[:, (k + 1) % dim] + 0.1 * k)) * np.cos(2 * np.pi * rel[:, k])
                      for k in range(dim)])
        rc = space.Q.centre - centre[0]
        p = np.zeros((mesh.n_cells, dim + 1))
        p[:, 0] = np.cos(2 * np.pi * rc[:, 0]) * np.sin(2 * np.pi * rc[:, -1] + 0.3)
        owner = node_owner(space.V, centre, [ball])
        results.append([hydrodynamic_forces(space, owner, centre, u.ravel(), p.ravel(), 1.0),
                        SurfaceForces(space, centre, [ball])(u.ravel(), p.ravel(), 1.0)])
    for (F0, T0), (F1, T1) in zip(*results):
        assert np.abs(T0).max() > 1e-3  # a torque that a wrong arm would change
        np.testing.assert_allclose(F1, F0, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(T1, T0, rtol=1e-9, atol=1e-12)
