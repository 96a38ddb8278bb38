"""DFG benchmark 2D-1 (Schäfer & Turek 1996): steady flow around a cylinder at Re = 20, the
cylinder a fixed fictitious boundary on the structured channel mesh.

Channel ``[0, 2.2] x [0, 0.41]``, cylinder of diameter 0.1 centred at (0.2, 0.2), parabolic inflow
``u = 4 U y (H - y) / H^2`` with ``U = 0.3`` (mean 0.2), ``rho = 1``, ``mu = 1e-3``, no-slip walls,
do-nothing outflow. Level ``L`` has ``22 2^L x 4 2^L`` cells, about ``2^L`` cells across the
diameter. Reference values: C_D = 5.57953523384, C_L = 0.010618948146, dp = 0.11752016697.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..coupling import hydrodynamic_forces, node_owner, rigid_body_constraints
from ..fem import FlowSpace
from ..fem.functions import sample_pressure
from ..flow import Dirichlet, DoNothing, NavierStokesProblem, NoSlip
from ..mesh import StructuredMesh
from ..params import SolverParams, param, section
from ..particles import Ball
from .base import Scene, SceneResult

REFERENCE = {"drag_coefficient": 5.57953523384, "lift_coefficient": 0.010618948146,
             "pressure_difference": 0.11752016697}
H, LENGTH, D, CENTRE = 0.41, 2.2, 0.1, np.array([0.2, 0.2])
DIRECT_LIMIT = 400_000  # unknowns up to which solver.linear = "auto" uses the direct solver here


@dataclass(frozen=True)
class DFGFluid:
    """Fluid of the DFG benchmark."""

    density: float = param(1.0, "density rho", "kg/m^3", positive=True)
    viscosity: float = param(1e-3, "dynamic viscosity mu", "Pa s", positive=True)
    max_inflow: float = param(0.3, "centre-line inflow velocity U (mean 2U/3)", "m/s", positive=True)


@dataclass(frozen=True)
class DFGParams:
    """Parameters of ``dfg-2d-1``."""

    fluid: DFGFluid = section(DFGFluid)
    solver: SolverParams = section(SolverParams)


class DFG2D1(Scene):
    name = "dfg-2d-1"
    description = "DFG 2D-1: steady flow around a fixed fictitious-boundary cylinder, Re = 20 (drag, lift)"
    Params = DFGParams
    default_level = 4
    max_level = 6

    @staticmethod
    def mesh(level: int) -> StructuredMesh:
        n = 2**level
        return StructuredMesh.box((22 * n, 4 * n), upper=(LENGTH, H))

    def run(self, params: DFGParams, level: int, progress=None) -> SceneResult:
        f = params.fluid
        mesh = self.mesh(level)
        cylinder = Ball(D / 2, 2)
        centres = CENTRE[None, :]

        def obstacle(V, t):
            owner = node_owner(V, centres, [cylinder])
            return rigid_body_constraints(V, owner, centres, np.zeros((1, 2)), np.zeros(1))

        U = f.max_inflow
        bcs = {"xmin": Dirichlet(lambda x, t: np.column_stack([4 * U * x[:, 1] * (H - x[:, 1]) / H**2, 0 * x[:, 0]])),
               "xmax": DoNothing(), "ymin": NoSlip(), "ymax": NoSlip()}
        linear = params.solver.linear_solver()
        if linear == "auto":
            # multigrid does not yet handle fictitious boundaries efficiently (65 s against 10 s
            # for the direct solver at level 3): direct while it fits, multigrid beyond
            linear = "direct" if FlowSpace.estimate_dofs(mesh) <= DIRECT_LIMIT else "multigrid"
        problem = NavierStokesProblem(mesh, f.viscosity, bcs, density=f.density, linear_solver=linear,
                                      newton=params.solver.newton_settings(), extra_constraints=obstacle,
                                      coarse_cells=self.mesh(min(level, 2)).n_cells)
        # multigrid: the coarsest level still resolves the cylinder (4 cells across the diameter);
        # coarser levels see no obstacle worth the name and spoil the coarse-grid correction
        x, report = problem.solve_steady()
        space = problem.space
        u, p = x[:space.n_u], x[space.n_u:]
        owner = node_owner(space.V, centres, [cylinder])
        force, _ = hydrodynamic_forces(space, owner, centres, u, p, f.viscosity)
        mean = 2.0 * U / 3.0
        scale = 2.0 / (f.density * mean**2 * D)
        # front and back points of the cylinder; the cell behind a surface point is partly inside
        # the particle, so the pressure is extrapolated from the fluid cell one cell further out
        h = mesh.spacing[0]
        front_back = np.array([[CENTRE[0] - D / 2, CENTRE[1]], [CENTRE[0] + D / 2, CENTRE[1]]])
        outward = front_back + np.array([[-1.5 * h, 0.0], [1.5 * h, 0.0]])
        dp = sample_pressure(space, p, front_back, cells_at=outward)
        q = {"drag_coefficient": float(scale * force[0, 0]), "lift_coefficient": float(scale * force[0, 1]),
             "pressure_difference": float(dp[0] - dp[1]),
             "cells_per_diameter": float(D / mesh.spacing.max())}
        for key, ref in REFERENCE.items():
            q[f"{key}_error"] = abs(q[key] - ref) / abs(ref)
        return SceneResult(q, mesh.n_cells, problem.n_dofs, newton_iterations=report.iterations)
