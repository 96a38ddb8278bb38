"""The sharp fictitious boundary: closest-point projections, ghost rows exact for linear flows,
the cut cells' continuity rows and pressure extension, the kernel that writes constraint rows,
the Newton system against finite differences, and accuracy against the nodal boundary."""
import numpy as np
import pytest
import scipy.sparse as sp

from fbmflow.coupling import FixedObstacles, node_owner, sharp_boundary
from fbmflow.coupling.sharp import pressure_extension
from fbmflow.fem import FlowSpace, assemble_divergence
from fbmflow.fem import _kernels as fk
from fbmflow.fem.constraints import RowConstraints
from fbmflow.flow import Dirichlet, DoNothing, NavierStokesProblem, NoSlip
from fbmflow.mesh import StructuredMesh
from fbmflow.particles import Ball, Box, Cylinder
from fbmflow.solvers import DirectSolver

RNG = np.random.default_rng(7)


@pytest.mark.parametrize("shape", [Ball(0.3, 2), Ball(0.3, 3), Box((0.3, 0.2)), Box((0.3, 0.2, 0.25)),
                                   Cylinder(0.2, 0.5)], ids=repr)
def test_projection_is_the_closest_surface_point(shape):
    """Inside points go to the surface along the outward unit normal, and no surface point of a
    dense sample is closer."""
    d = shape.dim
    x = RNG.uniform(-0.35, 0.35, (400, d))
    x = x[shape.inside(x)][:60]
    p, n = shape.project(x)
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0)
    dist = np.linalg.norm(p - x, axis=1)
    np.testing.assert_allclose(np.einsum("ij,ij->i", p - x, n), dist, atol=1e-12)  # along the normal
    assert np.all(shape.inside(p - 1e-9 * n)) and not np.any(shape.inside(p + 1e-6 * n))
    cloud = RNG.uniform(-0.35, 0.35, (20000, d))
    samples = shape.project(cloud[shape.inside(cloud)])[0]  # a dense sample of the surface
    nearest = np.min(np.linalg.norm(samples[None, :, :] - x[:, None, :], axis=2), axis=1)
    assert np.all(dist <= nearest + 1e-12)


def _setup(dim, level=2):
    n = 4 * 2**level
    mesh = StructuredMesh.rectilinear([np.linspace(0.0, 1.0, n + 1) ** 1.1]
                                      + [np.linspace(0.0, 1.0, n + 1)] * (dim - 1))
    space = FlowSpace(mesh)
    centres = np.array([[0.47] + [0.52] * (dim - 1)])
    shapes = [Ball(0.23, dim)]
    owner = node_owner(space.V, centres, shapes)
    return space, centres, shapes, owner


@pytest.mark.parametrize("dim", [2, 3])
def test_ghost_rows_are_exact_for_linear_flows(dim):
    """A linear velocity field continued linearly through the surface is itself: ``C u = g``
    holds to round-off when the particle's own velocity at the surface points is that field's
    (a rigid motion is a linear field, so the particle may translate and spin)."""
    space, centres, shapes, owner = _setup(dim)
    U, w = RNG.normal(size=(1, dim)), RNG.normal(size=(1,) if dim == 2 else (1, 3))
    X = space.V.coordinates - centres[0]
    if dim == 2:
        u = U[0] + w[0] * np.column_stack([-X[:, 1], X[:, 0]])
    else:
        u = U[0] + np.cross(w[0], X)
    sharp = sharp_boundary(space, owner, centres, shapes)
    rows = sharp.ghosts.constraints(U, w)
    assert rows.dofs.size > 0
    assert np.abs(rows.residual(u.T.ravel())).max() < 1e-13 * np.abs(u).max()
    assert sharp.ghosts.weight.min() >= 1.0 and sharp.ghosts.weight.max() <= 2.0 + 1e-12


