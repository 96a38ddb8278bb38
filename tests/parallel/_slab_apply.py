"""Run under ``mpiexec -n P python _slab_apply.py``: every process applies the mass, Laplace and
convection operator on its slab, sums the shared planes and compares with the whole mesh's
product; prints one line per process and exits 1 on a mismatch."""
import sys

import numpy as np

from fbmflow.fem import FlowSpace, apply_mass_laplace
from fbmflow.mesh import StructuredMesh
from fbmflow.parallel import SlabPartition, world

comm = world()
dim = int(sys.argv[1])
mesh = StructuredMesh.box((3, 2, 7)[:dim - 1] + (7,), periodic=(True,) + (False,) * (dim - 1))
whole = FlowSpace(mesh)
u = np.random.default_rng(5).standard_normal(whole.n_u)  # the same on every process
want = apply_mass_laplace(whole, 2.0, 0.3, u, convection=0.7).reshape(dim, whole.n_v)
part = SlabPartition(mesh, comm.size, comm.rank)
local = FlowSpace(part.mesh)
mine = u.reshape(dim, whole.n_v)[:, part.nodes]
got = apply_mass_laplace(local, 2.0, 0.3, mine.ravel(), convection=0.7).reshape(dim, part.nodes.size)
part.sum_shared(got, comm)
error = float(np.abs(got - want[:, part.nodes]).max() / np.abs(want).max())
dot = part.dot(got, mine, comm)
dot_error = abs(dot - float(np.sum(want * u.reshape(dim, whole.n_v)))) / abs(dot)
ok = error < 1e-13 and dot_error < 1e-12
print(f"rank {comm.rank} of {comm.size}: layers {part.layers}, error {error:.1e}, dot error {dot_error:.1e}",
      flush=True)
sys.exit(0 if comm.allreduce(int(ok)) == comm.size else 1)
