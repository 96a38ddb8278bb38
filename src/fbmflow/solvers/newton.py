"""Newton's method with a backtracking line search and a work report (deal.II step-57 style)."""
from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from .. import interrupt

log = logging.getLogger(__name__)


class ConvergenceError(RuntimeError):
    """A nonlinear or linear solver did not converge, or a run left the physically possible; the
    message says how far it got. ``remedy``: what to change, in the user's terms, where the
    raising code knows it (None: the caller that knows the context adds one, :meth:`with_remedy`).
    """

    #: whether a shorter time step may help: the adaptive step control retries only then
    #: (:class:`~fbmflow.adaptive.StepControl`)
    retry = True

    def __init__(self, message: str, remedy: str | None = None):
        super().__init__(message)
        self.remedy = remedy

    def with_remedy(self, remedy: str, prefix: str = "") -> "ConvergenceError":
        """The same error with ``prefix`` before its message and ``remedy`` where it had none."""
        return type(self)(f"{prefix}{self.args[0]}", self.remedy or remedy)


@dataclass(frozen=True)
class NewtonSettings:
    """Stopping rule: ``|F| <= max(atol, rtol |F_0|)`` or ``|dx| <= step_tol |x|`` (2-norms).

    ``reuse_jacobian``: let the linear step keep an earlier factorised Jacobian (chord / modified
    Newton) while it contracts the residual at least ``1 / reuse_contraction`` times per
    iteration; a fresh one is built otherwise, and always after a failed line search. The solution
    and the stopping rule are the same; only the work changes. Pays off in time stepping, where
    the mass term dominates and the Jacobian changes little from step to step.

    ``linear_rtol``: the relative residual asked of each linear step from a linear solver that
    takes one per solve (multigrid; the direct solver's PARDISO refinement; None: the solver's
    own target). A Newton (or chord) step needs no more than a small fraction of the residual it
    reduces; the stopping rule above, on the nonlinear residual, decides the accuracy of the
    solution. A step near the target is asked no more than to reach it: ``max(linear_rtol,
    target / (2 |F_k|))``, at most :data:`LAST_STEP_FORCING`.

    ``adaptive_linear_rtol``: Eisenstat and Walker's forcing terms (1996, choice 2) instead:
    ``eta_k = 0.9 (|F_k| / |F_(k-1)|)^2``, safeguarded by ``0.9 eta_(k-1)^2`` where that exceeds
    0.1, at most ``linear_rtol`` and at least half the final target over ``|F_k|`` and
    :data:`MIN_FORCING` (an iterative solver's attainable accuracy; ``linear_rtol`` where that is
    smaller): loose solves far from the solution, tight ones where Newton converges
    quadratically.
    """

    rtol: float = 1e-10
    atol: float = 1e-12
    step_tol: float = 1e-12
    max_iterations: int = 30
    max_backtracks: int = 8
    reuse_jacobian: bool = False
    reuse_contraction: float = 10.0
    linear_rtol: float | None = None
    adaptive_linear_rtol: bool = False


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
                 x0: np.ndarray, settings: NewtonSettings = NewtonSettings(), reference: float | None = None,
                 norm: Callable[[np.ndarray], float] | None = None):
    """Solve ``F(x) = 0``.

    Parameters
    ----------
    residual : x -> F(x), both (n,) float64
    linear_step : (x, F, fresh, rtol) -> (dx, LinearReport) solving ``J dx = -F``; with ``fresh``
        False it may use an earlier Jacobian (``settings.reuse_jacobian``); ``rtol``: the relative
        residual asked of the solve (None: ``settings.linear_rtol``, or the solver's own)
    x0 : (n,) float64, first iterate (constraints already applied)
    reference : float, optional
        The residual norm that ``settings.rtol`` is relative to (default ``|F(x0)|``): a caller
        that starts from a better guess passes the norm at its usual start, so that the stopping
        rule, and with it the accuracy, stays the same.
    norm : x -> float, optional, the norm of residuals and steps (default the Euclidean norm; one
        process's part of a distributed vector: the sum over the unknowns it owns,
        :meth:`fbmflow.parallel.blocks.BlockPartition.dot`)

    Returns
    -------
    x : (n,) float64
    report : NewtonReport

    Raises
    ------
    ConvergenceError
        when the iteration count is exhausted or a residual is not finite.
    StopRequested
        after an iteration, when a signal asked the run to stop and no run loop will stop it
        after its step instead (:mod:`fbmflow.interrupt`).
    """
    with interrupt.safe_point("iteration"):
        return _iterate(residual, linear_step, x0, settings, reference, norm or _euclidean)


def _euclidean(x: np.ndarray) -> float:
    return float(np.linalg.norm(x))


def _iterate(residual, linear_step, x0, settings, reference, size):
    """:func:`solve_newton`'s iteration (``size``: the norm)."""
    x = x0.copy()
    report = NewtonReport()
    F = residual(x)
    norm = size(F)
    report.residuals.append(norm)
    target = max(settings.atol, settings.rtol * (norm if reference is None else reference))
    fresh = not settings.reuse_jacobian
    eta = None  # the forcing term of the last step (adaptive_linear_rtol)
    while norm > target:
        interrupt.check()
        if report.iterations >= settings.max_iterations or not np.isfinite(norm):
            raise ConvergenceError(
                f"Newton did not converge: residual {norm:.3e} after {report.iterations} iterations "
                f"(started at {report.residuals[0]:.3e}, target {target:.3e})")
        if settings.adaptive_linear_rtol and settings.linear_rtol is not None:
            eta = _forcing_term(eta, report.residuals, settings.linear_rtol, target)
        elif settings.linear_rtol is not None:  # no tighter than the step to the target needs
            eta = min(max(settings.linear_rtol, 0.5 * target / norm), LAST_STEP_FORCING)
        dx, lin = linear_step(x, F, fresh, eta)
        report.linear_iterations += lin.iterations
        report.linear_time_s += lin.wall_time_s
        if size(dx) <= settings.step_tol * max(size(x), 1.0):
            x = x + dx  # update below round-off: converged as far as arithmetic allows
            break
        step = 1.0
        for _ in range(settings.max_backtracks + 1):
            x_new = x + step * dx
            F_new = residual(x_new)
            norm_new = size(F_new)
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
        fresh = not settings.reuse_jacobian or norm_new * settings.reuse_contraction > norm
        x, F, norm = x_new, F_new, norm_new
        report.iterations += 1
        report.residuals.append(norm)
        log.debug("newton %d: |F| = %.3e (step %.3g)", report.iterations, norm, step)
    report.converged = True
    return x, report


#: the loosest linear solve asked of a Newton step that is to reach the target on its own (the
#: residual it leaves is only the linear one where the Jacobian is exact)
LAST_STEP_FORCING = 0.1

#: the tightest linear solve the forcing terms ask for (multigrid stagnated near 3e-6 on dfg-3d-1z
#: level 3, measured; each Newton step then still reduces the residual 10^4-fold)
MIN_FORCING = 1e-4


def _forcing_term(eta: float | None, residuals: list[float], eta_max: float, target: float) -> float:
    """Eisenstat–Walker choice 2 (gamma 0.9, alpha 2) with its safeguards; ``residuals``: the
    nonlinear residual norms so far, the current one last."""
    if eta is None or len(residuals) < 2:
        new = eta_max
    else:
        new = 0.9 * (residuals[-1] / residuals[-2]) ** 2
        if 0.9 * eta**2 > 0.1:
            new = max(new, 0.9 * eta**2)
    return float(max(min(new, eta_max), 0.5 * target / residuals[-1], min(MIN_FORCING, eta_max)))