def test_ghost_liftings_are_the_derivatives_of_the_values():
    space, centres, shapes, owner = _setup(3, 1)
    ghosts = sharp_boundary(space, owner, centres, shapes).ghosts
    free = np.array([[True, False, True, True, True, False]])
    L = ghosts.liftings(free).toarray()
    v0 = ghosts.constraints(np.zeros((1, 3)), np.zeros((1, 3))).values
    for k, b in enumerate(np.flatnonzero(free[0])):
        g = np.zeros(6)
        g[b] = 1.0
        v = ghosts.constraints(g[None, :3], g[None, 3:]).values - v0
        np.testing.assert_allclose(L[ghosts.dofs, k], v, atol=1e-15)
    assert np.all(L[np.setdiff1d(np.arange(L.shape[0]), ghosts.dofs)] == 0.0)


@pytest.mark.parametrize("dim", [2, 3])
def test_uncovered_ghost_nodes_take_the_solids_velocity(dim):
    """Moved by a third of a cell, the particle leaves some ghost nodes in the fluid: exactly
    those are returned, with the rigid velocity of the moved, spinning particle."""
    space, centres, shapes, owner = _setup(dim)
    ghosts = sharp_boundary(space, owner, centres, shapes).ghosts
    moved = centres + 0.3 / (4 * 2**2)
    later = node_owner(space.V, moved, shapes)
    U, w = RNG.normal(size=(1, dim)), RNG.normal(size=(1,) if dim == 2 else (1, 3))
    dofs, values = ghosts.uncovered(space.V, later, moved, U, w)
    expected = ghosts.nodes[later[ghosts.nodes] < 0]
    assert expected.size > 0 and np.all(owner[expected] >= 0)
    n_v = space.V.n_dofs
    np.testing.assert_array_equal(dofs, np.concatenate([c * n_v + expected for c in range(dim)]))
    X = space.V.coordinates[expected] - moved[0]
    rigid = U[0] + (w[0] * np.column_stack([-X[:, 1], X[:, 0]]) if dim == 2 else np.cross(w[0], X))
    np.testing.assert_allclose(values, rigid.T.ravel(), atol=1e-14)


@pytest.mark.parametrize("dim", [2, 3])
def test_fluid_continuity_rows(dim):
    """The cut cells' continuity rows over the fluid part: equal to the assembled rows for a
    particle too small to reach the quadrature points, zero for one that covers the cell, and in
    between for the real one (the constant mode's row sums to the fluid part's flux)."""
    space, centres, shapes, owner = _setup(dim, 1)
    BT = assemble_divergence(space).data.reshape(space.mesh.n_cells, dim + 1, -1)
    cont = sharp_boundary(space, owner, centres, shapes).continuity
    tiny = sharp_boundary(space, owner, centres, [Ball(1e-9, dim)]).continuity
    huge = sharp_boundary(space, owner, centres, [Ball(5.0, dim)]).continuity
    np.testing.assert_allclose(tiny.data, BT[tiny.cells], atol=1e-15)
    assert np.all(huge.data == 0.0)
    whole, part = np.abs(BT[cont.cells]).sum(), np.abs(cont.data).sum()
    assert 0.2 * whole < part < whole


@pytest.mark.parametrize("dim", [2, 3])
def test_pressure_extension_continues_a_linear_pressure_exactly(dim):
    space, centres, shapes, owner = _setup(dim)
    ext = pressure_extension(space, owner, np.flatnonzero(
        ((o := owner[space.V.cell_dofs]) < 0).any(axis=1) & (o >= 0).any(axis=1)), centres)
    a, b = 0.7, RNG.normal(size=dim)
    npl = dim + 1
    c, s = space.Q.centre, space.Q.scale
    p = np.zeros(space.n_p)  # P1disc coefficients of p(x) = a + b . x on every cell
    p[0::npl] = a + c @ b
    for k in range(dim):
        p[k + 1::npl] = b[k] * s[:, k]
    assert ext.dofs.size > 0
    np.testing.assert_allclose((ext.matrix @ p)[ext.dofs], p[ext.dofs], atol=1e-13)
    assert np.abs(ext.residual(p)).max() < 1e-13
    targets = ext.matrix[ext.dofs].tocoo().col // npl
    assert np.all((owner[space.V.cell_dofs[targets]] < 0).all(axis=1))  # continued from fluid cells


