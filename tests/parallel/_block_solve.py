"""Run under ``mpiexec -n P python _block_solve.py DIM CASE [GRID]``: every process solves an Oseen
time step's saddle-point system on its block (``GRID``: the processes along every axis, as
``2x2``; the automatic choice where not given) with the distributed multigrid and compares its owned
unknowns with the whole mesh's direct solution; it also solves the same system alone (one slab)
for the cycles per solve. Prints one line per process and exits 1 on a mismatch.

CASE: ``channel`` (inflow at the last axis's lower face, outflow at its upper face),
``cavity`` (a closed box: the mean pressure fixed, the continuity data balanced) or ``periodic``
(periodic along every axis: the slabs form a ring, the mean pressure fixed)."""
import sys

import numpy as np

from fbmflow.flow import Dirichlet, DoNothing, NoSlip
from fbmflow.flow.blocks import BlockFlowLevels
from fbmflow.flow.levels import FlowLevel
from fbmflow.mesh import StructuredMesh
from fbmflow.parallel import SerialComm, world
from fbmflow.solvers.direct import factorize
from fbmflow.solvers.distributed import DistributedMultigrid

comm = world()
dim, case = int(sys.argv[1]), sys.argv[2]
grid = tuple(int(g) for g in sys.argv[3].split("x")) if len(sys.argv) > 3 else None
shape = (8, 16) if dim == 2 else (4, 4, 16)
mesh = StructuredMesh.box(shape, upper=(1.0, 2.0) if dim == 2 else (1.0, 1.0, 2.0),
                          periodic=(case == "periodic",) * dim)
tags = mesh.tags
boundary = {t: NoSlip() for t in tags}
if case == "channel":
    boundary[tags[-2]] = Dirichlet((0.0,) * (dim - 1) + (1.0,))
    boundary[tags[-1]] = DoNothing()
elif case == "cavity":
    boundary[tags[-1]] = Dirichlet((1.0,) + (0.0,) * (dim - 1))
closed = case in ("cavity", "periodic")
coefficients = dict(m=50.0, a=1.0, rho=1.0, mu=0.01, convection=True)


def velocity(coordinates):
    x = coordinates
    if case == "periodic":  # periodic itself: a ring's halo nodes lie a period away
        s, c = np.sin(np.pi * x[:, -1]), np.cos(2 * np.pi * x[:, 0])
        return np.stack([s + c] + [s * c] * (dim - 1)).ravel()
    return np.stack([np.sin(3 * x[:, -1]) + x[:, 0]] + [x[:, 0] * x[:, -1]] * (dim - 1)).ravel()


whole = FlowLevel(mesh, boundary, closed)
u_whole = velocity(whole.space.V.coordinates)
reference_system = whole.system(u_whole, newton=False, **coefficients)
rng = np.random.default_rng(7)
b = rng.standard_normal(reference_system.n_u + reference_system.n_p)
n_u = reference_system.n_u
g = reference_system.balance(b[n_u:])
u_ref, p_ref = factorize(reference_system)(b[:n_u], g)
x_ref = np.concatenate([u_ref, p_ref])


def solve(communicator):
    slabs = BlockFlowLevels(mesh, boundary, closed, communicator,
                            grid=grid if communicator.size > 1 else None)
    fine = slabs.partitions[0]
    u = velocity(slabs.levels[0].space.V.coordinates)
    system = slabs.systems(u, **coefficients)
    solver = DistributedMultigrid(system, rtol=1e-11)
    rhs = fine.local(b)
    u, p, report = solver.solve(rhs[:system.n_u], rhs[system.n_u:])
    x = np.concatenate([u, p])
    want = fine.local(x_ref)
    own = fine.owned
    error = float(np.abs(x[own] - want[own]).max() / np.abs(x_ref).max())
    ghosts = float(np.abs(x - want).max() / np.abs(x_ref).max())  # consistent: ghosts too
    return error, ghosts, report.iterations, len(solver.levels) + 1, slabs.grid


error, ghosts, cycles, n_levels, chosen = solve(comm)
_, _, alone, _, _ = solve(SerialComm())
ok = error < 1e-8 and ghosts < 1e-8 and cycles <= 1.3 * alone + 1
print(f"rank {comm.rank} of {comm.size}: {case} {dim}D, grid {chosen}, {n_levels} levels, error {error:.1e} "
      f"(ghosts {ghosts:.1e}), cycles {cycles} against {alone} on one process", flush=True)
sys.exit(0 if comm.allreduce(int(ok)) == comm.size else 1)
