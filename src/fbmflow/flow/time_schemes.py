"""Implicit one-step time schemes as sequences of theta-substeps (a registry, not an if-chain).

A substep of length ``k = fraction * dt`` from ``(u_old, t_old)`` to ``(u, t_new)`` solves

    rho M (u - u_old) / k + a [A(u) u - f(t_new)] + b [A(u_old) u_old - f(t_old)] + B p = 0,
    B^T u = 0,

with ``A(u) u = mu L u + rho N(u) u``; the pressure is implicit (a Lagrange multiplier) in every
substep. The schemes:

* ``backward-euler``: one substep, ``a = 1, b = 0``; first order, strongly A-stable.
* ``crank-nicolson``: one substep, ``a = b = 1/2``; second order, A-stable, weakly damped.
* ``fractional-step-theta`` (Glowinski; Turek's variant): three substeps of lengths
  ``theta, 1 - 2 theta, theta`` with ``theta = 1 - 1/sqrt(2)`` and weights ``(alpha, beta)``,
  ``(beta, alpha)``, ``(alpha, beta)``, ``alpha = (1 - 2 theta)/(1 - theta)``, ``beta = 1 - alpha``;
  second order and strongly A-stable.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Substep:
    """One theta-substep: its share of ``dt`` and the implicit/explicit weights."""

    fraction: float
    implicit: float
    explicit: float


_THETA = 1.0 - np.sqrt(0.5)
_ALPHA = (1.0 - 2.0 * _THETA) / (1.0 - _THETA)
_BETA = 1.0 - _ALPHA

#: the time schemes by name (the parameter ``time.scheme``): each a sequence of theta-substeps
TIME_SCHEMES: dict[str, tuple[Substep, ...]] = {
    "backward-euler": (Substep(1.0, 1.0, 0.0),),
    "crank-nicolson": (Substep(1.0, 0.5, 0.5),),
    "fractional-step-theta": (Substep(_THETA, _ALPHA, _BETA),
                              Substep(1.0 - 2.0 * _THETA, _BETA, _ALPHA),
                              Substep(_THETA, _ALPHA, _BETA)),
}


def pressure_lag(name: str) -> float:
    """Share of the step by which a moving fictitious boundary's pressure trails its velocity.

    The particles' constraints hold at the step's start positions, so a step's start velocity
    ``u_old`` was solved with the boundary one step further back. A single substep's pressure,
    a Lagrange multiplier of the whole substep, balances ``b A(u_old) + a A(u)`` and so belongs
    to the geometry ``b`` of a step behind the new velocity's: one half for Crank–Nicolson,
    none for backward Euler. The fractional-step theta scheme's last substep starts from a
    velocity solved with the step's own boundary: no lag to first order.
    """
    substeps = get_scheme(name)
    return substeps[0].explicit if len(substeps) == 1 else 0.0


def get_scheme(name: str) -> tuple[Substep, ...]:
    """The substeps of a registered scheme; ValueError naming the choices otherwise."""
    try:
        return TIME_SCHEMES[name]
    except KeyError:
        raise ValueError(f"unknown time scheme {name!r}; choose one of {sorted(TIME_SCHEMES)}") from None


def advance(problem, x: np.ndarray, t: float, dt: float, scheme: str, guess: np.ndarray | None = None,
            rtol: float | None = None, linear_rtol: float | None = None, extra=None):
    """One time step of ``problem`` (a NavierStokesProblem) from ``(x, t)`` over ``dt``.

    ``guess`` (n_dofs,): a prediction of the new state, where Newton starts (one-substep schemes
    only; ignored by the others, whose substeps end at other times). The stopping rule, and so
    the result up to it, does not depend on it. ``rtol``: Newton's residual reduction per substep
    (default the problem's); ``linear_rtol``: a looser target for its linear steps
    (:meth:`~fbmflow.flow.navier_stokes.NavierStokesProblem.solve`); ``extra``: the substeps' further
    constraints
    instead of the problem's own (:meth:`~fbmflow.flow.navier_stokes.NavierStokesProblem.constraints`).

    Returns
    -------
    x_new : (n_dofs,) float64
    reports : list of NewtonReport, one per substep
    """
    if not dt > 0:
        raise ValueError(f"time step must be positive, got {dt}")
    reports = []
    s = problem.space
    subs = get_scheme(scheme)
    for sub in subs:
        k = sub.fraction * dt
        t_new = t + k
        u_old = x[:s.n_u]
        rhs = (problem.rho / k) * problem.apply_mass(u_old)
        if sub.implicit:
            rhs += sub.implicit * problem.load(t_new)
        if sub.explicit:
            rhs += sub.explicit * (problem.load(t) - problem.apply_spatial(u_old))
        x, report = problem.solve(x, 1.0 / k, sub.implicit, rhs, t_new,
                                  guess=guess if len(subs) == 1 else None, rtol=rtol,
                                  linear_rtol=linear_rtol, extra=extra)
        reports.append(report)
        t = t_new
    return x, reports