def test_replace_rows_kernel_matches_numpy():
    A = sp.random(12, 12, density=0.4, random_state=3, format="csr") + sp.identity(12, format="csr")
    A.sort_indices()
    rows = np.array([2, 7])
    R = sp.lil_matrix((2, 12))
    R[0, A[2].indices[:3]] = [1.0, 2.0, 3.0]
    R[1, A[7].indices[-2:]] = [4.0, 5.0]
    R = R.tocsr()
    R.sort_indices()
    ref = A.toarray()
    ref[rows] = R.toarray()
    B = A.copy()
    assert fk.replace_rows(B.indptr, B.indices, B.data, rows, R.indptr, R.indices, R.data)
    np.testing.assert_array_equal(B.toarray(), ref)
    column = np.setdiff1d(np.arange(12), A[2].indices)[0]
    outside = sp.csr_matrix((np.array([9.0]), (np.array([0]), np.array([column]))), shape=(1, 12))
    C = A.copy()
    assert not fk.replace_rows(C.indptr, C.indices, C.data, rows[:1], outside.indptr, outside.indices,
                               outside.data)
    np.testing.assert_array_equal(C.toarray(), A.toarray())  # all or nothing
    written = RowConstraints(rows[:1], outside, np.zeros(1)).write_rows(A.copy(), np.array([2.0]))
    expected = A.toarray()
    expected[2] = 2.0 * outside.toarray()[0]
    np.testing.assert_array_equal(written.toarray(), expected)


def _cylinder_flow(level, boundary, convection=True):
    """Channel flow past a fixed disk (DFG 2D-1 geometry) with the given boundary."""
    from fbmflow.scenes.dfg import DFG2D1
    scene = DFG2D1()
    mesh = scene.mesh(level)
    bcs = {"xmin": Dirichlet(scene.inflow(0.3)), "xmax": DoNothing(), "ymin": NoSlip(), "ymax": NoSlip()}
    obstacle = FixedObstacles([scene.cylinder()], scene.centre[None, :], boundary)
    return NavierStokesProblem(mesh, 1e-3, bcs, linear_solver=DirectSolver(), extra_constraints=obstacle,
                               convection=convection)


def test_newton_system_matches_the_residual():
    """The Jacobian with ghost rows, fluid-part continuity and the pressure extension is the
    derivative of the residual (central differences, random state, orphaned modes left out)."""
    problem = _cylinder_flow(2, "sharp")
    con = problem.constraints(0.0)
    assert con.rows is not None and con.extension is not None
    x = RNG.standard_normal(problem.n_dofs) * 0.1
    con.apply_to_vector(x)
    orphans, rhs = problem.orphans(con), problem.load(0.0)
    system = problem.linear_system(x, 0.0, 1.0, con)
    d = RNG.standard_normal(problem.n_dofs)
    d[con.fixed] = 0.0
    if system.orphans is not None:
        d[problem.space.n_u:] -= system.orphans @ d[problem.space.n_u:]
    eps = 1e-6
    fd = (problem.residual(x + eps * d, 0.0, 1.0, rhs, con, orphans)
          - problem.residual(x - eps * d, 0.0, 1.0, rhs, con, orphans)) / (2 * eps)
    Kd = system.matrix(bordered=False) @ d
    assert np.abs(fd - Kd).max() < 1e-8 * np.abs(fd).max()


