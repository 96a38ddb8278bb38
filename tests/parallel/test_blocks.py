"""Slabs of a structured mesh, one per process (:mod:`fbmflow.parallel.blocks`)."""
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from fbmflow.fem import FlowSpace, apply_mass_laplace
from fbmflow.mesh import StructuredMesh
from fbmflow.parallel import LAUNCHER_VARIABLES, BlockPartition, SerialComm


class _Loopback:
    """Process ``rank``'s side of ``Sendrecv``, ``Send`` and ``Recv`` among blocks held in one
    process. A first pass (``sent`` None) records what every process sends and receives zeros; a
    second pass hands each process what its neighbour sent in the first (the exchanges write
    only what no process sends, so the order does not matter), the k-th message between two
    processes (two processes on a ring exchange twice) to the k-th receive, as MPI matches
    them."""

    def __init__(self, rank, sent=None):
        self.rank, self.sent, self.record, self.count = rank, sent, {}, {}

    def Send(self, buf, dest):  # noqa: N802 (mpi4py's name)
        self.record.setdefault((self.rank, dest), []).append(buf.copy())

    def Recv(self, buf, source):  # noqa: N802
        k = self.count[source] = self.count.get(source, -1) + 1
        buf[:] = 0.0 if self.sent is None else self.sent[(source, self.rank)][k]

    def Sendrecv(self, sendbuf, dest, recvbuf, source):  # noqa: N802
        self.Send(sendbuf, dest)
        self.Recv(recvbuf, source)

    def allreduce(self, value, op=None):
        return value


def _exchange(parts, vectors, method):
    """``method`` ("update_ghosts" or "add_ghosts") of every block on its vector, as if each
    process ran it at once."""
    sent = {}
    for r, part in enumerate(parts):
        comm = _Loopback(r)
        getattr(part, method)(vectors[r].copy(), comm)
        sent.update(comm.record)
    for r, part in enumerate(parts):
        getattr(part, method)(vectors[r], _Loopback(r, sent))


def _mesh(dim, ring=False, shape=None, periodic=None):
    shape = shape or (3, 2, 9)[:dim - 1] + (9,)
    periodic = periodic or (True,) + (False,) * (dim - 2) + (ring,)
    return StructuredMesh.box(shape, upper=(1.0, 0.7, 2.0)[:dim - 1] + (2.0,), periodic=periodic)


#: (dim, grid, halo, mesh shape, periodic axes): slabs (the default grid) and blocks
CASES = [(2, (1, 1), 1, None, (True, False)), (2, (1, 3), 1, None, (True, False)),
         (3, (1, 1, 2), 1, None, (True, False, False)), (3, (1, 1, 4), 1, None, (True, False, False)),
         (2, (1, 3), 2, None, (True, False)), (3, (1, 1, 2), 3, None, (True, False, False)),
         (2, (1, 2), 1, None, (True, True)), (3, (1, 1, 3), 2, None, (True, False, True)),
         (2, (1, 4), 1, None, (True, True)),
         (2, (2, 2), 1, (6, 9), (False, False)), (2, (3, 2), 1, (8, 9), (True, False)),
         (2, (2, 2), 1, (8, 8), (True, True)), (2, (2, 3), 2, (9, 9), (False, False)),
         (3, (2, 1, 2), 1, (8, 6, 9), (False, False, True)),
         (3, (2, 2, 2), 1, (8, 6, 9), (True, False, False)),
         (3, (2, 2, 3), 2, (11, 10, 10), (True, True, True))]


