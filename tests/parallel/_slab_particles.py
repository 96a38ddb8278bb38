"""Run as ``[mpiexec -n P] python _slab_particles.py SCENE LEVEL STEPS OUT [KEY=VALUE ...]``:
``STEPS`` time steps on as many processes as the launcher started (one without a launcher) of a
scene at ``LEVEL`` with the settings given. The first process writes every step's particle
positions and velocities and the linear solver's cycles per step to ``OUT`` (``.npz``); every
process prints one line with its final position and its Numba threads."""
import sys

import numpy as np

from fbmflow._jit import numba_threads
from fbmflow.scenes.registry import load_scene

case, level, steps, out = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
scene, params, level = load_scene(case, level, sys.argv[5:])
sim = scene.build(params, level).sim
rows = [sim.step() for _ in range(steps)]
comm = sim.comm
if comm.rank == 0:
    np.savez(out, position=np.array([r.position for r in rows]),
             velocity=np.array([r.velocity for r in rows]),
             cycles=np.array([r.linear.iterations for r in rows]), processes=comm.size)
print(f"rank {comm.rank} of {comm.size}: {case}, {steps} steps, position {rows[-1].position[0]}, "
      f"threads {numba_threads()}", flush=True)
