"""Asking for the GPU: clear errors before any work (no GPU, no ``gpu`` extra, settings the GPU
solver cannot take, a problem too large for the device)."""
import subprocess
import sys

import pytest

from fbmflow.config import ParamError
from fbmflow.gpu.device import gpu_problem
from fbmflow.solvers.choice import InsufficientMemory
from fbmflow.solvers.settings import SolverParams


@pytest.mark.skipif(gpu_problem() is None, reason="a GPU and the gpu extra are here: the run would start")
def test_asking_for_the_gpu_without_one_stops_before_any_work_with_one_line(tmp_path):
    """``fbmflow run cavity-2d --set solver.device=gpu`` on a machine without a GPU or without the
    ``gpu`` extra: exit code 2, one line that names the setting and the fix, no results."""
    out = subprocess.run([sys.executable, "-m", "fbmflow.cli", "run", "cavity-2d", "--level", "1", "--set",
                          "solver.device=gpu", "--out", str(tmp_path / "run"), "--no-plot"],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 2, out.stderr
    errors = [line for line in out.stderr.splitlines() if line.startswith("fbmflow: error:")]
    assert len(errors) == 1 and "solver.device = 'gpu'" in errors[0] and "solver.device = 'cpu'" in errors[0]
    assert ("gpu extra" in errors[0]) != ("no CUDA GPU" in errors[0])
    assert not (tmp_path / "run" / "summary.json").exists()


@pytest.mark.parametrize("settings, words", [
    (dict(linear="direct"), "not the direct solver"),
    (dict(multigrid={"smoother": "vanka-full"}), "smoothes with vanka-factored"),
])
def test_settings_the_gpu_solver_cannot_take_are_refused(settings, words):
    from fbmflow.config import from_dict
    with pytest.raises(ParamError, match=words):
        from_dict(SolverParams, dict(settings, device="gpu"))


def test_the_gpu_runs_on_one_process():
    with pytest.raises(ParamError, match="runs on one process"):
        SolverParams(device="gpu").on_processes(2)
    assert SolverParams(device="gpu").on_processes(1).device == "gpu"


def test_a_problem_larger_than_the_free_device_memory_is_refused_with_the_figures(monkeypatch):
    """:func:`fbmflow.gpu.gpu_solver` on a device with 2 GB free: a 3D problem of 10 million
    unknowns is refused naming the need, the free memory and the remedies; 100 000 pass."""
    import fbmflow.gpu.multigrid as gm
    from fbmflow.gpu.device import simulated_backend

    def small():
        backend = simulated_backend()
        backend.free_bytes = lambda: 2 * 10**9
        return backend

    monkeypatch.setattr(gm, "gpu_problem", lambda: None)
    monkeypatch.setattr(gm, "gpu_backend", small)
    linear = SolverParams(device="gpu").linear_solver(3, 100_000)
    assert isinstance(gm.gpu_solver(linear, 3, 100_000), gm.DeviceMultigridSolver)
    with pytest.raises(InsufficientMemory, match=r"needs about \d+\.\d GB of device memory for 10000000 "
                       r"unknowns.*2\.0 GB free on the GPU.*a lower --level"):
        gm.gpu_solver(linear, 3, 10_000_000)


def test_the_gpu_running_out_of_memory_fails_the_step_with_the_remedy_and_no_retry():
    """Where the device's memory runs out during a run (its array module raising ``MemoryError``
    or CuPy's ``OutOfMemoryError``): a :class:`~fbmflow.gpu.device.DeviceMemoryError`, which the
    run treats as a failed step (a ConvergenceError: the last good state kept, a remedy printed)
    but the adaptive step control does not retry with a shorter step; when the mesh's cells are
    copied and when a hierarchy is set up."""
    from fbmflow.flow import NavierStokesProblem, NoSlip
    from fbmflow.gpu.device import DeviceMemoryError, simulated_backend
    from fbmflow.gpu.multigrid import DeviceMultigridSolver
    from fbmflow.mesh import StructuredMesh
    from fbmflow.solvers import ConvergenceError, MultigridSolver

    backend = simulated_backend()
    backend.free_bytes = lambda: 3 * 10**9

    def full(a, dtype=None):
        raise MemoryError("Out of memory allocating 1,024 bytes")

    backend.put = full
    mesh = StructuredMesh.box((4, 4))
    with pytest.raises(DeviceMemoryError, match=r"ran out of memory copying the mesh's cells \(Out of memory "
                       r"allocating 1,024 bytes; 3\.0 GB free now\)") as err:
        NavierStokesProblem(mesh, 0.01, {t: NoSlip() for t in mesh.tags},
                            linear_solver=DeviceMultigridSolver(backend=backend), coarse_cells=2)
    assert isinstance(err.value, ConvergenceError) and not err.value.retry
    assert "a lower --level" in err.value.remedy and "solver.device = 'cpu'" in err.value.remedy
    prob = NavierStokesProblem(mesh, 0.01, {t: NoSlip() for t in mesh.tags}, linear_solver=MultigridSolver(),
                               coarse_cells=2)
    system = prob.linear_system(prob.zero_state(), 100.0, 1.0, prob.constraints())
    with pytest.raises(DeviceMemoryError, match="setting up the multigrid hierarchy") as err:
        DeviceMultigridSolver(backend=backend).factor(system)
    assert not err.value.with_remedy("another remedy", "step 3: ").retry  # (how a step adds its place)
    with pytest.raises(ValueError, match="not the device's"):  # another error passes as it is
        with backend.memory_guard("doing nothing"):
            raise ValueError("not the device's")