@pytest.mark.parametrize("dim, grid, halo, shape, periodic", CASES)
def test_block_rows_of_the_owned_cells_are_the_whole_meshs_and_ghosts_follow_owners(dim, grid, halo, shape,
                                                                                     periodic):
    """The operator applied on every block mesh: the whole mesh's product at every node of the
    owned cells; after the ghost update at every block node (halos of one cell layer and of
    several; periodic axes, whose blocks form rings; slabs and blocks in two and three
    directions). The owned unknowns cover the whole mesh's once; the ghosts' parts added to the
    owners sum to the whole; dots count each once."""
    mesh = _mesh(dim, shape=shape, periodic=periodic)
    size = int(np.prod(grid))
    whole = FlowSpace(mesh)
    u = np.random.default_rng(3).standard_normal(whole.n_u)
    want = apply_mass_laplace(whole, 2.0, 0.3, u, convection=0.7).reshape(dim, whole.n_v)
    parts = [BlockPartition(mesh, size, r, halo=halo, grid=grid) for r in range(size)]
    for part in parts:
        for a, ((lo, hi), held) in enumerate(zip(part.layers, part.held)):
            n, ring = mesh.shape[a], periodic[a] and grid[a] > 1
            assert held == ((lo - halo, hi + halo) if ring else (max(lo - halo, 0), min(hi + halo, n)))
    scale = np.abs(want).max()
    got = []
    for part in parts:
        local = FlowSpace(part.mesh)
        assert part.mesh.periodic == tuple(p and g == 1 for p, g in zip(periodic, grid))
        shift = local.V.coordinates - whole.V.coordinates[part.nodes]  # a ring's halo: by the period
        periods = np.array(mesh.upper) - np.array(mesh.lower)
        assert np.allclose(np.round(shift / periods) * periods, shift)
        assert np.array_equal(part.local_nodes(part.nodes), np.arange(part.n_v))
        assert np.array_equal(part.local_cells(part.cells), np.arange(part.n_cells))
        v = apply_mass_laplace(local, 2.0, 0.3, u.reshape(dim, -1)[:, part.nodes].ravel(), convection=0.7)
        complete = np.unique(local.V.cell_dofs[part.owned_cells])
        assert np.allclose(v.reshape(dim, -1)[:, complete], want[:, part.nodes[complete]], rtol=0.0,
                           atol=1e-13 * scale)
        got.append(np.concatenate([v, np.zeros(part.n_cells * (dim + 1))]))
    _exchange(parts, got, "update_ghosts")
    for part, v in zip(parts, got):
        assert np.allclose(v[:dim * part.n_v].reshape(dim, -1), want[:, part.nodes], rtol=0.0,
                           atol=1e-13 * scale)
    n_whole = whole.n_u + whole.n_p
    owned = np.concatenate([part.unknowns_of_whole[part.owned] for part in parts])
    assert np.array_equal(np.sort(owned), np.arange(n_whole))
    ones = [np.ones(part.owned.size) for part in parts]
    _exchange(parts, ones, "add_ghosts")
    total = np.zeros(n_whole)
    for part, v in zip(parts, ones):
        assert np.all(v[~part.owned] == 0.0)
        np.add.at(total, part.unknowns_of_whole, v)
    copies = np.zeros(n_whole)
    for part in parts:
        np.add.at(copies, part.unknowns_of_whole, 1.0)
    assert np.array_equal(total, copies)  # every copy's one added to the owner's
    y = np.random.default_rng(4).standard_normal(n_whole)
    dots = [part.dot(part.local(y), part.local(y), SerialComm()) for part in parts]
    assert np.isclose(sum(dots), y @ y, rtol=1e-13)


class _Gathering:
    """Process ``rank``'s side of ``allgather`` among slabs held in one process: a first pass
    (``given`` None) records what each process gives (and hands it back as everyone's); a second
    hands every process the list of all."""

    def __init__(self, rank, size, given=None):
        self.rank, self.size, self.given = rank, size, given
        self.record = {}

    def allgather(self, value):
        self.record[self.rank] = value
        return [value] * self.size if self.given is None else [self.given[r] for r in range(self.size)]


@pytest.mark.parametrize("dim, grid, shape, periodic", [(2, (1, 3), None, (True, False)),
                                                         (3, (1, 1, 2), None, (True, False, False)),
                                                         (2, (1, 3), None, (True, True)),
                                                         (2, (2, 2), (8, 9), (True, False)),
                                                         (3, (2, 2, 2), (8, 6, 9), (False, False, True))])
def test_components_joined_over_blocks_are_the_whole_meshs(dim, grid, shape, periodic):
    """Connected components of random free nodes found on every block and joined
    (:meth:`~fbmflow.parallel.blocks.BlockPartition.join_components`) are the whole mesh's: every
    node's smallest node of its component, and all components with their node counts (which the
    closing of fluid pockets takes the largest of)."""
    mesh = _mesh(dim, shape=shape, periodic=periodic)
    size = int(np.prod(grid))
    whole = FlowSpace(mesh)
    free = np.random.default_rng(5).random(whole.n_v) < (0.2 if dim == 2 else 0.05)
    labels = whole.free_node_components(free)
    roots, sizes = np.unique(labels[free], return_counts=True)
    assert 3 < roots.size < free.sum() / 2  # components of many sizes, some across blocks
    parts = [BlockPartition(mesh, size, r, grid=grid) for r in range(size)]
    local = [FlowSpace(part.mesh).free_node_components(free[part.nodes]) for part in parts]
    given = {}
    for r, part in enumerate(parts):
        comm = _Gathering(r, size)
        part.join_components(local[r], comm)
        given.update(comm.record)
    for r, part in enumerate(parts):
        got, got_roots, got_sizes = part.join_components(local[r], _Gathering(r, size, given))
        assert np.array_equal(got, labels[part.nodes])
        assert np.array_equal(got_roots, roots) and np.array_equal(got_sizes, sizes)