def test_stokes_flow_past_a_disk_stays_bounded():
    """Without the pressure extension the cut cells' weakly seen pressure modes drove the
    velocities to 20 times the inflow at 4 cells per diameter; with it the flow stays near the
    nodal boundary's (max |u| 0.39 for a centre-line inflow of 0.3) and the pressure physical."""
    for level in (2, 3):
        problem = _cylinder_flow(level, "sharp", convection=False)
        x, report = problem.solve(problem.zero_state(), 0.0, 1.0, problem.load(0.0), 0.0)
        u, p = problem.split(x)
        assert report.iterations == 1
        assert np.abs(u).max() < 0.45 and np.abs(p).max() < 0.1, (np.abs(u).max(), np.abs(p).max())


def test_channel_over_a_flat_face_is_far_more_accurate_than_the_nodal_boundary():
    """Stokes flow driven by a body force in a periodic channel whose floor is a box face at
    y = 0.23 (between nodes): u = (y - 0.23)(1 - y) / 2 exactly. The nodal boundary puts the wall
    on the last node layer inside; the sharp one meets it up to the extrapolation's O(h^2)
    (measured max errors, 8 / 16 / 32 cells: nodal 1.2e-2 / 2.5e-3 / 4.3e-3, sharp 5.8e-4 /
    1.2e-5 / 8.7e-5)."""
    y0, box, centres = 0.23, Box((5.0, 0.23)), np.array([[0.5, 0.0]])
    errors = {}
    for boundary in ("nodes", "sharp"):
        for n in (8, 16, 32):
            mesh = StructuredMesh.box((n, n), periodic=(True, False))
            problem = NavierStokesProblem(mesh, 1.0, {"ymin": NoSlip(), "ymax": NoSlip()}, convection=False,
                                          body_force=lambda x, t: np.column_stack([np.ones(len(x)),
                                                                                   0 * x[:, 0]]),
                                          linear_solver=DirectSolver(),
                                          extra_constraints=FixedObstacles([box], centres, boundary))
            x, _ = problem.solve_steady()
            u, _ = problem.split(x)
            X = problem.space.V.coordinates
            fluid = X[:, 1] >= y0
            exact = 0.5 * (X[fluid, 1] - y0) * (1 - X[fluid, 1])
            errors[boundary, n] = np.abs(u[0, fluid] - exact).max()
    for n in (8, 16, 32):
        assert errors["sharp", n] < 0.1 * errors["nodes", n], errors
    assert errors["sharp", 32] < 2e-4 and errors["sharp", 16] < 1e-4, errors


def test_lifting_response_in_a_closed_box_matches_finite_differences():
    """The implicit coupling's linear response of the flow to the particle velocity equals the
    derivative of the solved flow (central differences), in a closed box, where the sharp
    boundary's continuity rows make the pressure border's left null vector unknown and the
    direct solver solves the bordered system exactly (balancing alone was 2-35 % off)."""
    from fbmflow.coupling.settings import CouplingParams, FictitiousBoundaryParams
    from fbmflow.params import FluidParams, TimeParams
    from fbmflow.particles import Particles
    from fbmflow.simulation import Simulation
    from fbmflow.solvers.settings import SolverParams

    mesh = StructuredMesh.box((8, 12), upper=(2.0, 3.0))
    sim = Simulation(mesh, Particles.at_rest([Ball(0.3, 2)], 1.5, [[1.03, 1.51]]),
                     FluidParams(density=1.0, viscosity=0.5), time=TimeParams(scheme="backward-euler"),
                     solver=SolverParams(linear="direct", newton_reuse_jacobian=False),
                     coupling=CouplingParams(first_rtol=1e-10),
                     fbm=FictitiousBoundaryParams(boundary="sharp"))
    sim.step(0.01)
    p = sim.particles

    def flow(vy):
        state = p.copy()
        state.velocity = p.velocity + [0.0, vy]
        return sim.system.flow_and_forces(0.01, velocities=state)[0]

    x0 = flow(0.0)
    free = np.array([[False, True, False]])
    dX = sim.system.rigid_responses(x0, free, 0.01)[0][0]
    fd = (flow(1e-4) - flow(-1e-4)) / 2e-4
    assert np.abs(dX - fd).max() < 1e-7 * np.abs(fd).max()
