"""Rigid particles: shapes (inside tests, volume, inertia), state and Newton–Euler dynamics."""
from .dynamics import (
    INTEGRATORS,
    accelerations,
    integrate,
    pack_velocities,
    quaternion_step,
    symmetric_motion,
    unpack_velocities,
    velocity_gain,
)
from .shapes import Ball, Box, Cylinder, Ellipsoid, ImplicitShape, TriangulatedSurface
from .state import Particles

__all__ = ["Ball", "Box", "Cylinder", "Ellipsoid", "ImplicitShape", "TriangulatedSurface", "Particles",
           "INTEGRATORS", "accelerations", "integrate", "pack_velocities", "quaternion_step",
           "symmetric_motion", "unpack_velocities", "velocity_gain"]
