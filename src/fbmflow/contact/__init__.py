"""Particle–particle and particle–wall contact (imports ``particles`` only)."""
from .repulsion import Repulsion

__all__ = ["Repulsion"]
