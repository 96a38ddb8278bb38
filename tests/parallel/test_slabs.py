"""Slabs of a structured mesh, one per process (:mod:`fbmflow.parallel.slabs`)."""
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from fbmflow.fem import FlowSpace, apply_mass_laplace
from fbmflow.mesh import StructuredMesh
from fbmflow.parallel import LAUNCHER_VARIABLES, SerialComm, SlabPartition


class _Loopback:
    """Process ``rank``'s side of ``Sendrecv`` among slabs held in one process: it receives the
    neighbour's values as they were before any exchange (``before``: rank -> values)."""

    def __init__(self, parts, before, rank):
        self.parts, self.before, self.rank = parts, before, rank

    def Sendrecv(self, sendbuf, dest, recvbuf, source):  # noqa: N802 (mpi4py's name)
        p = self.parts[source].plane
        recvbuf[:] = self.before[source][:, -p:] if source < self.rank else self.before[source][:, :p]

    def allreduce(self, value, op=None):
        return value


@pytest.mark.parametrize("dim, size", [(2, 1), (2, 3), (3, 2), (3, 4), (3, 9)])
def test_slab_products_summed_at_shared_planes_are_the_whole_meshs(dim, size):
    """The operator applied on every slab's own mesh, the shared planes summed: the whole mesh's
    product at every slab node, the same bits on both copies of a shared node; the slabs' nodes
    and cells cover the mesh's, each node owned once."""
    mesh = StructuredMesh.box((3, 2, 9)[:dim - 1] + (9,), upper=(1.0, 0.7, 2.0)[:dim - 1] + (2.0,),
                              periodic=(True,) + (False,) * (dim - 1))
    whole = FlowSpace(mesh)
    u = np.random.default_rng(3).standard_normal(whole.n_u).reshape(dim, whole.n_v)
    want = apply_mass_laplace(whole, 2.0, 0.3, u.ravel(), convection=0.7).reshape(dim, whole.n_v)
    parts = [SlabPartition(mesh, size, r) for r in range(size)]
    before = {}
    for r, part in enumerate(parts):
        local = FlowSpace(part.mesh)
        assert np.allclose(local.V.coordinates, whole.V.coordinates[part.nodes])
        before[r] = apply_mass_laplace(local, 2.0, 0.3, u[:, part.nodes].ravel(),
                                       convection=0.7).reshape(dim, part.nodes.size)
    got = {r: before[r].copy() for r in before}
    for r, part in enumerate(parts):
        part.sum_shared(got[r], _Loopback(parts, before, r))
        assert np.allclose(got[r], want[:, part.nodes], rtol=0.0, atol=1e-13 * np.abs(want).max())
    for r in range(1, size):
        p = parts[r].plane
        assert np.array_equal(got[r][:, :p], got[r - 1][:, -p:])
    owned = np.concatenate([part.nodes[part.owned] for part in parts])
    assert np.array_equal(owned, np.arange(whole.n_v))
    assert np.array_equal(np.concatenate([part.cells for part in parts]), np.arange(mesh.n_cells))
    dots = [part.dot(got[r], u[:, part.nodes], SerialComm()) for r, part in enumerate(parts)]
    assert np.isclose(sum(dots), np.sum(want * u), rtol=1e-13)


def test_slabs_refuse_what_they_cannot_split():
    mesh = StructuredMesh.box((4, 3))
    with pytest.raises(ValueError, match="at least as many cell layers"):
        SlabPartition(mesh, 4, 0)
    with pytest.raises(ValueError, match="not periodic"):
        SlabPartition(StructuredMesh.box((4, 4), periodic=(False, True)), 2, 0)
    with pytest.raises(ValueError, match="rank 2"):
        SlabPartition(mesh, 2, 2)


@pytest.mark.parametrize("dim, size", [(2, 2), (3, 3)])
def test_under_mpiexec_the_slabs_give_the_whole_meshs_product(dim, size):
    """``mpiexec -n P``: each process's slab product, summed with its neighbours' over MPI,
    equals the whole mesh's; where the ``mpi`` extra is installed."""
    pytest.importorskip("mpi4py")
    mpiexec = shutil.which("mpiexec", path=str(Path(sys.executable).parent)) or shutil.which("mpiexec")
    if mpiexec is None:
        pytest.skip("no mpiexec")
    script = Path(__file__).with_name("_slab_apply.py")
    out = subprocess.run([mpiexec, "-n", str(size), sys.executable, str(script), str(dim)],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stdout + out.stderr
    assert out.stdout.count(f" of {size}: layers") == size


def test_world_is_one_process_without_a_launcher_and_refuses_a_mismatched_mpi(monkeypatch):
    """No launcher: the stand-in. A launcher's two processes: mpi4py missing, or an MPI that sees
    one process (mpi4py built against another MPI), each a RuntimeError naming the remedy."""
    import types

    from fbmflow.parallel import world
    for size, _ in LAUNCHER_VARIABLES:
        monkeypatch.delenv(size, raising=False)
    assert isinstance(world(), SerialComm)
    monkeypatch.setenv("PMI_SIZE", "2")
    monkeypatch.setenv("PMI_RANK", "0")
    monkeypatch.setitem(sys.modules, "mpi4py", None)
    with pytest.raises(RuntimeError, match=r"pip install -e \"\.\[mpi\]\""):
        world()
    alone = types.SimpleNamespace(COMM_WORLD=types.SimpleNamespace(Get_size=lambda: 1))
    monkeypatch.setitem(sys.modules, "mpi4py", types.SimpleNamespace(MPI=alone))
    with pytest.raises(RuntimeError, match="another MPI"):
        world()
