"""Channel flows: 2D Poiseuille flow and its 3D square-duct counterpart, steady.

2D: ``[0, 4] x [0, 1]``, parabolic inflow ``u = 4 U y (1 - y)``, no-slip walls, do-nothing outflow.
The exact solution is the same parabola with ``p = 8 mu U (4 - x)``; Q2 represents it exactly, so
the velocity error measures the solver tolerance. 3D: ``[0, 4] x [0, 1]^2`` with inflow
``u = 16 U y (1 - y) z (1 - z)``; mass conservation is checked through the flow rates.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..config import Section, param, tree
from ..fem.functions import sample_pressure, sample_velocity
from ..fem.quadrature import gauss_tensor
from ..flow import Dirichlet, DoNothing, NoSlip
from ..mesh import StructuredMesh
from ..solvers.settings import SteadySolverParams
from .base import Scene, SceneResult
from .builder import flow_problem, steady_result


@dataclass(frozen=True)
class ChannelFluid(Section):
    """Newtonian fluid."""

    density: float = param(1.0, "density rho", "kg/m^3", positive=True)
    viscosity: float = param(0.01, "dynamic viscosity mu", "Pa s", positive=True)


@dataclass(frozen=True)
class ChannelInflow(Section):
    """Inflow profile."""

    max_velocity: float = param(1.0, "centre-line inflow velocity U", "m/s", positive=True)


ChannelParams = tree("ChannelParams", "Parameters of ``channel-2d`` and ``channel-3d``.", fluid=ChannelFluid,
                     inflow=ChannelInflow, solver=SteadySolverParams)


class _Channel(Scene):
    """The channel's steady solve; subclasses give ``dim`` and :meth:`measure`."""

    Params = ChannelParams
    dim = 2
    default_level = 2

    def mesh(self, level: int) -> StructuredMesh:
        n = 2**level
        return StructuredMesh.box((4 * n,) + (n,) * (self.dim - 1), upper=(4.0,) + (1.0,) * (self.dim - 1))

    def profile(self, U: float):
        if self.dim == 2:
            return lambda x, t: np.stack([4 * U * x[:, 1] * (1 - x[:, 1]), 0 * x[:, 0]], axis=1)
        return lambda x, t: np.stack([16 * U * x[:, 1] * (1 - x[:, 1]) * x[:, 2] * (1 - x[:, 2]),
                                      0 * x[:, 0], 0 * x[:, 0]], axis=1)

    def run(self, params: ChannelParams, level: int, progress=None) -> SceneResult:
        mesh = self.mesh(level)
        bcs = {t: NoSlip() for t in mesh.tags}
        bcs["xmin"] = Dirichlet(self.profile(params.inflow.max_velocity))
        bcs["xmax"] = DoNothing()
        problem = flow_problem(mesh, params.fluid.viscosity, bcs, params.solver, density=params.fluid.density)
        x, report = problem.solve_steady()
        return steady_result(problem, self.measure(params, *problem.whole_flow(x)), report.iterations)

    def measure(self, params: ChannelParams, s, x: np.ndarray) -> dict:
        """The scene's quantities of the solved flow ``x (n_dofs,)`` on the whole mesh's FlowSpace
        ``s``."""
        raise NotImplementedError


class Channel2D(_Channel):
    name = "channel-2d"
    description = "Poiseuille flow in [0,4]x[0,1], parabolic inflow, do-nothing outflow (exact solution)"
    max_level = 6

    def measure(self, params: ChannelParams, s, x: np.ndarray) -> dict:
        u, p = x[:s.n_u].reshape(s.dim, s.n_v), x[s.n_u:]
        exact = self.profile(params.inflow.max_velocity)(s.V.coordinates, 0.0).T
        drop = sample_pressure(s, p, np.array([[0.0, 0.5], [4.0, 0.5]]))
        return {"max_velocity_error": float(np.max(np.abs(u - exact))),
                "pressure_drop": float(drop[0] - drop[1]),
                "pressure_drop_exact": 32.0 * params.fluid.viscosity * params.inflow.max_velocity}


class Channel3D(_Channel):
    name = "channel-3d"
    description = "duct flow in [0,4]x[0,1]^2, inflow 16U y(1-y)z(1-z), do-nothing outflow"
    max_level = 4
    dim = 3

    def measure(self, params: ChannelParams, s, x: np.ndarray) -> dict:
        u = x[:s.n_u]
        n = s.mesh.shape[1]
        pts, w = gauss_tensor(2, 4)
        # composite Gauss rule on the n x n face cells of x = const
        ij = np.indices((n, n)).reshape(2, -1).T
        yz = ((ij[:, None, :] + 0.5 * (pts[None, :, :] + 1.0)) / n).reshape(-1, 2)
        wts = np.tile(w, n * n) / (4.0 * n * n)

        def flux(x0):
            points = np.column_stack([np.full(len(yz), x0), yz])
            return float(wts @ sample_velocity(s, u, points)[:, 0])

        centre = sample_velocity(s, u, np.array([[4.0, 0.5, 0.5]]))[0, 0]
        return {"flow_rate_in": flux(0.0), "flow_rate_out": flux(4.0),
                "flow_rate_exact": 4.0 * params.inflow.max_velocity / 9.0,
                "centerline_velocity_out": float(centre)}
