"""Bodies held in place in a flow (e.g. the DFG cylinder) as fictitious boundaries."""
from __future__ import annotations

import numpy as np

from ..fem import FlowSpace
from ..fem.constraints import DirichletConstraints
from ..fem.dofmap import DofMap
from .indicator import node_owner, rigid_body_constraints
from .sharp import sharp_boundary, supports_sharp_boundary


class FixedObstacles:
    """The ``extra_constraints`` of a :class:`~fbmflow.flow.navier_stokes.NavierStokesProblem` for bodies held
    at their positions: the rigid velocity ``U_i`` (zero: at rest) on their nodes, and with
    ``boundary = "sharp"`` the sharp boundary's changes (:mod:`fbmflow.coupling.sharp`) on the
    finest mesh asked for, told by its first axis's cells (never the axis divided among
    processes; coarser multigrid levels get the nodal constraints). On one process's slab the
    halo must hold the rows' reach (:func:`~fbmflow.coupling.sharp.reach_layers` where the
    bodies lie in the mesh's finest cells). A non-zero
    ``U_i`` gives the quasi-steady flow of bodies passing through these positions (e.g. the
    Stokes drag of a sphere approaching a wall).

    Parameters
    ----------
    shapes : list of shapes, one per body
    centres : (n, dim) float64, the bodies' centres [m]
    boundary : ``"nodes"`` or ``"sharp"``
    velocities : (n, dim) float64 or None, the bodies' translational velocities [m/s]
    angular_velocities : (n,) float64 in 2D, (n, 3) in 3D, or None: the bodies' angular
        velocities [rad/s] about their centres (a body turning in place)
    """

    def __init__(self, shapes: list, centres, boundary: str = "nodes", velocities=None,
                 angular_velocities=None):
        if boundary not in ("nodes", "sharp"):
            raise ValueError(f"unknown fictitious boundary {boundary!r}; choose nodes or sharp")
        if boundary == "sharp" and not supports_sharp_boundary(shapes):
            raise ValueError("the sharp fictitious boundary needs shapes with a closest-point projection "
                             "(Ball, Box, Cylinder); use the nodal boundary for the others")
        self.shapes = list(shapes)
        self.centres = np.atleast_2d(np.asarray(centres, dtype=float))
        self.boundary = boundary
        n, dim = self.centres.shape
        self.velocities = np.zeros((n, dim)) if velocities is None else np.array(velocities, dtype=float)
        if self.velocities.shape != (n, dim):
            raise ValueError(f"velocities must have shape {(n, dim)}, got {self.velocities.shape}")
        spin = (n,) if dim == 2 else (n, 3)
        self.angular_velocities = (np.zeros(spin) if angular_velocities is None
                                   else np.array(angular_velocities, dtype=float))
        if self.angular_velocities.shape != spin:
            raise ValueError(f"angular_velocities must have shape {spin}, "
                             f"got {self.angular_velocities.shape}")
        self._finest: tuple | None = None  # (DOF map, its first axis's cell size, the sharp boundary there)

    def __call__(self, V: DofMap, t: float) -> DirichletConstraints:
        motion = (self.velocities, self.angular_velocities)
        owner = node_owner(V, self.centres, self.shapes)
        rigid = rigid_body_constraints(V, owner, self.centres, *motion)
        if self.boundary == "nodes":
            return rigid
        h = float(V.mesh.spacing[0])
        if self._finest is None or h < self._finest[1] or (h == self._finest[1] and V is not self._finest[0]):
            space = FlowSpace(V.mesh)
            self._finest = (V, h, sharp_boundary(space, node_owner(space.V, self.centres, self.shapes),
                                                 self.centres, self.shapes))
        if h > self._finest[1]:
            return rigid
        return self._finest[2].constraints(rigid, *motion)
