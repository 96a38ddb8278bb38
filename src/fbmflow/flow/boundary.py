"""Boundary conditions on the faces of a structured box mesh.

Each non-periodic face (``xmin``, ``xmax``, ...) gets exactly one condition:

* :class:`Dirichlet` - prescribed velocity, a constant vector or a callable ``g(x, t)`` with
  ``x (n, dim)`` returning ``(n, dim)``;
* :class:`NoSlip` - zero velocity;
* :class:`Slip` - free slip / symmetry plane: zero normal velocity, natural tangential stress;
* :class:`DoNothing` - natural outflow ``nu du/dn - p n = 0`` (gradient form of the viscous term).

Where faces meet, the stronger condition wins: slip is applied first, then Dirichlet, then
no-slip (so a wall's edge stays at rest next to an inflow or a moving lid). The pressure is fixed
by ``int p = 0`` unless some face is do-nothing.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..fem.constraints import DirichletConstraints
from ..fem.dofmap import DofMap
from ..mesh.structured import AXES


@dataclass(frozen=True)
class Dirichlet:
    """Prescribed velocity: a constant (dim,) vector or ``g(x (n, dim), t) -> (n, dim)``."""

    value: tuple[float, ...] | Callable


@dataclass(frozen=True)
class NoSlip:
    """Zero velocity on the face."""


@dataclass(frozen=True)
class Slip:
    """Free slip / symmetry plane: zero normal velocity."""


@dataclass(frozen=True)
class DoNothing:
    """Natural outflow boundary."""


BoundaryCondition = Dirichlet | NoSlip | Slip | DoNothing
_ORDER = {Slip: 0, Dirichlet: 1, NoSlip: 2}


def check_boundary(tags: tuple[str, ...], bcs: dict) -> None:
    """Raise ValueError unless ``bcs`` assigns one known condition to exactly the faces ``tags``."""
    missing = [t for t in tags if t not in bcs]
    extra = [t for t in bcs if t not in tags]
    if extra:
        raise ValueError(f"boundary conditions for unknown or periodic faces {extra}; faces are {list(tags)}")
    if missing:
        raise ValueError(f"no boundary condition for faces {missing}; give each of {list(tags)} one of "
                         "Dirichlet, NoSlip, Slip, DoNothing")
    for tag, bc in bcs.items():
        if not isinstance(bc, (Dirichlet, NoSlip, Slip, DoNothing)):
            raise ValueError(f"face {tag}: {bc!r} is not a boundary condition")


def pressure_is_determined(bcs: dict) -> bool:
    """True when a do-nothing face fixes the pressure level."""
    return any(isinstance(bc, DoNothing) for bc in bcs.values())


def build_constraints(V: DofMap, bcs: dict, t: float = 0.0) -> DirichletConstraints:
    """Velocity constraints of the conditions ``bcs`` at time ``t``."""
    dim, n = V.mesh.dim, V.n_dofs
    values = np.zeros((dim, n))
    mask = np.zeros((dim, n), dtype=bool)
    for tag, bc in sorted(((t_, b) for t_, b in bcs.items() if type(b) in _ORDER),
                          key=lambda item: _ORDER[type(item[1])]):
        dofs = V.boundary_dofs(tag)
        if isinstance(bc, Slip):
            axis = AXES.index(tag[0])
            values[axis, dofs] = 0.0
            mask[axis, dofs] = True
            continue
        mask[:, dofs] = True
        if isinstance(bc, NoSlip):
            values[:, dofs] = 0.0
        elif callable(bc.value):
            g = np.asarray(bc.value(V.coordinates[dofs], t), dtype=float)
            if g.shape != (dofs.size, dim):
                raise ValueError(f"face {tag}: Dirichlet callable returned shape {g.shape}, "
                                 f"expected {(dofs.size, dim)}")
            values[:, dofs] = g.T
        else:
            g = np.asarray(bc.value, dtype=float)
            if g.shape != (dim,):
                raise ValueError(f"face {tag}: Dirichlet value needs {dim} components, got {bc.value!r}")
            values[:, dofs] = g[:, None]
    flat = np.flatnonzero(mask.ravel())
    return DirichletConstraints(flat, values.ravel()[flat])
