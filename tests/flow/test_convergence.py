"""Manufactured-solution convergence of Q2/P1disc for Stokes and steady Navier–Stokes.

Targets (issue 2): fitted orders velocity L2 >= 2.8, velocity H1 >= 1.8, pressure L2 >= 1.8 on
three nested meshes, in 2D and 3D, on uniform and on smoothly deformed meshes (2D).
"""
import numpy as np
import pytest
from mms import Manufactured2D, Manufactured3D, body_force, fitted_order

from fbmflow.fem.functions import error_norms
from fbmflow.flow import Dirichlet, NavierStokesProblem
from fbmflow.mesh import StructuredMesh
from fbmflow.solvers import DirectSolver


def deform(mesh: StructuredMesh, amplitude: float = 0.06) -> StructuredMesh:
    """Smoothly moved interior vertices (boundary kept on the box)."""
    x = mesh.vertices.copy()
    bump = np.prod(np.sin(np.pi * x), axis=1)
    x[:, 0] += amplitude * bump * np.cos(np.pi * x[:, 1])
    x[:, 1] += amplitude * bump * np.sin(2 * np.pi * x[:, 0])
    return StructuredMesh(mesh.shape, mesh.lower, mesh.upper, mesh.periodic, x)


def convergence(sol, cells, convection, deformed=False, mu=1.0, rho=1.0):
    h, errs, its = [], [], []
    for n in cells:
        mesh = StructuredMesh.box((n,) * sol.dim)
        if deformed:
            mesh = deform(mesh)
        bc = {t: Dirichlet(lambda x, t: sol.u(x)) for t in mesh.tags}
        prob = NavierStokesProblem(mesh, mu, bc, density=rho,
                                   body_force=body_force(sol, mu, rho, convection), convection=convection,
                                   linear_solver=DirectSolver())
        x, report = prob.solve_steady()
        u, p = prob.split(x)
        e = error_norms(prob.space, u.ravel(), p, sol.u, sol.grad, sol.p)
        h.append(1.0 / n)
        errs.append([e["u_l2"], e["u_h1"], e["p_l2"]])
        its.append(report.iterations)
    errs = np.array(errs)
    return [fitted_order(h, errs[:, i]) for i in range(3)], errs, its


@pytest.mark.parametrize("convection", [False, True], ids=["stokes", "navier-stokes"])
@pytest.mark.parametrize("deformed", [False, True], ids=["uniform", "deformed"])
def test_orders_2d(convection, deformed):
    orders, errs, its = convergence(Manufactured2D, [4, 8, 16], convection, deformed)
    assert orders[0] >= 2.8 and orders[1] >= 1.8 and orders[2] >= 1.8, (orders, errs)
    assert max(its) <= (1 if not convection else 5)


@pytest.mark.parametrize("convection", [False, True], ids=["stokes", "navier-stokes"])
def test_orders_3d(convection):
    orders, errs, its = convergence(Manufactured3D, [2, 4, 8], convection)
    assert orders[0] >= 2.8 and orders[1] >= 1.8 and orders[2] >= 1.8, (orders, errs)
    assert max(its) <= (1 if not convection else 5)


def test_navier_stokes_dominated_convection_2d():
    """Re ~ 100 on the manufactured field (mu = 0.01): Newton still converges with full order."""
    orders, errs, its = convergence(Manufactured2D, [8, 16, 32], True, mu=0.01)
    assert orders[0] >= 2.8 and orders[1] >= 1.8 and orders[2] >= 1.8, (orders, errs)
    assert max(its) <= 6
