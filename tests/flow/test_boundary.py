"""Boundary conditions: slip planes, periodic directions, do-nothing outflow, validation."""
import numpy as np
import pytest

from fbmflow.fem.functions import sample_velocity
from fbmflow.flow import Dirichlet, DoNothing, NavierStokesProblem, NoSlip, Slip
from fbmflow.flow.boundary import build_constraints
from fbmflow.mesh import StructuredMesh


def test_periodic_channel_driven_by_body_force_is_poiseuille():
    """Periodic in x, no-slip in y, force G: u = G/(2 mu) y (1 - y) exactly (Q2 is exact)."""
    mu, G = 0.1, 2.0
    mesh = StructuredMesh.box((4, 4), periodic=(True, False))
    prob = NavierStokesProblem(mesh, mu, {"ymin": NoSlip(), "ymax": NoSlip()},
                               body_force=lambda x, t: np.column_stack([np.full(len(x), G), 0 * x[:, 0]]))
    x, report = prob.solve_steady()
    u, _ = prob.split(x)
    y = prob.space.V.coordinates[:, 1]
    assert np.max(np.abs(u[0] - G / (2 * mu) * y * (1 - y))) < 1e-10
    assert np.max(np.abs(u[1])) < 1e-10


def test_periodic_3d_duct_force_balance():
    """3D, periodic in x and z with slip-free walls in y: same Poiseuille profile."""
    mu, G = 1.0, 1.0
    mesh = StructuredMesh.box((2, 2, 2), periodic=(True, False, True))
    prob = NavierStokesProblem(mesh, mu, {"ymin": NoSlip(), "ymax": NoSlip()},
                               body_force=lambda x, t: np.column_stack([np.full(len(x), G), 0 * x[:, :2]]))
    x, _ = prob.solve_steady()
    u, _ = prob.split(x)
    y = prob.space.V.coordinates[:, 1]
    assert np.max(np.abs(u[0] - G / (2 * mu) * y * (1 - y))) < 1e-10


def test_slip_walls_give_plug_flow():
    """Uniform inflow between slip walls stays uniform up to the do-nothing outflow."""
    mesh = StructuredMesh.box((8, 2), upper=(4.0, 1.0))
    bcs = {"xmin": Dirichlet((1.0, 0.0)), "xmax": DoNothing(), "ymin": Slip(), "ymax": Slip()}
    prob = NavierStokesProblem(mesh, 0.01, bcs)
    x, _ = prob.solve_steady()
    u, p = prob.split(x)
    assert np.allclose(u[0], 1.0, atol=1e-10) and np.allclose(u[1], 0.0, atol=1e-10)
    assert np.allclose(p, 0.0, atol=1e-10)


def test_symmetry_plane_halves_the_channel():
    """Poiseuille flow in [0,1] equals the half channel [0,0.5] with a symmetry plane at y = 0.5."""
    mu = 0.05
    full = StructuredMesh.box((8, 4), upper=(2.0, 1.0))
    half = StructuredMesh.box((8, 2), upper=(2.0, 0.5))
    inflow = Dirichlet(lambda x, t: np.column_stack([4 * x[:, 1] * (1 - x[:, 1]), 0 * x[:, 0]]))
    res = []
    for mesh, top in ((full, NoSlip()), (half, Slip())):
        prob = NavierStokesProblem(mesh, mu, {"xmin": inflow, "xmax": DoNothing(), "ymin": NoSlip(),
                                              "ymax": top})
        x, _ = prob.solve_steady()
        pts = np.array([[1.0, 0.25], [1.7, 0.4], [0.3, 0.1]])
        res.append(sample_velocity(prob.space, x[:prob.space.n_u], pts))
    assert np.allclose(res[0], res[1], atol=1e-10)


def test_corner_precedence_no_slip_wins():
    mesh = StructuredMesh.box((2, 2))
    from fbmflow.fem.dofmap import DofMap
    V = DofMap(mesh)
    con = build_constraints(V, {"xmin": NoSlip(), "xmax": NoSlip(), "ymin": NoSlip(),
                                "ymax": Dirichlet((1.0, 0.0))})
    vals = np.zeros(2 * V.n_dofs)
    vals[con.dofs] = con.values
    top = V.boundary_dofs("ymax")
    corners = top[[0, -1]]
    assert np.all(vals[corners] == 0.0)
    assert np.all(vals[top[1:-1]] == 1.0)


@pytest.mark.parametrize("bcs, match", [
    ({"xmin": NoSlip()}, "no boundary condition for faces"),
    ({"xmin": NoSlip(), "xmax": NoSlip(), "ymin": NoSlip(), "ymax": NoSlip(), "zmin": NoSlip()},
     "unknown or periodic faces"),
    ({"xmin": NoSlip(), "xmax": NoSlip(), "ymin": NoSlip(), "ymax": "wall"}, "is not a boundary condition"),
])
def test_bad_boundary_conditions_are_rejected(bcs, match):
    with pytest.raises(ValueError, match=match):
        NavierStokesProblem(StructuredMesh.box((2, 2)), 1.0, bcs)


def test_bad_material_parameters_are_rejected():
    bcs = {t: NoSlip() for t in ("xmin", "xmax", "ymin", "ymax")}
    with pytest.raises(ValueError, match="viscosity must be positive"):
        NavierStokesProblem(StructuredMesh.box((2, 2)), -1.0, bcs)
    with pytest.raises(ValueError, match="density must be positive"):
        NavierStokesProblem(StructuredMesh.box((2, 2)), 1.0, bcs, density=0.0)


def test_wrong_dirichlet_shape_is_reported():
    bcs = {"xmin": Dirichlet((1.0, 0.0, 0.0)), "xmax": NoSlip(), "ymin": NoSlip(), "ymax": NoSlip()}
    with pytest.raises(ValueError, match="needs 2 components"):
        NavierStokesProblem(StructuredMesh.box((2, 2)), 1.0, bcs).zero_state()


def test_fluid_pocket_enclosed_by_constrained_nodes_is_closed():
    """Constrained nodes around one free node push fluid out of it: no divergence-free field
    exists unless the pocket is held still. The constraints close it; the solve converges."""
    from fbmflow.fem.constraints import DirichletConstraints

    mesh = StructuredMesh.box((6, 6))

    def ring(V, t):
        lat = np.array([(i, j) for i in range(4, 9) for j in range(4, 9) if (i, j) != (6, 6)])  # its 4 cells
        nodes = V._lattice_to_dof(lat)
        out = V.coordinates[nodes] - 0.5  # radially outwards: net flux out of the pocket
        dofs = np.concatenate([nodes, V.n_dofs + nodes])
        order = np.argsort(dofs)
        return DirichletConstraints(dofs[order], out.T.ravel()[order])

    flow = NavierStokesProblem(mesh, 1.0, {t: NoSlip() for t in mesh.tags}, convection=False,
                               extra_constraints=ring)
    con = flow.constraints()
    centre = flow.space.V._lattice_to_dof(np.array([[6, 6]]))[0]
    assert centre in con.dofs and centre + flow.space.n_v in con.dofs
    x, report = flow.solve_steady()
    assert report.converged and np.all(np.isfinite(x))
