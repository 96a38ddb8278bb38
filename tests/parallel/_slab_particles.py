"""Run as ``[mpiexec -n P] python _slab_particles.py CASE LEVEL STEPS OUT [KEY=VALUE ...]``:
``STEPS`` time steps on as many processes as the launcher started (one without a launcher) of a
scene at ``LEVEL`` with the settings given (CASE a scene's name), or of ``sphere``: a sphere
settling from rest in a closed 1 x 1 x 2 box of 4 x 4 x 8 cells (``LEVEL`` ignored; the nodal
boundary, multigrid, the implicit coupling). The first process writes every step's particle
positions and velocities and the linear solver's cycles per step to ``OUT`` (``.npz``); every
process prints one line with its final position."""
import sys

import numpy as np

from fbmflow import Simulation
from fbmflow.coupling.settings import CouplingParams, FictitiousBoundaryParams
from fbmflow.mesh import StructuredMesh
from fbmflow.params import FluidParams, TimeParams
from fbmflow.particles import Ball, Particles
from fbmflow.scenes.registry import load_scene
from fbmflow.solvers.settings import SolverParams

case, level, steps, out = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
if case == "sphere":
    mesh = StructuredMesh.box((4, 4, 8), upper=(1.0, 1.0, 2.0))
    particles = Particles.at_rest([Ball(0.3, dim=3)], 1500.0, [[0.5, 0.5, 1.2]])
    sim = Simulation(mesh, particles, FluidParams(density=1000.0, viscosity=0.5, gravity=1.0),
                     time=TimeParams(dt=0.05, t_end=1.0), fbm=FictitiousBoundaryParams(boundary="nodes"),
                     solver=SolverParams(linear="multigrid", newton_rtol=1e-10, linear_rtol=1e-10),
                     coupling=CouplingParams(tol=1e-10))
else:
    scene, params, level = load_scene(case, level, sys.argv[5:])
    sim = scene.build(params, level).sim
rows = [sim.step() for _ in range(steps)]
comm = sim.comm
if comm.rank == 0:
    np.savez(out, position=np.array([r.position for r in rows]),
             velocity=np.array([r.velocity for r in rows]),
             cycles=np.array([r.linear.iterations for r in rows]), processes=comm.size)
print(f"rank {comm.rank} of {comm.size}: {case}, {steps} steps, position {rows[-1].position[0]}", flush=True)
