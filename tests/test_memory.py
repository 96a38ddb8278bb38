"""The memory guard: an estimate of the linear solver's memory before the first solve, a refusal
with the figure and a remedy when it exceeds the available memory, a warning above half of it."""
import logging

import pytest

import fbmflow.solvers.choice as choice
from fbmflow.cli import main
from fbmflow.mesh import StructuredMesh
from fbmflow.params import FluidParams
from fbmflow.particles import Ball, Particles
from fbmflow.simulation import Simulation
from fbmflow.solvers.choice import InsufficientMemory, available_memory, estimate_memory
from fbmflow.solvers.settings import SolverParams

#: peak resident sets of whole runs (two or three steps, or a steady solve) [GB]: (unknowns, dim,
#: engine, measured)
MEASURED = [(17_106, 2, "superlu", 0.33), (52_818, 2, "pardiso", 0.55), (164_946, 2, "pardiso", 1.30),
            (544_674, 2, "pardiso", 3.60), (164_946, 2, "multigrid", 0.81), (32_707, 3, "pardiso", 1.22),
            (32_707, 3, "superlu", 0.91), (64_547, 3, "pardiso", 2.0), (278_739, 3, "pardiso", 10.3),
            (64_547, 3, "multigrid", 0.8), (278_739, 3, "multigrid", 1.44), (486_979, 3, "multigrid", 3.4),
            (2_012_403, 3, "multigrid", 8.9), (164_946, 2, "superlu", 1.52)]
#: the same for a particle scene's time steps with multigrid, the largest peaks measured since
#: the model's last fit (ten-cate level 0, one step, python -m fbmbench memory_model, commit
#: a1bb209; levels 1 and 2 at 28462f9, 2026-11-29: level 1 the largest of one step, memory_model,
#: and of three, thread_scaling; level 2 one step, memory_model; level 3 one step and the spheres
#: two at 114f0e2, unguarded_steps, the guard's refusal logged only:
#: docs/validation/multigrid-with-fictitious-boundaries.md, "Memory")
TRANSIENT = [(64_547, 3, "multigrid", 0.38), (278_739, 3, "multigrid", 0.73),
             (2_012_403, 3, "multigrid", 2.67), (10_024_003, 3, "multigrid", 10.97),
             (15_789_027, 3, "multigrid", 19.60)]


@pytest.mark.parametrize("n, dim, engine, measured", MEASURED)
def test_the_estimate_is_conservative_but_not_wild(n, dim, engine, measured):
    """Against the runs it was fitted to: above the measured peak, by less than 70 %."""
    need, words = estimate_memory(n, dim, engine)
    assert measured * 1e9 <= need <= 1.7 * measured * 1e9, (need / 1e9, words)
    assert words == choice.ENGINE_NAMES[engine]


@pytest.mark.parametrize("n, dim, engine, measured", TRANSIENT)
def test_the_time_step_estimate_is_conservative_but_not_wild(n, dim, engine, measured):
    """A particle scene's time steps need less than a steady Newton solve of the same size; the
    estimate for them is still above the measured peak, by less than 70 %."""
    need, _ = estimate_memory(n, dim, engine, transient=True)
    assert measured * 1e9 <= need <= 1.7 * measured * 1e9, need / 1e9
    assert need < estimate_memory(n, dim, engine)[0]


@pytest.mark.parametrize("installed", [True, False])
def test_the_direct_solver_is_estimated_with_the_backend_it_would_take(installed, monkeypatch):
    """``"direct"`` is PARDISO where installed (for 3D and large 2D systems), else SuperLU."""
    from fbmflow.solvers import direct

    monkeypatch.setattr(direct, "pardiso_available", lambda: installed)
    engine = "pardiso" if installed else "superlu"
    assert estimate_memory(64_547, 3, "direct") == estimate_memory(64_547, 3, engine)
    assert estimate_memory(64_547, 3, direct.DirectSolver()) == estimate_memory(64_547, 3, engine)


def test_available_memory_reads_meminfo_and_gives_none_without_it(tmp_path):
    info = tmp_path / "meminfo"
    info.write_text("MemTotal:       24684096 kB\nMemAvailable:    2000000 kB\n")
    assert available_memory(info) == 2000000 * 1024.0
    info.write_text("MemTotal:       24684096 kB\n")
    assert available_memory(info) is None
    assert available_memory(tmp_path / "missing") is None


def _disk_sim(solver="direct"):
    mesh = StructuredMesh.box((8, 24), upper=(2.0, 6.0))
    return Simulation(mesh, Particles.at_rest([Ball(0.25, 2)], 1.25, [[1.0, 4.0]]), FluidParams(),
                      solver=SolverParams(linear=solver))


def test_a_run_larger_than_the_available_memory_is_refused(monkeypatch):
    """Before: a MemoryError traceback from the factorisation, or the out-of-memory killer."""
    monkeypatch.setattr(choice, "available_memory", lambda: 1e8)
    with pytest.raises(InsufficientMemory, match=r"the direct solver \(SuperLU\) needs about 0\.4 GB for "
                                                 r"2242 unknowns \(2D\), more than the 0\.1 GB available; "
                                                 r"use a coarser mesh \(a lower --level\) or solver.linear = "
                                                 r"multigrid"):
        _disk_sim()
    with pytest.raises(InsufficientMemory, match=r"multigrid needs about .*; use a coarser mesh \(a lower "
                                                 r"--level\)$"):
        _disk_sim("multigrid")


