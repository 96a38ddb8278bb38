"""The Navier–Stokes problem, boundary conditions and time schemes (no particles here)."""
from .boundary import Dirichlet, DoNothing, NoSlip, Slip
from .navier_stokes import NavierStokesProblem

__all__ = ["NavierStokesProblem", "Dirichlet", "NoSlip", "Slip", "DoNothing"]
