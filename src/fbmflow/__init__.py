"""fbmflow: particulate flows with the finite element fictitious boundary method.

The public API is listed in ``__all__`` (documented on the site's Python API page); names are imported lazily
so
that ``import fbmflow`` does no work (no Numba import, no compilation).
"""
import importlib

__version__ = "0.1.0"

_API = {
    "Simulation": "fbmflow.simulation",
    "StepReport": "fbmflow.coupling.system",
    "InsufficientMemory": "fbmflow.solvers.choice",
    "FluidParams": "fbmflow.params",
    "TimeParams": "fbmflow.params",
    "SolverParams": "fbmflow.solvers.settings",
    "CouplingParams": "fbmflow.coupling.settings",
    "FictitiousBoundaryParams": "fbmflow.coupling.settings",
    "ContactParams": "fbmflow.contact.settings",
    "RepulsionParams": "fbmflow.contact.settings",
    "ParamError": "fbmflow.config",
    "from_dict": "fbmflow.config",
    "COUPLINGS": "fbmflow.coupling",
    "FORCE_ESTIMATORS": "fbmflow.coupling",
    "StructuredMesh": "fbmflow.mesh",
    "FlowSpace": "fbmflow.fem",
    "NavierStokesProblem": "fbmflow.flow",
    "Dirichlet": "fbmflow.flow",
    "NoSlip": "fbmflow.flow",
    "Slip": "fbmflow.flow",
    "DoNothing": "fbmflow.flow",
    "TIME_SCHEMES": "fbmflow.flow.time_schemes",
    "advance": "fbmflow.flow.time_schemes",
    "NewtonSettings": "fbmflow.solvers",
    "ConvergenceError": "fbmflow.solvers",
    "LINEAR_SOLVERS": "fbmflow.solvers",
    "Ball": "fbmflow.particles",
    "Ellipsoid": "fbmflow.particles",
    "Box": "fbmflow.particles",
    "Cylinder": "fbmflow.particles",
    "ImplicitShape": "fbmflow.particles",
    "TriangulatedSurface": "fbmflow.particles",
    "Particles": "fbmflow.particles",
    "SCENES": "fbmflow.scenes",
    "get_scene": "fbmflow.scenes",
    "load_scene": "fbmflow.scenes",
    "run_scene": "fbmflow.scenes",
    "resume": "fbmflow.scenes",
}

__all__ = ["__version__", *_API]


def __getattr__(name):
    if name in _API:
        return getattr(importlib.import_module(_API[name]), name)
    raise AttributeError(f"module 'fbmflow' has no attribute {name!r}")


def __dir__():
    return __all__