def test_a_run_above_half_the_available_memory_warns(monkeypatch, caplog):
    need, _ = estimate_memory(2242, 2, "direct")
    monkeypatch.setattr(choice, "available_memory", lambda: 1.5 * need)
    with caplog.at_level(logging.WARNING, logger="fbmflow.simulation"):
        _disk_sim()
    assert any("more than half of the" in r.getMessage() for r in caplog.records)
    caplog.clear()
    monkeypatch.setattr(choice, "available_memory", lambda: 3.0 * need)
    with caplog.at_level(logging.WARNING, logger="fbmflow.simulation"):
        _disk_sim()
    assert not caplog.records


def test_a_particle_scene_s_mesh_is_checked_with_the_time_step_model(monkeypatch, caplog):
    """sedimentation-3d with 1 000 spheres at level 2 (10.0 M unknowns): its time steps need
    11.0 GB (docs/validation/many-particles.md); the steady model's 65.6 GB refused it on a 24 GB
    machine before the mesh was made."""
    from fbmflow.fem import FlowSpace
    from fbmflow.scenes.builder import check_mesh_size

    shape = (56, 56, 112)
    n = FlowSpace.count_dofs(shape)
    transient, _ = estimate_memory(n, 3, "multigrid", transient=True)
    steady, _ = estimate_memory(n, 3, "multigrid")
    assert transient < 23e9 < steady
    monkeypatch.setattr(choice, "available_memory", lambda: 23e9)
    with caplog.at_level(logging.WARNING):
        check_mesh_size(shape, None, 3, "particles.count")
    assert not caplog.records  # more than half the memory: the run's own check says so, once
    monkeypatch.setattr(choice, "available_memory", lambda: 0.9 * transient)
    with pytest.raises(Exception, match="particles.count asks for a mesh of 56 x 56 x 112 cells"):
        check_mesh_size(shape, None, 3, "particles.count")


@pytest.mark.parametrize("scene", ["glowinski-free-fall", "cavity-2d"])
def test_the_command_line_refuses_with_exit_2_and_one_line(scene, monkeypatch, capsys, tmp_path):
    """Time-dependent and steady scenes alike, before the first solve."""
    monkeypatch.setattr(choice, "available_memory", lambda: 1e8)
    assert main(["run", scene, "--level", "0", "--out", str(tmp_path), "--quiet", "--no-plot"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "GB available; use a coarser mesh (a lower --level)" in err[0], err


def test_the_implicit_coupling_s_responses_count_and_are_refused_with_a_remedy(monkeypatch):
    """2000 disks at sedimentation-2d's default level: 6000 responses of 2.1 M unknowns (about
    1 TB) ended in a NumPy MemoryError in the first step; now refused before it, and the
    explicit, stabilised and Newton-Krylov couplings, which keep none, are not."""
    from fbmflow.coupling.settings import CouplingParams

    need, _ = estimate_memory(2242, 2, "direct")
    three = choice.RESPONSE_BYTES * 2242 * 3  # one disk's responses
    monkeypatch.setattr(choice, "available_memory", lambda: need + 1.5 * three)
    mesh = StructuredMesh.box((8, 24), upper=(2.0, 6.0))
    disks = Particles.at_rest([Ball(0.25, 2)] * 2, 1.25, [[0.5, 4.0], [1.5, 4.0]])
    with pytest.raises(InsufficientMemory, match=r"implicit coupling's responses to 6 rigid-body velocity "
                                                 r"components need about .* coupling.scheme = stabilised"):
        Simulation(mesh, disks, FluidParams(), coupling=CouplingParams(scheme="implicit"))
    for scheme in ("explicit", "stabilised", "newton-krylov"):
        Simulation(mesh, disks, FluidParams(), coupling=CouplingParams(scheme=scheme))
    one = Particles.at_rest([Ball(0.25, 2)], 1.25, [[1.0, 4.0]])
    Simulation(mesh, one, FluidParams(), coupling=CouplingParams(scheme="implicit"))  # 3 fit


def test_the_address_space_limit_and_the_cgroup_limit_count(tmp_path, monkeypatch):
    """What a batch scheduler sets (``ulimit -v``, a cgroup) bounds the memory available, not only
    the machine's free memory (before: a MemoryError traceback under ``ulimit -v 4000000``)."""
    import resource

    status = tmp_path / "status"
    status.write_text("VmSize:  1000000 kB\n")
    monkeypatch.setattr(resource, "getrlimit", lambda which: (4_000_000 * 1024, resource.RLIM_INFINITY))
    assert choice.address_space_left(status) == (4_000_000 - 1_000_000) * 1024.0
    monkeypatch.setattr(resource, "getrlimit", lambda which: (resource.RLIM_INFINITY, resource.RLIM_INFINITY))
    assert choice.address_space_left(status) is None
    cgroup = tmp_path / "cgroup"
    cgroup.mkdir()
    (cgroup / "memory.max").write_text("2000000000\n")
    (cgroup / "memory.current").write_text("500000000\n")
    assert choice.cgroup_left(cgroup) == 1.5e9
    (cgroup / "memory.max").write_text("max\n")
    assert choice.cgroup_left(cgroup) is None
    info = tmp_path / "meminfo"
    info.write_text("MemAvailable:    9000000 kB\n")
    monkeypatch.setattr(choice, "cgroup_left", lambda: 1.5e9)
    assert available_memory(info) == 1.5e9  # the least of the three
