"""Rigid particles: shapes (inside tests, volume, inertia), state and Newton–Euler dynamics."""
from .shapes import Ball

__all__ = ["Ball"]
