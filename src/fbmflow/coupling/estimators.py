"""Force estimators: strategies that turn a solved flow into the hydrodynamic force and torque on
every particle, registered by name in :data:`~fbmflow.coupling.estimators.FORCE_ESTIMATORS` (the
parameter ``fbm.force``).

An estimator has

* ``name`` and ``lags_pressure``: whether the pressure's part may be taken on the particles moved
  back to where the step's pressure belongs (the simulation then evaluates the velocity's and the
  pressure's parts separately, each with a rule for its own positions);
* ``check(shapes, sharp)``: ValueError with a remedy when it cannot serve these shapes with this
  fictitious boundary (``sharp``: the sharp boundary is on);
* ``prepare(space, centres, shapes, rotations, owner, walls, cells, spacing)``: the rule for particles at
  ``centres (n, dim)`` with rotations ``(n, dim, dim)``; ``owner (n_v,)`` int64 is their node
  owner where known (None: computed), ``walls`` the velocity nodes held by the walls, ``cells``
  a mask ``(n_cells,)`` of the cells whose part of the integral the rule takes (one process's
  owned cells, its part of a sum over processes; None: all), ``spacing`` the whole mesh's
  finest cell length where ``space``'s mesh is a process's slab (None: its own; for a rule
  whose points follow the resolution);
* ``evaluate(rule, u, p, mu, rho, u_old, dt, about)``: force ``(n, dim)`` and torque ``(n, 3)``
  of the flow ``u (dim * n_v,)``, ``p (n_p,)``; ``u_old`` is the velocity at the step's start
  and ``about`` the flow a response ``u`` is a change of (the estimators linear in the flow ignore
  both). An estimator that lags the pressure gets None for ``u`` or ``p`` when the simulation
  takes the other part only;
* ``evaluate_many(rule, U, P, mu, rho, dt, about)``: force ``(k, n, dim)`` and torque
  ``(k, n, 3)`` of ``k`` responses ``U (k, dim * n_v)``, ``P (k, n_p)`` about the flow ``about``
  (the implicit coupling's lifting responses; None for ``U`` or ``P``: that part left out). The
  estimators linear in the flow evaluate all of them in one pass over their
  :class:`~fbmflow.coupling.forces.ForceFunctional`; the base class's default evaluates them one
  by one;
* ``own_response(rule, W, free, mu, rho, dt, about)``: each particle's force and torque on its
  own unit rigid motions ``W (n_u, k)`` with the rest of the flow held, about the flow ``about``:
  ``(n, r, r)`` (:meth:`~fbmflow.coupling.forces.ForceFunctional.own_response`; what the
  stabilised explicit coupling takes as each particle's stiffness).
"""
from __future__ import annotations

import numpy as np

from ..fem.space import FlowSpace
from .forces import SurfaceForces, TestFunctionForces, supports_surface_force, volume_force_functional
from .indicator import node_owner


class ForceEstimator:
    """Base of the estimators: any shape, either boundary, the pressure's part lagged; the rule's
    node owner computed where not given."""

    name = ""
    lags_pressure = True

    def check(self, shapes: list, sharp: bool) -> None:
        return None

    def evaluate_many(self, rule, U, P, mu, rho, dt=None, about=None):
        """Force (k, n, dim) and torque (k, n, 3) of the responses ``U (k, n_u)``, ``P (k, n_p)``
        about the flow ``about``, one response at a time (the estimators linear in the flow
        override this with one pass over all of them)."""
        k = (U if U is not None else P).shape[0]
        out = [self.evaluate(rule, None if U is None else U[i], None if P is None else P[i], mu, rho, dt=dt,
                             about=about) for i in range(k)]
        return np.stack([f for f, _ in out]), np.stack([t for _, t in out])

    def own_response(self, rule, W, free, mu, rho, dt=None, about=None):
        """Each particle's force and torque on its own unit rigid motions, (n, r, r): the rule's
        :meth:`~fbmflow.coupling.forces.ForceFunctional.own_response` (the estimators whose
        rule is not linear in the flow override this)."""
        return rule.own_response(W, free, mu)

    @staticmethod
    def _owner(space: FlowSpace, centres: np.ndarray, shapes: list, rotations: np.ndarray,
               owner: np.ndarray | None) -> np.ndarray:
        return node_owner(space.V, centres, shapes, rotations) if owner is None else owner


