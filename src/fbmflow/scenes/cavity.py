"""Lid-driven cavity: the unit square with the lid ``y = 1`` moving at speed 1, steady.

The corners of the lid belong to the resting walls (no-slip wins), i.e. the non-leaky cavity.
Above Re = 100 the steady state is reached by continuation in Re (doubling from 100), each Newton
solve starting from the previous solution; the intermediate ones only to
``solver.continuation_rtol``.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..config import Section, param, tree
from ..fem.functions import sample_velocity
from ..flow import Dirichlet, NoSlip
from ..mesh import StructuredMesh
from ..solvers.settings import SteadySolverParams
from .base import Scene, SceneResult, pyplot, save_figure
from .builder import flow_problem, steady_result
from .data import ghia1982


def recirculating_state(problem) -> np.ndarray:
    """A recirculating velocity ``(sin^2 pi x sin 2 pi y, -sin 2 pi x sin^2 pi y)`` (third
    component zero in 3D) with the problem's boundary values: x (n_dofs,) float64. The state at
    which the solver tests and benchmarks linearise the cavity's Oseen/Newton systems."""
    x = problem.zero_state()
    X = problem.space.V.coordinates
    u, _ = problem.split(x)
    u[0] = np.sin(np.pi * X[:, 0]) ** 2 * np.sin(2 * np.pi * X[:, 1])
    u[1] = -np.sin(2 * np.pi * X[:, 0]) * np.sin(np.pi * X[:, 1]) ** 2
    problem.constraints().apply_to_vector(x)
    return x


@dataclass(frozen=True)
class CavityFluid(Section):
    """Fluid of the cavity (density 1, lid speed 1, side 1, so viscosity = 1 / re)."""

    re: float = param(100.0, "Reynolds number U L / nu", positive=True, maximum=5000.0)


CavityParams = tree("CavityParams", "Parameters of ``cavity-2d``.", fluid=CavityFluid,
                    solver=SteadySolverParams)


class Cavity2D(Scene):
    name = "cavity-2d"
    description = "lid-driven unit square, steady Navier-Stokes (Ghia et al. 1982 centrelines)"
    Params = CavityParams
    default_level = 3  # 64 x 64 cells: Q2 nodes coincide with the 129 sample points
    max_level = 6

    @staticmethod
    def mesh(level: int) -> StructuredMesh:
        n = 8 * 2**level
        return StructuredMesh.box((n, n))

    def run(self, params: CavityParams, level: int, progress=None) -> SceneResult:
        mesh = self.mesh(level)
        bcs = {"xmin": NoSlip(), "xmax": NoSlip(), "ymin": NoSlip(), "ymax": Dirichlet((1.0, 0.0))}
        re_path = [params.fluid.re]
        while re_path[0] > 100.0:
            re_path.insert(0, max(100.0, re_path[0] / 2))
        problem = flow_problem(mesh, 1.0 / re_path[0], bcs, params.solver)
        x, newton_its = None, 0
        final = problem.newton
        for k, re in enumerate(re_path):
            problem.mu = 1.0 / re
            last = k == len(re_path) - 1
            loose = dataclasses.replace(final, rtol=params.solver.continuation_rtol)
            problem.newton = final if last else loose
            x, report = problem.solve_steady(x)
            newton_its += report.iterations
            if progress and len(re_path) > 1:
                progress(k + 1, len(re_path), None)
        s = np.linspace(0.0, 1.0, 129)
        space, x = problem.whole_flow(x)
        u_vert = sample_velocity(space, x[:space.n_u], np.stack([np.full_like(s, 0.5), s], axis=1))[:, 0]
        v_horiz = sample_velocity(space, x[:space.n_u], np.stack([s, np.full_like(s, 0.5)], axis=1))[:, 1]
        q = {"u_vertical_centerline": u_vert.tolist(), "v_horizontal_centerline": v_horiz.tolist(),
             "y_samples": s.tolist()}
        re_int = int(round(params.fluid.re))
        if re_int in ghia1982.U and abs(params.fluid.re - re_int) < 1e-12:
            u_error = np.interp(ghia1982.Y, s, u_vert) - ghia1982.U[re_int]
            v_error = np.interp(ghia1982.X, s, v_horiz) - ghia1982.V[re_int]
            q["ghia_max_deviation_u"] = float(np.max(np.abs(u_error)))
            q["ghia_max_deviation_v"] = float(np.max(np.abs(v_error)))
        return steady_result(problem, q, newton_its)

    def plot(self, summary: dict, path) -> bool:
        plt = pyplot()

        q = summary["quantities"]
        s = np.array(q["y_samples"])
        re = summary["params"]["fluid"]["re"]
        fig, ax = plt.subplots(1, 2, figsize=(10, 4.5))
        ax[0].plot(q["u_vertical_centerline"], s, label="fbmflow")
        ax[0].set_xlabel("u(0.5, y)")
        ax[0].set_ylabel("y")
        ax[1].plot(s, q["v_horizontal_centerline"], label="fbmflow")
        ax[1].set_xlabel("x")
        ax[1].set_ylabel("v(x, 0.5)")
        re_int = int(round(re))
        if re_int in ghia1982.U and abs(re - re_int) < 1e-12:
            ax[0].plot(ghia1982.U[re_int], ghia1982.Y, "o", mfc="none", label="Ghia et al. 1982")
            ax[1].plot(ghia1982.X, ghia1982.V[re_int], "o", mfc="none", label="Ghia et al. 1982")
        for a in ax:
            a.grid(alpha=0.3)
            a.legend()
        fig.suptitle(f"cavity-2d, Re = {re:g}, level {summary['level']} ({summary['n_cells']} cells)")
        return save_figure(fig, path)