def test_blocks_refuse_what_they_cannot_split():
    mesh = StructuredMesh.box((4, 5))
    with pytest.raises(ValueError, match="two cell layers each along axis 1"):
        BlockPartition(mesh, 3, 0)
    with pytest.raises(ValueError, match="periodic axis of 4 cell layers.*wrap onto itself"):
        BlockPartition(StructuredMesh.box((4, 4), periodic=(False, True)), 2, 0)
    with pytest.raises(ValueError, match="rank 2"):
        BlockPartition(mesh, 2, 2)
    with pytest.raises(ValueError, match="4 cell layers each \\(a halo of 3\\).* at most 1 process"):
        BlockPartition(mesh, 2, 0, halo=3)
    with pytest.raises(ValueError, match="periodic axis of 9 cell layers.*a halo of 3"):
        BlockPartition(_mesh(2, ring=True), 2, 0, halo=3)
    with pytest.raises(ValueError, match="two cell layers each along axis 0"):
        BlockPartition(mesh, 4, 0, grid=(4, 1))
    with pytest.raises(ValueError, match="grid \\(2, 2\\) of processes for 2 processes"):
        BlockPartition(mesh, 2, 0, grid=(2, 2))


def _mpiexec():
    pytest.importorskip("mpi4py")
    mpiexec = shutil.which("mpiexec", path=str(Path(sys.executable).parent)) or shutil.which("mpiexec")
    if mpiexec is None:
        pytest.skip("no mpiexec")
    return mpiexec


@pytest.mark.parametrize("dim, case, grid", [(2, "cavity", "1x4"), (2, "periodic", "1x4"),
                                             (2, "periodic", "2x2"), (3, "cavity", "2x1x2")])
