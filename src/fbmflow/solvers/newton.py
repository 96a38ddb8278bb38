"""Newton's method with a backtracking line search and a work report (deal.II step-57 style)."""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

log = logging.getLogger(__name__)


class ConvergenceError(RuntimeError):
    """A nonlinear or linear solver did not converge; the message says how far it got."""


@dataclass(frozen=True)
class NewtonSettings:
    """Stopping rule: ``|F| <= max(atol, rtol |F_0|)`` or ``|dx| <= step_tol |x|`` (2-norms).

    ``reuse_jacobian``: let the linear step keep an earlier factorised Jacobian (chord / modified
    Newton) while it contracts the residual at least ``reuse_contraction`` times per iteration, or
    while finishing with it is cheaper than a new factorisation: at the observed contraction
    ``rho`` it needs ``log(target / |F|) / log(rho)`` more iterations, each costing what the last
    one did without its set-up, against the factorisation's set-up time (``factor_time_s`` of the
    linear report; without it, a fresh one whenever the contraction is weaker), and as long as
    those iterations fit into ``max_iterations``. A fresh
    Jacobian is built always after a failed line search. The solution and the stopping rule are
    the same; only the work changes. Pays off in time stepping, where the mass term dominates and
    the Jacobian changes little from step to step, and most in 3D, where a factorisation costs
    tens of solves (ten-cate level 0, five warm-started steps: 5 factorisations and 41-46 s
    against 10 and 63-65 s with the contraction test alone).
    """

    rtol: float = 1e-10
    atol: float = 1e-12
    step_tol: float = 1e-12
    max_iterations: int = 30
    max_backtracks: int = 8
    reuse_jacobian: bool = False
    reuse_contraction: float = 10.0


@dataclass
class NewtonReport:
    """What one Newton solve did."""

    converged: bool = False
    iterations: int = 0
    residuals: list[float] = field(default_factory=list)
    line_search_steps: int = 0
    linear_iterations: int = 0
    linear_time_s: float = 0.0


def solve_newton(residual: Callable[[np.ndarray], np.ndarray],
                 linear_step: Callable[[np.ndarray, np.ndarray, bool], tuple[np.ndarray, object]],
                 x0: np.ndarray, settings: NewtonSettings = NewtonSettings(), scale: float | None = None):
    """Solve ``F(x) = 0``.

    Parameters
    ----------
    residual : x -> F(x), both (n,) float64
    linear_step : (x, F, fresh) -> (dx, LinearReport) solving ``J dx = -F``; with ``fresh`` False
        it may use an earlier Jacobian (``settings.reuse_jacobian``)
    x0 : (n,) float64, first iterate (constraints already applied)
    scale : float, optional
        Residual norm the relative tolerance refers to (default ``|F(x0)|``). A warm start close
        to the solution passes the cold start's residual, so that it stops at the same accuracy
        instead of reducing its own, smaller residual ``1 / rtol`` times.

    Returns
    -------
    x : (n,) float64
    report : NewtonReport

    Raises
    ------
    ConvergenceError
        when the iteration count is exhausted or a residual is not finite.
    """
    x = x0.copy()
    report = NewtonReport()
    F = residual(x)
    norm = float(np.linalg.norm(F))
    report.residuals.append(norm)
    target = max(settings.atol, settings.rtol * (norm if scale is None else scale))
    fresh = not settings.reuse_jacobian
    while norm > target:
        start = time.perf_counter()
        if report.iterations >= settings.max_iterations or not np.isfinite(norm):
            raise ConvergenceError(
                f"Newton did not converge: residual {norm:.3e} after {report.iterations} iterations "
                f"(started at {report.residuals[0]:.3e}, target {target:.3e})")
        dx, lin = linear_step(x, F, fresh)
        report.linear_iterations += lin.iterations
        report.linear_time_s += lin.wall_time_s
        if np.linalg.norm(dx) <= settings.step_tol * max(np.linalg.norm(x), 1.0):
            x = x + dx  # update below round-off: converged as far as arithmetic allows
            break
        step = 1.0
        for _ in range(settings.max_backtracks + 1):
            x_new = x + step * dx
            F_new = residual(x_new)
            norm_new = float(np.linalg.norm(F_new))
            if np.isfinite(norm_new) and norm_new <= (1.0 - 1e-4 * step) * norm:
                break
            step *= 0.5
            report.line_search_steps += 1
        else:
            if not fresh:  # an old Jacobian misled the search: retry with a fresh one
                fresh = True
                continue
            raise ConvergenceError(
                f"Newton line search failed at iteration {report.iterations + 1}: residual "
                f"{norm:.3e} did not decrease (target {target:.3e})")
        iteration_s = time.perf_counter() - start - lin.setup_time_s
        fresh = not settings.reuse_jacobian or _refactor(
            norm, norm_new, target, lin.factor_time_s, iteration_s, settings.reuse_contraction,
            settings.max_iterations - report.iterations - 1)
        x, F, norm = x_new, F_new, norm_new
        report.iterations += 1
        report.residuals.append(norm)
        log.debug("newton %d: |F| = %.3e (step %.3g)", report.iterations, norm, step)
    report.converged = True
    return x, report


def _refactor(norm: float, norm_new: float, target: float, setup_s: float, iteration_s: float,
              contraction: float, iterations_left: int) -> bool:
    """Whether the next Newton step should get a fresh Jacobian (see :class:`NewtonSettings`):
    the old one contracts less than ``contraction`` times per step and finishing with it would
    cost more than a factorisation (``setup_s``) or more steps than are left."""
    if norm_new * contraction <= norm:
        return False
    rho = norm_new / norm
    if rho >= 1.0 or norm_new <= target:
        return rho >= 1.0
    remaining = np.log(target / norm_new) / np.log(rho)
    return remaining * iteration_s >= setup_s or remaining >= iterations_left
