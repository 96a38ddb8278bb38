"""Rigid particles: shapes (inside tests, volume, inertia), state and Newton–Euler dynamics."""
from .dynamics import INTEGRATORS, accelerations, integrate
from .shapes import Ball
from .state import Particles

__all__ = ["Ball", "Particles", "INTEGRATORS", "accelerations", "integrate"]
