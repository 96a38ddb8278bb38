"""The only place where fluid meets particles: node ownership, fictitious-boundary constraints,
hydrodynamic forces (estimators in :data:`~fbmflow.coupling.estimators.FORCE_ESTIMATORS`) and the
coupling schemes (:data:`~fbmflow.coupling.schemes.COUPLINGS`)."""
from .estimators import FORCE_ESTIMATORS, SurfaceForce, TestFunctionForce, VolumeForce, make_force_estimator
from .forces import (
    SurfaceForces,
    TestFunctionForces,
    cut_cells,
    hydrodynamic_forces,
    mirror_images,
    supports_surface_force,
)
from .indicator import node_owner, rigid_body_constraints, rigid_liftings
from .obstacles import FixedObstacles
from .schemes import (
    COUPLINGS,
    CoupledFlow,
    ExplicitCoupling,
    ImplicitCoupling,
    NewtonKrylovCoupling,
    StabilisedCoupling,
    make_coupling,
)
from .sharp import SharpBoundary, sharp_boundary, supports_sharp_boundary

__all__ = ["node_owner", "rigid_body_constraints", "rigid_liftings", "cut_cells", "hydrodynamic_forces",
           "mirror_images", "TestFunctionForces", "SurfaceForces", "supports_surface_force", "FixedObstacles",
           "SharpBoundary", "sharp_boundary", "supports_sharp_boundary", "FORCE_ESTIMATORS", "VolumeForce",
           "TestFunctionForce", "SurfaceForce", "make_force_estimator", "COUPLINGS", "CoupledFlow",
           "ExplicitCoupling", "StabilisedCoupling", "NewtonKrylovCoupling", "ImplicitCoupling",
           "make_coupling"]
