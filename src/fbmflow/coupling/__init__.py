"""The only place where fluid meets particles: node ownership, fictitious-boundary constraints,
hydrodynamic forces."""
from .forces import (cut_cells, hydrodynamic_forces, mirror_images, SurfaceForces, supports_surface_force,
                     TestFunctionForces)
from .obstacles import FixedObstacles
from .indicator import node_owner, rigid_body_constraints, rigid_liftings
from .sharp import SharpBoundary, sharp_boundary, supports_sharp_boundary

__all__ = ["node_owner", "rigid_body_constraints", "rigid_liftings", "cut_cells", "hydrodynamic_forces", "mirror_images",
           "TestFunctionForces", "SurfaceForces", "supports_surface_force", "FixedObstacles", "SharpBoundary",
           "sharp_boundary", "supports_sharp_boundary"]