def test_under_mpiexec_the_distributed_multigrid_solves_the_whole_system(dim, case, grid):
    """``mpiexec -n P``: the distributed multigrid's solution on every process's block equals
    the whole mesh's direct solution (owned unknowns and ghosts), in at most 1.3 times the cycles
    of one process (plus one), in a closed box and in a periodic one (the blocks rings), on slabs
    and on blocks in two directions; where the ``mpi`` extra is installed."""
    script = Path(__file__).with_name("_block_solve.py")
    size = int(np.prod([int(g) for g in grid.split("x")]))
    out = subprocess.run([_mpiexec(), "-n", str(size), sys.executable, str(script), str(dim), case, grid],
                         capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stdout + out.stderr
    chosen = str(tuple(int(g) for g in grid.split("x")))
    assert out.stdout.count(f" of {size}: {case} {dim}D, grid {chosen}") == size


def test_under_mpiexec_an_uncaught_exception_on_one_process_ends_every_process(tmp_path):
    """``mpiexec -n 2``: a script whose second process raises an exception no code catches, while
    the first waits for it in a barrier, ends with a non-zero status and the traceback (the
    processes aborted together) instead of hanging. Where the ``mpi`` extra is installed."""
    script = tmp_path / "bug.py"
    script.write_text("from fbmflow.parallel import world\n"
                      "comm = world()\n"
                      "if comm.rank == 1:\n"
                      "    raise ValueError('a bug on process 1')\n"
                      "comm.Barrier()\n"
                      "print('after the barrier')\n")
    out = subprocess.run([_mpiexec(), "-n", "2", sys.executable, str(script)], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode != 0
    assert "ValueError: a bug on process 1" in out.stderr
    assert "after the barrier" not in out.stdout


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


def _fbmflow(launcher, *args):
    """``fbmflow ARGS`` (under ``launcher``, e.g. ``mpiexec -n 2``), the completed process."""
    command = [*launcher, sys.executable, "-m", "fbmflow.cli", *args]
    return subprocess.run(command, capture_output=True, text=True, timeout=600)


def test_under_mpiexec_fbmflow_run_divides_a_particle_scene_and_resumes_on_other_process_counts(tmp_path):
    """``mpiexec -n 4 fbmflow run glowinski-free-fall`` (level 0, the sharp boundary, multigrid,
    the implicit coupling with the trapezoidal integrator, tolerances 1e-10), oversubscribed on
    two cores: the disk's positions and velocities in ``run.h5`` are one process's to 1e-8
    relative, in at most 1.3 times the cycles (plus one) per step; the output is written once,
    the progress printed once. Its checkpoint at step 2, resumed on one process, ends where the
    uninterrupted run ends. Under ``mpiexec -n 2`` a scene whose mesh cannot be divided (a
    suspension's, which does not coarsen) and a setting that does not run on several processes
    (the direct solver) stop both processes with one line and status 2. Where the ``mpi`` extra
    is installed."""
    import h5py

    mpiexec = [_mpiexec(), "-n", "2"]
    four = [_mpiexec(), "-n", "4"]  # oversubscribed on two cores: the answer, not the speed
    settings = ["solver.linear=multigrid", "time.dt=0.005", "time.t_end=0.02",
                "solver.newton_rtol=1e-10", "solver.linear_rtol=1e-10", "coupling.tol=1e-10"]  # the
    # solvers' stopping points (the coupling's 1e-6 by default) far below the 1e-8 compared
    run = ["run", "glowinski-free-fall", "--level", "0", "--no-plot", "--checkpoint-every", "2"]
    run += [a for s in settings for a in ("--set", s)]
    one = _fbmflow([], *run, "--out", str(tmp_path / "one"))
    assert one.returncode == 0, one.stderr
    two = _fbmflow(four, *run, "--out", str(tmp_path / "two"))
    assert two.returncode == 0, two.stderr
    assert two.stderr.count("fbmflow") == one.stderr.count("fbmflow")  # every line once
    summary = json.loads((tmp_path / "two" / "summary.json").read_text())
    assert summary["processes"] == 4 and summary["steps"] == 4
    with h5py.File(tmp_path / "one" / "run.h5") as f, h5py.File(tmp_path / "two" / "run.h5") as g:
        for key in ("position", "velocity"):
            assert f[key].shape == g[key].shape == (5, 1, 2)
            assert np.abs(g[key][:] - f[key][:]).max() <= 1e-8 * np.abs(f[key][:]).max()
        assert np.all(g["linear_iterations"][1:] <= 1.3 * f["linear_iterations"][1:] + 1)
    resumed = _fbmflow([], "resume", str(tmp_path / "two"), "--no-plot")  # from step 2, one process
    assert resumed.returncode == 0, resumed.stderr
    with h5py.File(tmp_path / "one" / "run.h5") as f, h5py.File(tmp_path / "two" / "run.h5") as g:
        assert np.abs(g["velocity"][:] - f["velocity"][:]).max() <= 1e-8 * np.abs(f["velocity"][:]).max()
    periodic = ["run", "suspension-2d", "--set", "solver.linear=multigrid", "--out", str(tmp_path / "c")]
    for args, what in ((periodic, "does not coarsen"),
                       (run[:2] + ["--set", "solver.linear=direct", "--out", str(tmp_path / "s")],
                        "solver.linear = 'multigrid'")):
        refused = _fbmflow(mpiexec, *args)
        assert refused.returncode == 2 and refused.stderr.count("fbmflow: error") == 1, refused.stderr
        assert what in refused.stderr and "Traceback" not in refused.stderr


def test_under_mpiexec_fbmflow_run_divides_a_steady_flow_scene(tmp_path):
    """``mpiexec -n 2 fbmflow run dfg-2d-1`` at level 3 (steady flow past a fixed cylinder with the
    sharp boundary, multigrid, Newton to 1e-10): the drag and lift measured on the gathered flow
    are one process's to 1e-8 of the drag, the summary names the whole mesh's cells and unknowns
    and the two processes. Where the ``mpi`` extra is installed."""
    run = ["run", "dfg-2d-1", "--level", "3", "--no-plot", "--set", "solver.linear=multigrid",
           "--set", "solver.newton_rtol=1e-10"]
    one = _fbmflow([], *run, "--out", str(tmp_path / "one"))
    assert one.returncode == 0, one.stderr
    two = _fbmflow([_mpiexec(), "-n", "2"], *run, "--out", str(tmp_path / "two"))
    assert two.returncode == 0, two.stderr
    a, b = (json.loads((tmp_path / d / "summary.json").read_text()) for d in ("one", "two"))
    assert b["processes"] == 2 and (b["n_cells"], b["n_dofs"]) == (a["n_cells"], a["n_dofs"])
    drag = a["quantities"]["drag_coefficient"]
    for key in ("drag_coefficient", "lift_coefficient"):
        assert abs(b["quantities"][key] - a["quantities"][key]) <= 1e-8 * drag, key


def test_under_mpiexec_taylor_green_on_a_ring_of_slabs_is_one_processs(tmp_path):
    """``mpiexec -n 2 fbmflow run taylor-green-2d`` (periodic along both axes: the two slabs a
    ring, neighbours across the periodic sides too): the error against the exact vortex and the
    kinetic energy of every step are one process's to 1e-8. Where the ``mpi`` extra is
    installed."""
    run = ["run", "taylor-green-2d", "--level", "1", "--no-plot", "--set", "solver.linear=multigrid",
           "--set", "solver.newton_rtol=1e-10", "--set", "time.t_end=0.125"]
    one = _fbmflow([], *run, "--out", str(tmp_path / "one"))
    assert one.returncode == 0, one.stderr
    two = _fbmflow([_mpiexec(), "-n", "2"], *run, "--out", str(tmp_path / "two"))
    assert two.returncode == 0, two.stderr
    a, b = (json.loads((tmp_path / d / "summary.json").read_text())["quantities"] for d in ("one", "two"))
    assert abs(b["velocity_l2_error"] - a["velocity_l2_error"]) <= 1e-8 * a["velocity_l2_error"]
    assert len(b["kinetic_energy"]) == 6
    assert np.allclose(b["kinetic_energy"], a["kinetic_energy"], rtol=1e-8, atol=0.0)


def _one_and_two(tmp_path, script: str, arguments, processes: int = 2) -> tuple:
    """The ``.npz`` the test script ``script`` writes run alone and under ``mpiexec -n
    processes`` (``arguments(out)``: its arguments for the output file ``out``), and what the
    processes printed."""
    runs, printed = {}, ""
    for size in (1, processes):
        launcher = [_mpiexec(), "-n", str(size)] if size > 1 else []
        out = subprocess.run(launcher + [sys.executable, str(Path(__file__).with_name(script)),
                                         *arguments(str(tmp_path / f"{size}.npz"))],
                             capture_output=True, text=True, timeout=600)
        assert out.returncode == 0, out.stdout + out.stderr
        runs[size], printed = np.load(tmp_path / f"{size}.npz"), out.stdout
    return runs[1], runs[processes], printed


def _assert_follows(one, two, processes: int = 2) -> None:
    """Several processes' particle positions and velocities one process's to 1e-8 relative, in
    at most 1.3 times its cycles per step (plus one)."""
    assert int(two["processes"]) == processes
    for key in ("position", "velocity"):
        assert np.abs(two[key] - one[key]).max() <= 1e-8 * np.abs(one[key]).max()
    assert np.abs(one["velocity"]).max() > 0.0
    assert np.all(two["cycles"] <= 1.3 * one["cycles"] + 1)


@pytest.mark.parametrize("boundary", ["nodes", "sharp"])
def test_under_mpiexec_particles_in_a_periodic_box_follow_one_processs_steps(tmp_path, boundary):
    """``mpiexec -n 2 python _slab_ring.py``: two disks in a box periodic along both axes with
    either boundary, one across the periodic sides (on the first and the last slab of the ring,
    through its images), both centred on mesh lines (nodes exactly on their surfaces; the first
    on a vertex, where the sharp boundary's halo cells extend the pressure unlike their owners,
    which stalled the solves while FGMRES's border direction was not made consistent), the
    mixture's mean flux removed (summed over the processes): two steps' positions and velocities
    those of one process to 1e-8 relative, in at most 1.3 times the cycles (plus one).
    Where the ``mpi`` extra is installed."""
    one, two, _ = _one_and_two(tmp_path, "_slab_ring.py", lambda out: ["2", out, boundary])
    _assert_follows(one, two)
    assert np.abs(two["mixture"]).max() <= 1e-12 * np.abs(one["velocity"]).max()  # the flux removed


def test_under_mpiexec_the_test_function_force_follows_one_process(tmp_path):
    """``mpiexec -n 2``: three steps of ``glowinski-free-fall`` at level 0 with the test-function
    force (its test function spans the cells around the disk, which one process holds where the
    other holds them as halo), positions and velocities those of one process to 1e-8 relative.
    Where the ``mpi`` extra is installed."""
    settings = ["fbm.force=test-function", "solver.linear=multigrid", "solver.newton_rtol=1e-10",
                "solver.linear_rtol=1e-10", "coupling.tol=1e-10"]
    one, two, _ = _one_and_two(tmp_path, "_slab_particles.py",
                               lambda out: ["glowinski-free-fall", "0", "3", out, *settings])
    _assert_follows(one, two)


def test_under_mpiexec_a_particle_across_blocks_in_two_directions_follows_one_process(tmp_path):
    """``mpiexec -n 4`` with ``solver.process_grid = 2x2``: two steps of ``glowinski-free-fall`` at
    level 1 (the sharp boundary, its halo of 4 layers), the disk centred on the cut between the
    blocks across x; positions and velocities those of one process to 1e-8 relative. Where the
    ``mpi`` extra is installed."""
    settings = ["solver.process_grid=2x2", "solver.linear=multigrid", "solver.newton_rtol=1e-10",
                "solver.linear_rtol=1e-10", "coupling.tol=1e-10"]
    one, four, _ = _one_and_two(tmp_path, "_slab_particles.py",
                                lambda out: ["glowinski-free-fall", "1", "2", out, *settings], processes=4)
    _assert_follows(one, four, processes=4)


def test_under_mpiexec_particles_in_hard_contact_follow_one_process(tmp_path):
    """``mpiexec -n 2``: two steps of ``sedimentation-2d`` at level 0 with 12 disks, whose lattice
    gaps lie within the contact skin so that hard contact pushes them apart from the first step
    (the contact solver run alike on every process), positions and velocities those of one
    process to 1e-8 relative. Where the ``mpi`` extra is installed."""
    settings = ["particles.count=12", "solver.linear=multigrid", "solver.newton_rtol=1e-10",
                "solver.linear_rtol=1e-10", "coupling.flow_rtol=1e-10", "coupling.tol=1e-10"]
    one, two, _ = _one_and_two(tmp_path, "_slab_particles.py",
                               lambda out: ["sedimentation-2d", "0", "2", out, *settings])
    _assert_follows(one, two)


def test_under_mpiexec_ten_cate_follows_one_processs_step(tmp_path):
    """``mpiexec -n 2``: a step of ``ten-cate`` at level 0 at its defaults (3D, the sharp boundary
    with the surface force, multigrid, the implicit coupling; tolerances 1e-10), the sphere's
    position and velocity those of one process to 1e-8 relative, in at most 1.3 times the cycles
    (plus one); each process runs on its share of the cores. Where the ``mpi`` extra is
    installed."""
    from fbmflow._jit import max_threads
    from fbmflow.cores import usable_cpus

    settings = ["solver.newton_rtol=1e-10", "solver.linear_rtol=1e-10", "coupling.tol=1e-10"]
    one, two, printed = _one_and_two(tmp_path, "_slab_particles.py",
                                     lambda out: ["ten-cate", "0", "1", out, *settings])
    assert printed.count(" of 2: ten-cate") == 2
    if "NUMBA_NUM_THREADS" not in os.environ:
        share = max(1, min(max_threads(), len(usable_cpus()) // 2))
        # the two processes' lines may interleave: count the figures, not the lines
        assert re.findall(r"threads (\d+)", printed) == [str(share)] * 2, printed
    _assert_follows(one, two)


@pytest.mark.parametrize("dim, grid, ring", [(2, (1, 3), False), (3, (1, 1, 2), False), (2, (1, 3), True),
                                             (3, (1, 1, 2), True), (2, (2, 2), False), (3, (2, 1, 2), True)])
def test_sharp_boundary_rows_of_the_owned_unknowns_are_the_whole_meshs(dim, grid, ring):
    """The sharp boundary built on every block (slabs, and blocks in two directions) with a halo
    of :func:`~fbmflow.coupling.sharp.reach_layers` layers, balls across the blocks' boundaries: the
    ghost rows of the owned cells' nodes, the owned cut cells' continuity rows and pressure
    extensions are the whole mesh's (in global numbers), and no owned row reaches beyond the
    slab (:attr:`~fbmflow.coupling.sharp.GhostNodes.beyond`). The surface, volume and
    test-function forces of the owned cells (the last of a time step and of a change of a flow)
    summed over the slabs are the whole mesh's."""
    from fbmflow.coupling.forces import SurfaceForces, TestFunctionForces, volume_force_functional
    from fbmflow.coupling.indicator import node_owner
    from fbmflow.coupling.sharp import reach_layers, sharp_boundary
    from fbmflow.particles import Ball

    size = int(np.prod(grid))
    mesh = StructuredMesh.box((6 * grid[0],) + (6,) * (dim - 2) + (18,), upper=(1.0,) * (dim - 1) + (3.0,),
                              periodic=(False,) * (dim - 1) + (ring,))
    rng = np.random.default_rng(7)
    n = 4
    centres = np.column_stack([rng.uniform(0.3, 0.7, (n, dim - 1)),
                               np.linspace(0.05, 1.9, n) if ring else np.linspace(0.6, 2.4, n)])
    shapes = [Ball(r, dim=dim) for r in rng.uniform(0.17, 0.26, n)]
    whole = FlowSpace(mesh)
    ref = sharp_boundary(whole, node_owner(whole.V, centres, shapes), centres, shapes)
    ghost_row = {int(g): k for k, g in enumerate(ref.ghosts.nodes)}
    u, u_old, about = rng.standard_normal((3, whole.n_u))
    p = rng.standard_normal(whole.n_p)
    tested = TestFunctionForces(whole, node_owner(whole.V, centres, shapes), centres, shapes)
    want = [SurfaceForces(whole, centres, shapes)(u, p, 0.3),
            volume_force_functional(whole, node_owner(whole.V, centres, shapes), centres)(u, p, 0.3),
            tested(u, p, 0.3, 1.2, u_old=u_old, dt=0.01), tested(u, p, 0.3, 1.2, dt=0.01, about=about)]
    got = [np.zeros_like(w[0]) for w in want], [np.zeros_like(w[1]) for w in want]
    halo = reach_layers(mesh)
    npl = dim + 1
    for r in range(size):
        part = BlockPartition(mesh, size, r, halo=halo, grid=grid)
        local = FlowSpace(part.mesh)
        owner = node_owner(local.V, centres, shapes)
        sb = sharp_boundary(local, owner, centres, shapes, domain=mesh)
        inner = np.unique(local.V.cell_dofs[part.owned_cells])
        assert not np.isin(sb.ghosts.beyond, inner).any()
        mine = np.flatnonzero(np.isin(sb.ghosts.nodes, inner))
        assert mine.size > 0
        for k in mine:
            row = sb.ghosts.matrix.getrow(k)
            want_row = ref.ghosts.matrix.getrow(ghost_row[int(part.nodes[sb.ghosts.nodes[k]])])
            assert np.array_equal(np.sort(part.nodes[row.indices]), np.sort(want_row.indices))
            assert np.allclose(row.data[np.argsort(part.nodes[row.indices])],
                               want_row.data[np.argsort(want_row.indices)], rtol=0, atol=1e-14)
        cut = part.owned_cells[sb.continuity.cells]
        cells = part.cells[sb.continuity.cells[cut]]
        at = np.searchsorted(ref.continuity.cells, cells)
        assert np.array_equal(ref.continuity.cells[at], cells)
        assert cells.size == np.isin(ref.continuity.cells, part.cells[part.owned_cells]).sum() > 0
        # a row's columns: component-major, the cell's nodes in ascending order, local or global
        # (which differ at a ring's wrap)
        order = np.argsort(part.nodes[np.sort(local.V.cell_dofs[sb.continuity.cells[cut]], axis=1)], axis=1)
        nl = order.shape[1]
        data = sb.continuity.data[cut].reshape(cells.size, npl, dim, nl)
        data = np.take_along_axis(data, order[:, None, None, :], axis=3).reshape(cells.size, npl, dim * nl)
        assert np.allclose(data, ref.continuity.data[at], rtol=0, atol=1e-14)
        rows = sb.extension.dofs[part.owned_cells[sb.extension.dofs // npl]]
        E = sb.extension.matrix[rows].tocoo()
        W = ref.extension.matrix[part.cells[rows // npl] * npl + rows % npl].tocoo()
        assert rows.size > 0 and E.nnz == W.nnz
        assert sorted(zip(E.row, part.cells[E.col // npl] * npl + E.col % npl, np.round(E.data, 12))) == \
            sorted(zip(W.row, W.col, np.round(W.data, 12)))
        lu, lu_old, l_about = (v.reshape(dim, -1)[:, part.nodes].ravel() for v in (u, u_old, about))
        lp = p[(part.cells[:, None] * npl + np.arange(npl)).ravel()]
        spacing = float(mesh.finest_spacing.min())
        tested = TestFunctionForces(local, owner, centres, shapes, cells=part.owned_cells)
        parts = [SurfaceForces(local, centres, shapes, cells=part.owned_cells, spacing=spacing)(lu, lp, 0.3),
                 volume_force_functional(local, owner, centres, part.owned_cells)(lu, lp, 0.3),
                 tested(lu, lp, 0.3, 1.2, u_old=lu_old, dt=0.01),
                 tested(lu, lp, 0.3, 1.2, dt=0.01, about=l_about)]
        for i, (f, t) in enumerate(parts):
            got[0][i] += f
            got[1][i] += t
    for i, (f, t) in enumerate(want):
        assert np.allclose(got[0][i], f, rtol=1e-12, atol=1e-14 * np.abs(f).max())
        assert np.allclose(got[1][i], t, rtol=1e-12, atol=1e-14 * np.abs(t).max() + 1e-300)
    if dim == 2 and grid[0] == 1:  # a halo of one layer: an owned image point lies beyond it: the run stops
        from fbmflow.coupling.estimators import VolumeForce
        from fbmflow.coupling.system import ParticleGeometry
        from fbmflow.particles import Particles
        from fbmflow.solvers import ConvergenceError

        part = BlockPartition(mesh, size, 1, halo=1)
        geometry = ParticleGeometry(FlowSpace(part.mesh), Particles.at_rest(shapes, 2.0, centres), True,
                                    VolumeForce(), np.zeros(0, dtype=np.int64), part.owned_cells, mesh,
                                    SerialComm())
        with pytest.raises(ConvergenceError, match="beyond the halo") as err:
            geometry.sharp(geometry.space.V)
        assert "fbm.boundary = 'nodes'" in err.value.remedy


def test_solver_settings_on_several_processes_take_multigrid_and_refuse_the_direct_solver():
    from fbmflow.config import ParamError
    from fbmflow.solvers.settings import SolverParams

    auto = SolverParams()
    assert auto.on_processes(1) is auto
    assert auto.on_processes(4).linear == "multigrid"
    assert SolverParams(linear="direct").on_processes(1).linear == "direct"
    with pytest.raises(ParamError, match="direct solver runs on one process"):
        SolverParams(linear="direct").on_processes(2)


def test_block_levels_choose_the_grid_that_divides_most_levels_with_fewest_faces():
    """Slabs along the last axis on a long box (ten Cate's at level 1, 12 x 12 x 64 cells, on 2 and 4
    processes), blocks on a square (4 processes: 2 x 2) and on ten Cate's level-2 box on 16 with
    the sharp boundary's halo (1 x 2 x 8: 7 104 cell faces between the blocks, against 7 872 for
    2 x 2 x 4 and 8 640 for slabs); slabs where a grid
    ties (a square on 2); the grid asked for where given; ``solver.process_grid`` parsed and
    checked."""
    from types import SimpleNamespace

    from fbmflow.config import ParamError
    from fbmflow.flow.blocks import BlockFlowLevels
    from fbmflow.solvers.settings import SolverParams

    def chosen(shape, size, **kwargs):
        mesh = StructuredMesh.box(shape)
        return BlockFlowLevels(mesh, {}, True, SimpleNamespace(size=size, rank=0), **kwargs).grid

    assert chosen((12, 12, 64), 2) == (1, 1, 2) and chosen((12, 12, 64), 4) == (1, 1, 4)
    assert chosen((16, 16), 4) == (2, 2) and chosen((16, 16), 2) == (1, 2)
    assert chosen((24, 24, 128), 16, halo=4) == (1, 2, 8)
    assert chosen((16, 16), 4, grid=(4, 1)) == (4, 1)
    with pytest.raises(ValueError, match="a grid \\(8, 1\\) of processes needs two cell layers each"):
        chosen((8, 8), 8, grid=(8, 1))
    assert SolverParams(process_grid="2x1x2").grid(4, 3) == (2, 1, 2)
    assert SolverParams(process_grid="2x2").grid(1, 2) is None  # one process: no grid
    for bad in ("3x2", "2x2x1", "two"):
        with pytest.raises(ParamError, match="not a grid of 4 processes over the mesh's 2 axes.*as 1x4"):
            SolverParams(process_grid=bad).grid(4, 2)


def test_block_levels_refuse_a_mesh_too_thin_for_the_processes():
    """4 layers along the last axis cannot hold two slabs with the sharp boundary's halo of 4 on a
    level above the coarsest (dfg-3d-1z at level 2): the message says to run on one process. A
    mesh that does not coarsen (a suspension's odd cell count) has no level to divide either."""
    from types import SimpleNamespace

    from fbmflow.flow.blocks import BlockFlowLevels

    mesh = StructuredMesh.box((8, 4, 4))
    with pytest.raises(ValueError, match="5 cell layers each \\(a halo of 4\\).*run it on one process"):
        BlockFlowLevels(mesh, {}, True, SimpleNamespace(size=2, rank=0), halo=4)
    odd = StructuredMesh.box((45, 45), periodic=(True, True))
    with pytest.raises(ValueError, match="does not coarsen.*run it on one process or on a mesh with even"):
        BlockFlowLevels(odd, {}, True, SimpleNamespace(size=2, rank=0), halo=4)
