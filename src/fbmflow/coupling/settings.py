"""The coupling settings: the scheme and particle integrator
(:class:`~fbmflow.coupling.settings.CouplingParams`) and the fictitious boundary with its force
estimator (:class:`~fbmflow.coupling.settings.FictitiousBoundaryParams`)."""
from __future__ import annotations

import dataclasses

from ..config import Section, param
from .estimators import FORCE_ESTIMATORS
from .schemes import COUPLINGS

_INTEGRATORS = ("semi-implicit-euler", "trapezoidal")  # the integrators that couple with a flow
_INTEGRATOR_DOC = ("particle integrator: semi-implicit-euler (first order) or trapezoidal (second order with "
                   "time.scheme = crank-nicolson; not with hard contact)")


@dataclasses.dataclass(frozen=True)
class CouplingParams(Section):
    """Fluid–particle coupling: the scheme (:data:`fbmflow.coupling.schemes.COUPLINGS`) and the particle
    integrator."""

    scheme: str = param("implicit", "coupling: explicit (staggered), stabilised (explicit with each "
                        "particle's own stiffness implicit), newton-krylov (one Newton step on the particle "
                        "velocities, matrix-free), implicit (sub-iterated) or auto (implicit "
                        "while its stored flow responses fit 4 GB, else stabilised)",
                        choices=tuple(COUPLINGS) + ("auto",))
    tol: float = param(1e-6, "implicit coupling: estimated error of the particle velocities, relative",
                       positive=True, maximum=0.1)
    max_subiterations: int = param(20, "implicit coupling: sub-iteration limit per step (newton-krylov: "
                                   "FGMRES iteration limit)", minimum=1)
    first_rtol: float = param(1e-2, "implicit coupling: Newton's residual reduction in each step's first "
                              "flow solve, which only seeds the iteration (the step ends on a solve to "
                              "solver.newton_rtol; a value at or below that solves the first one alike)",
                              positive=True, maximum=0.5)
    flow_rtol: float = param(0.0, "explicit, stabilised and newton-krylov coupling: Newton's residual "
                             "reduction in the step's one flow solve, its linear steps asked for no more "
                             "than that (0, or a value at or below solver.newton_rtol: solver.newton_rtol)",
                             minimum=0.0, maximum=0.5)
    integrator: str = param("semi-implicit-euler", _INTEGRATOR_DOC, choices=_INTEGRATORS)
    krylov_rtol: float = param(1e-2, "newton-krylov coupling: FGMRES's residual reduction on the particles' "
                               "Newton equation (each iteration one linear solve; max_subiterations caps "
                               "them)", positive=True, maximum=0.5)
    added_mass: float = param(1.0, "stabilised and newton-krylov coupling: the added mass in each "
                              "particle's own stiffness (newton-krylov: its preconditioner), as a "
                              "multiple of a ball's potential-flow value (rho_f V for a disk, "
                              "rho_f V / 2 for a sphere); larger damps more, the steady state stays",
                              minimum=0.0)


@dataclasses.dataclass(frozen=True)
class SecondOrderCouplingParams(CouplingParams):
    """Fluid–particle coupling, second order in time with ``time.scheme = "crank-nicolson"``."""

    integrator: str = param("trapezoidal", _INTEGRATOR_DOC, choices=_INTEGRATORS)


_BOUNDARY_DOC = ("nodes: every velocity node inside a particle moves rigidly (first order in the mesh size); "
                 "sharp: the no-slip condition on the true surface (balls, boxes and cylinders)")


@dataclasses.dataclass(frozen=True)
class FictitiousBoundaryParams(Section):
    """How particles and obstacles meet the mesh (docs/method.md, "Particles as fictitious
    boundaries"), and the force estimator (:data:`fbmflow.coupling.estimators.FORCE_ESTIMATORS`)."""

    boundary: str = param("sharp", _BOUNDARY_DOC, choices=("nodes", "sharp"))
    force: str = param("auto", "hydrodynamic force: auto (surface for balls with the sharp boundary in 3D, "
                       "volume otherwise: the most accurate measured, coupling.estimators.auto_force) or "
                       "volume (-int sigma . grad alpha over the cut cells; "
                       "first order with the sharp boundary) or test-function (the momentum balance "
                       "tested with a function that is one on the particle, its gradient in the fluid "
                       "cells beyond the cut ones) or surface (the traction integrated over the true "
                       "surface; balls with the sharp boundary)", choices=(*FORCE_ESTIMATORS, "auto"))


@dataclasses.dataclass(frozen=True)
class NodalBoundaryParams(FictitiousBoundaryParams):
    """How particles and obstacles meet the mesh; the nodal boundary by default, in the scenes
    where the sharp one is not yet the better choice (many particles in contact; fixed obstacles,
    whose drag from the cut cells converges only to first order with it, docs/method.md)."""

    boundary: str = param("nodes", _BOUNDARY_DOC, choices=("nodes", "sharp"))
