"""The contact settings: hard contact (:class:`~fbmflow.contact.settings.ContactParams`) and the
short-range repulsion (:class:`~fbmflow.contact.settings.RepulsionParams`), each with the ``make``
that builds its model for a mesh."""
from __future__ import annotations

import dataclasses

from ..config import ParamError, Section, param
from .broadphase import BROADPHASES
from .contact_set import ContactSet
from .lubrication import Lubrication
from .narrowphase import Planes
from .repulsion import Repulsion

#: the largest contact skin, as a fraction of the smallest particle radius, that contact times and
#: distances survive: beyond it a scene warns and names the level that brings it below, and a
#: step that ends in an overlap names the skin as the cause
SKIN_FRACTION = 0.5


@dataclasses.dataclass(frozen=True)
class RepulsionParams(Section):
    """Short-range repulsion from walls and other particles (Glowinski et al.)."""

    enabled: bool = param(True, "repulsive forces on (the flow cannot resolve the last gap)")
    range_cells: float = param(1.0, "force range in mesh cells", positive=True)
    strength: float = param(10.0, "force at contact over the particle's weight in the fluid", positive=True)

    def make(self, mesh, walls=None):
        """The :class:`~fbmflow.contact.repulsion.Repulsion` for the walls of ``mesh`` (all faces, or the
        ``(axis, side)`` pairs in ``walls``); None when off. The range is counted in the
        mesh's finest cells (those of the fine zone of a graded mesh)."""
        if not self.enabled:
            return None
        return Repulsion(self.range_cells * float(max(mesh.finest_spacing)), tuple(mesh.lower),
                         tuple(mesh.upper), self.strength, None if walls is None else tuple(walls),
                         tuple(float(L) for L in mesh.periods) if any(mesh.periodic) else None)


@dataclasses.dataclass(frozen=True)
class ContactRepulsionParams(RepulsionParams):
    """Short-range repulsion, off by default in scenes with hard contact (which keeps the
    particles apart)."""

    enabled: bool = param(False, "repulsive forces on, in addition to hard contact")


@dataclasses.dataclass(frozen=True)
class ContactParams(Section):
    """Hard contact between particles and with the walls (projected Gauss–Seidel, sub-stepped)."""

    enabled: bool = param(True, "hard contact on (no overlap of particles or with the walls)")
    restitution: float = param(0.0, "coefficient of restitution (0: the fluid damps the rebound)",
                               minimum=0.0, maximum=1.0)
    friction: float = param(0.0, "Coulomb friction coefficient", nonnegative=True)
    substeps: int = param(10, "contact sub-steps per fluid step", minimum=1)
    iterations: int = param(50, "projected Gauss-Seidel sweeps per sub-step at most", minimum=1)
    broadphase: str = param("grid", "broadphase", choices=tuple(BROADPHASES))
    skin_cells: float = param(1.0, "contact distance in mesh cells: the fictitious boundary needs free "
                              "fluid nodes between surfaces", nonnegative=True)
    lubrication: bool = param(False, "lubrication correction for gaps below lubrication_range_cells")
    lubrication_range_cells: float = param(2.0, "gap in mesh cells below which the film force acts "
                                           "(the flow resolves larger gaps)", positive=True)
    lubrication_min_gap_cells: float = param(0.02, "gap in mesh cells at which the film force stops "
                                             "growing (surface roughness; below the range)", positive=True)
    lubrication_resolved_cells: float = param(0.37, "gap in mesh cells down to which the flow carries the "
                                              "film force (fitted to Brenner's exact drag)", nonnegative=True)

    def __post_init__(self):
        super().__post_init__()
        if not self.lubrication_min_gap_cells < self.lubrication_range_cells:
            raise ParamError(f"contact.lubrication_min_gap_cells = {self.lubrication_min_gap_cells} must be "
                             f"below contact.lubrication_range_cells = {self.lubrication_range_cells}")

    def make(self, mesh, viscosity: float, walls=None):
        """The :class:`~fbmflow.contact.contact_set.ContactSet` with the walls of ``mesh`` (all faces, or the
        ``(axis, side)`` pairs in ``walls``); None when off. ``viscosity``: the fluid's, for the
        lubrication correction. Distances are counted in the mesh's finest cells."""
        if not self.enabled:
            return None
        h = float(max(mesh.finest_spacing))  # the fine zone's cells on a graded mesh
        lubrication = None
        if self.lubrication:
            lubrication = Lubrication(viscosity, self.lubrication_range_cells * h,
                                      self.lubrication_min_gap_cells * h, self.lubrication_resolved_cells * h)
        return ContactSet(Planes.box(mesh.lower, mesh.upper, walls), restitution=self.restitution,
                          friction=self.friction, iterations=self.iterations, broadphase=self.broadphase,
                          skin=self.skin_cells * h, lubrication=lubrication,
                          periods=tuple(float(L) for L in mesh.periods) if any(mesh.periodic) else None,
                          origin=tuple(mesh.lower))


@dataclasses.dataclass(frozen=True)
class WallContactParams(ContactParams):
    """Hard contact with the walls, off by default in single-particle scenes, where the repulsion
    keeps the particle off the walls. A heavy particle that reaches the wall faster than the
    repulsion can stop it (at most about ``sqrt(2 strength g' h)``, ``g'`` the reduced gravity,
    ``h`` its range) needs it;
    it advances the particle by semi-implicit Euler."""

    enabled: bool = param(False, "hard contact on: the particle stops skin_cells from the walls (for a "
                          "heavy particle the repulsion cannot stop; set coupling.integrator = "
                          "semi-implicit-euler with it)")
