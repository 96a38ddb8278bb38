"""Decaying Taylor–Green vortex on the periodic unit square (exact Navier–Stokes solution).

    u = ( sin 2 pi x cos 2 pi y, -cos 2 pi x sin 2 pi y) exp(-8 pi^2 nu t),
    p = rho/4 (cos 4 pi x + cos 4 pi y) exp(-16 pi^2 nu t).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..config import ParamError, Section, derive, param, tree
from ..fem.functions import error_norms
from ..flow.time_schemes import advance
from ..mesh import StructuredMesh
from ..params import TimeParams
from ..solvers import ConvergenceError
from ..solvers.settings import SolverParams
from .base import Scene, SceneResult, pyplot, save_figure
from .builder import flow_problem, steady_result

TWO_PI = 2.0 * np.pi


def taylor_green_velocity(x: np.ndarray, t: float, nu: float) -> np.ndarray:
    """Exact velocity at points ``x (n, 2)`` -> (n, 2)."""
    decay = np.exp(-2.0 * TWO_PI**2 * nu * t)
    sx, cx = np.sin(TWO_PI * x[:, 0]), np.cos(TWO_PI * x[:, 0])
    sy, cy = np.sin(TWO_PI * x[:, 1]), np.cos(TWO_PI * x[:, 1])
    return decay * np.stack([sx * cy, -cx * sy], axis=1)


def taylor_green_gradient(x: np.ndarray, t: float, nu: float) -> np.ndarray:
    """Exact ``du_i/dx_k`` at ``x (n, 2)`` -> (n, 2, 2)."""
    decay = np.exp(-2.0 * TWO_PI**2 * nu * t)
    sx, cx = np.sin(TWO_PI * x[:, 0]), np.cos(TWO_PI * x[:, 0])
    sy, cy = np.sin(TWO_PI * x[:, 1]), np.cos(TWO_PI * x[:, 1])
    g = np.empty((x.shape[0], 2, 2))
    g[:, 0, 0], g[:, 0, 1] = cx * cy, -sx * sy
    g[:, 1, 0], g[:, 1, 1] = sx * sy, -cx * cy
    return TWO_PI * decay * g


@dataclass(frozen=True)
class TaylorGreenFluid(Section):
    """Fluid (density 1)."""

    viscosity: float = param(0.01, "kinematic viscosity nu", "m^2/s", positive=True)


TaylorGreenTime = derive(TimeParams, "TaylorGreenTime", "Time stepping of the vortex.", dt=0.025, t_end=0.5)


def _no_adaptive(params) -> None:
    if params.time.adaptive:
        raise ParamError("taylor-green-2d: time.adaptive chooses steps by the particles' motion and this "
                         "scene has no particles; set time.adaptive = false and choose time.dt")


TaylorGreenParams = tree("TaylorGreenParams", "Parameters of ``taylor-green-2d``.", validate=_no_adaptive,
                         fluid=TaylorGreenFluid, time=TaylorGreenTime, solver=SolverParams)


class TaylorGreen2D(Scene):
    name = "taylor-green-2d"
    description = "decaying Taylor-Green vortex on the periodic unit square, unsteady (exact solution)"
    Params = TaylorGreenParams
    default_level = 2
    max_level = 6

    @staticmethod
    def mesh(level: int) -> StructuredMesh:
        n = 4 * 2**level
        return StructuredMesh.box((n, n), periodic=(True, True))

    @staticmethod
    def initial_state(problem, nu: float) -> np.ndarray:
        x = np.zeros(problem.n_dofs)
        u, _ = problem.split(x)
        u[:] = taylor_green_velocity(problem.space.V.coordinates, 0.0, nu).T
        return x

    def run(self, params: TaylorGreenParams, level: int, progress=None) -> SceneResult:
        nu = params.fluid.viscosity
        mesh = self.mesh(level)
        problem = flow_problem(mesh, nu, {}, params.solver)
        x = self.initial_state(problem, nu)
        n_steps = params.time.n_steps
        dt = params.time.t_end / n_steps
        s = problem.space

        def energy(x):
            u = x[:s.n_u]
            return 0.5 * problem.dot(u, problem.apply_mass(u))

        times, energies, newton_its, t = [0.0], [energy(x)], 0, 0.0
        for step in range(1, n_steps + 1):
            try:
                x, reports = advance(problem, x, t, dt, params.time.scheme)
            except ConvergenceError as err:
                raise err.with_remedy("reduce time.dt or refine the mesh (--level)",
                                      f"step {step} (t = {t:.6g} -> {t + dt:.6g}): ") from None
            t = step * dt
            newton_its += sum(r.iterations for r in reports)
            times.append(t)
            energies.append(energy(x))
            if progress:
                progress(step, n_steps, t)
        s, x = problem.whole_flow(x)
        u, p = x[:s.n_u], x[s.n_u:]
        err = error_norms(s, u, p, lambda y: taylor_green_velocity(y, t, nu),
                          lambda y: taylor_green_gradient(y, t, nu), lambda y: 0.0 * y[:, 0])
        exact_energy = 0.25 * np.exp(-4.0 * TWO_PI**2 * nu * np.array(times))
        q = {"velocity_l2_error": err["u_l2"], "kinetic_energy": energies, "t": times,
             "kinetic_energy_exact": exact_energy.tolist()}
        return steady_result(problem, q, newton_its, steps=n_steps)

    def plot(self, summary: dict, path) -> bool:
        plt = pyplot()

        q = summary["quantities"]
        fig, ax = plt.subplots(figsize=(6, 4.5))
        ax.semilogy(q["t"], q["kinetic_energy"], label="fbmflow")
        ax.semilogy(q["t"], q["kinetic_energy_exact"], "--", label="exact")
        ax.set_xlabel("t")
        ax.set_ylabel("kinetic energy")
        ax.grid(alpha=0.3)
        ax.legend()
        ax.set_title(f"taylor-green-2d, level {summary['level']}, {summary['params']['time']['scheme']}")
        return save_figure(fig, path)
