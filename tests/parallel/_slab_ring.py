"""Run as ``[mpiexec -n P] python _slab_ring.py STEPS OUT BOUNDARY``: two disks settling in a
2 x 4 box periodic along both axes (a suspension: gravity along the periodic y axis, carried by
the mean pressure gradient, the mixture's mean flux removed after every step), one across the
periodic sides y = 0 and y = 4, the other across the middle, both centred on mesh lines (the
first on a mesh vertex: with the sharp boundary, a halo cell's pressure extension differs from
its owner's there), with the fictitious ``BOUNDARY`` (``nodes`` or ``sharp``), multigrid and
tolerances 1e-10, for ``STEPS`` steps through the Python API on as many processes as the
launcher started: the slabs form a ring. The first process writes every step's positions,
velocities and cycles, and the mixture's mean velocity, to ``OUT`` (``.npz``)."""
import sys

import numpy as np

import fbmflow as fb

steps, out, boundary = int(sys.argv[1]), sys.argv[2], sys.argv[3]
mesh = fb.StructuredMesh.box((16, 32), upper=(2.0, 4.0), periodic=(True, True))
disks = fb.Particles.at_rest([fb.Ball(0.25, dim=2)] * 2, density=1.25, position=[[0.75, 0.125], [1.25, 2.0]])
sim = fb.Simulation(mesh, disks, fb.FluidParams(density=1.0, viscosity=0.1, gravity=980.0),
                    time=fb.TimeParams(dt=0.005, t_end=1.0, scheme="crank-nicolson"),
                    solver=fb.SolverParams(linear="multigrid", newton_rtol=1e-10, linear_rtol=1e-10),
                    coupling=fb.CouplingParams(integrator="trapezoidal", tol=1e-10),
                    fbm=fb.FictitiousBoundaryParams(boundary=boundary))
rows = [sim.step() for _ in range(steps)]
mixture = sim.mixture_velocity()
if sim.comm.rank == 0:
    np.savez(out, position=np.array([r.position for r in rows]),
             velocity=np.array([r.velocity for r in rows]),
             cycles=np.array([r.linear.iterations for r in rows]), mixture=mixture, processes=sim.comm.size)
print(f"rank {sim.comm.rank} of {sim.comm.size}: ring, {steps} steps, position {rows[-1].position.ravel()}",
      flush=True)