class VolumeForce(ForceEstimator):
    """``F_i = -int sigma · grad alpha_i`` over the cells the particle cuts
    (:func:`~fbmflow.coupling.forces.hydrodynamic_forces`); any shape, either boundary. The rule is a
    :class:`~fbmflow.coupling.forces.ForceFunctional` of all particles."""

    name = "volume"

    def prepare(self, space: FlowSpace, centres: np.ndarray, shapes: list, rotations: np.ndarray,
                owner: np.ndarray | None = None, walls: np.ndarray | None = None,
                cells: np.ndarray | None = None, spacing: float | None = None):
        owner = self._owner(space, centres, shapes, rotations, owner)
        return volume_force_functional(space, owner, centres, cells)

    def evaluate(self, rule, u, p, mu, rho, u_old=None, dt=None, about=None):
        return rule(u, p, mu)

    def evaluate_many(self, rule, U, P, mu, rho, dt=None, about=None):
        return rule.many(U, P, mu)


class TestFunctionForce(ForceEstimator):
    """The momentum balance tested with a function that is one on the particle
    (:class:`~fbmflow.coupling.forces.TestFunctionForces`); ``du/dt`` is the step's mean acceleration
    ``(u - u_old) / dt``. Any shape, either boundary; the pressure is taken where the particle is.
    Responses about a flow are evaluated together through the linearisation there
    (:meth:`~fbmflow.coupling.forces.TestFunctionForces.linearised`)."""

    __test__ = False  # not a pytest class
    name = "test-function"
    lags_pressure = False

    def prepare(self, space: FlowSpace, centres: np.ndarray, shapes: list, rotations: np.ndarray,
                owner: np.ndarray | None = None, walls: np.ndarray | None = None,
                cells: np.ndarray | None = None, spacing: float | None = None):
        owner = self._owner(space, centres, shapes, rotations, owner)
        return TestFunctionForces(space, owner, centres, shapes, rotations, walls, cells=cells)

    def evaluate(self, rule, u, p, mu, rho, u_old=None, dt=None, about=None):
        return rule(u, p, mu, rho, u_old=u_old, dt=dt, about=about)

    def evaluate_many(self, rule, U, P, mu, rho, dt=None, about=None):
        if about is None or U is None or P is None:
            return super().evaluate_many(rule, U, P, mu, rho, dt=dt, about=about)
        return rule.linearised(about, mu, rho, dt).many(U, P, 1.0)

    def own_response(self, rule, W, free, mu, rho, dt=None, about=None):
        return rule.linearised(about, mu, rho, dt).own_response(W, free, 1.0)


class SurfaceForce(ForceEstimator):
    """The traction integrated over the true surface (:class:`~fbmflow.coupling.forces.SurfaceForces`);
    balls with the sharp boundary only (the nodal boundary's cut cells carry no flow up to the
    surface)."""

    name = "surface"

    def check(self, shapes: list, sharp: bool) -> None:
        if not (sharp and supports_surface_force(shapes)):
            raise ValueError("force 'surface' integrates the traction over the true surface of balls with "
                             "the sharp boundary (the nodal boundary's cut cells carry no flow up to the "
                             "surface); use fbm.boundary = 'sharp' with balls, or fbm.force = 'volume'")

    def prepare(self, space: FlowSpace, centres: np.ndarray, shapes: list, rotations: np.ndarray,
                owner: np.ndarray | None = None, walls: np.ndarray | None = None,
                cells: np.ndarray | None = None, spacing: float | None = None):
        return SurfaceForces(space, centres, shapes, cells=cells, spacing=spacing)

    def evaluate(self, rule, u, p, mu, rho, u_old=None, dt=None, about=None):
        return rule(u, p, mu)

    def evaluate_many(self, rule, U, P, mu, rho, dt=None, about=None):
        return rule.many(U, P, mu)


#: force estimators by name (the parameter ``fbm.force``)
FORCE_ESTIMATORS = {cls.name: cls for cls in (VolumeForce, TestFunctionForce, SurfaceForce)}


def auto_force(shapes: list, sharp: bool, dim: int) -> str:
    """The estimator ``fbm.force = "auto"`` takes: ``surface`` for balls with the sharp boundary in
    3D, where it reads the sphere array's drag -0.56 / +0.53 / +0.30 % at 6 / 8 / 12 cells per
    diameter against the volume force's +3.22 / +2.99 / +1.86 % (benchmarks/results/sphere_array.md);
    ``volume`` otherwise (the only one for the nodal boundary and any shape; in 2D the choice has
    not been measured to differ)."""
    return "surface" if dim == 3 and sharp and supports_surface_force(shapes) else "volume"


def make_force_estimator(name: str):
    """The registered estimator ``name``; ValueError listing the names otherwise."""
    try:
        return FORCE_ESTIMATORS[name]()
    except KeyError:
        raise ValueError(f"unknown hydrodynamic force {name!r}; choose one of "
                         f"{sorted(FORCE_ESTIMATORS)}") from None
