"""A small sharp-boundary problem the solver tests share."""
import numpy as np


def sharp_disk_problem(mesh, centre, radius, linear_solver=None):
    """A backward-Euler problem (dt 0.01, no-slip walls) on the 2D ``mesh`` with a sharp-boundary
    disk of ``radius`` at ``centre`` moving down at 1, and its constraints; ``linear_solver``: the
    problem's (default: its own choice)."""
    from fbmflow.coupling import node_owner, rigid_body_constraints, sharp_boundary
    from fbmflow.flow import NavierStokesProblem, NoSlip
    from fbmflow.particles import Ball
    centre, shapes = np.array([centre]), [Ball(radius, 2)]
    vel, ang = np.array([[0.0, -1.0]]), np.zeros(1)

    def ball(V, t):
        owner = node_owner(V, centre, shapes)
        rigid = rigid_body_constraints(V, owner, centre, vel, ang)
        if V is not prob.space.V:  # a coarser multigrid level: the nodes' constraints only
            return rigid
        return sharp_boundary(prob.space, owner, centre, shapes).constraints(rigid, vel, ang)

    prob = NavierStokesProblem(mesh, 0.01, {t: NoSlip() for t in mesh.tags}, extra_constraints=ball,
                              linear_solver=linear_solver)
    return prob, prob.constraints()
