"""Reference elements, quadrature, DOF maps, Numba kernels and assembly of Q2/P1disc."""
from .assembly import (
                       apply_convection,
                       apply_mass_laplace,
                       apply_reaction,
                       assemble_convection,
                       assemble_divergence,
                       assemble_laplace,
                       assemble_load,
                       assemble_mass,
                       assemble_mass_laplace,
                       pressure_mean_weights,
                       reaction_coefficients,
                       velocity_coefficients,
)
from .dofmap import DofMap, PressureDofMap
from .elements import ElementP1Disc, ElementQ1, ElementQ2
from .quadrature import gauss_tensor
from .space import FlowSpace

__all__ = ["FlowSpace", "DofMap", "PressureDofMap", "ElementQ1", "ElementQ2", "ElementP1Disc",
           "gauss_tensor", "assemble_mass", "assemble_laplace", "assemble_convection",
           "assemble_divergence", "assemble_load", "pressure_mean_weights",
           "apply_convection", "apply_reaction", "apply_mass_laplace", "assemble_mass_laplace",
           "reaction_coefficients", "velocity_coefficients"]
