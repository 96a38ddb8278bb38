"""Run under ``mpiexec -n P python _slab_flow.py DIM CASE STEPS``: every process takes ``STEPS``
time steps (fractional-step theta) of a Navier–Stokes flow on its slabs
(:class:`~fbmflow.flow.blocks.BlockNavierStokesProblem`) and compares its owned unknowns with the
same steps on the whole mesh by one process (multigrid too); prints one line per process with the
largest relative difference and the cycles per step of both, and exits 1 on a mismatch.

CASE: ``cavity`` (a closed box, its lid moving along the first axis; the mean pressure fixed) or
``channel`` (inflow through the last axis's lower face, outflow at its upper face)."""
import sys

import numpy as np

from fbmflow.flow import Dirichlet, DoNothing, NavierStokesProblem, NoSlip
from fbmflow.flow.blocks import BlockNavierStokesProblem
from fbmflow.flow.time_schemes import advance
from fbmflow.mesh import StructuredMesh
from fbmflow.parallel import world
from fbmflow.solvers import NewtonSettings
from fbmflow.solvers.multigrid import MultigridSolver

comm = world()
dim, case, steps = int(sys.argv[1]), sys.argv[2], int(sys.argv[3])
shape = (8, 16) if dim == 2 else (4, 4, 16)
mesh = StructuredMesh.box(shape, upper=(1.0, 2.0) if dim == 2 else (1.0, 1.0, 2.0))
tags = mesh.tags
boundary = {t: NoSlip() for t in tags}
if case == "channel":
    boundary[tags[-2]] = Dirichlet(lambda x, t: np.outer(x[:, 0] * (1 - x[:, 0]) * 4 * min(1.0, 5 * t),
                                                         np.eye(dim)[-1]))
    boundary[tags[-1]] = DoNothing()
else:
    boundary[tags[-1]] = Dirichlet((1.0,) + (0.0,) * (dim - 1))
newton = NewtonSettings(rtol=1e-11, atol=1e-13, linear_rtol=1e-10)
flow = dict(viscosity=0.01, density=1.0, newton=newton)
dt = 0.05


def run(problem):
    x = problem.zero_state(0.0)
    t = 0.0
    cycles = []
    for _ in range(steps):
        before = problem.linear_work.iterations
        x, _ = advance(problem, x, t, dt, "fractional-step-theta")
        cycles.append(problem.linear_work.iterations - before)
        t += dt
    return x, float(np.mean(cycles))


alone = NavierStokesProblem(mesh, boundary=boundary, linear_solver=MultigridSolver(rtol=1e-10), **flow)
whole, whole_cycles = run(alone)
slab = BlockNavierStokesProblem(mesh, boundary=boundary, comm=comm, **flow)
mine, cycles = run(slab)
part = slab.partition
want = part.local(whole)
own = part.owned
error = float(np.abs(mine[own] - want[own]).max() / np.abs(whole).max())
ok = error < 1e-8 and cycles <= 1.3 * whole_cycles + 1
print(f"rank {comm.rank} of {comm.size}: {case} {dim}D, {steps} steps, difference {error:.1e}, "
      f"cycles per step {cycles:.1f} against {whole_cycles:.1f} on the whole mesh", flush=True)
sys.exit(0 if comm.allreduce(int(ok)) == comm.size else 1)
