"""The GPU's launches pass CuPy arrays as numba-cuda's device arrays made without a stream
synchronisation (:func:`fbmflow.gpu.device.launch_view`), those a smoother sweeps with every time
made once. No GPU here: a stand-in CuPy (its ``ndarray`` a NumPy subclass) and stand-in kernels
that record what a launch passes them."""
import sys
import types

import numpy as np
import pytest
from sharp_disk import sharp_disk_problem

from fbmflow.mesh import StructuredMesh
from fbmflow.solvers.vanka import FactoredVankaSmoother


class FakeCupyArray(np.ndarray):
    """Stands in for a CuPy array: what a launch must not be passed."""


def fake(a):
    return np.asarray(a).view(FakeCupyArray)


class Recorder:
    """A stand-in kernel: ``kernel[grid, block](*args)`` records ``args``."""

    def __init__(self):
        self.calls = []

    def __getitem__(self, config):
        return lambda *args: self.calls.append(args)


@pytest.fixture
def fake_cupy(monkeypatch):
    """CuPy as a module whose ``ndarray`` is :class:`FakeCupyArray`, numba-cuda's ``as_cuda_array``
    recording its ``sync`` and returning a plain NumPy view, and recording stand-ins for the kernels
    a smoother, a space and the coefficients launch; returns the record."""
    from fbmflow._jit import cuda_target
    from fbmflow.gpu import _kernels

    record = {"sync": [], "kernels": {}}
    monkeypatch.setitem(sys.modules, "cupy", types.SimpleNamespace(ndarray=FakeCupyArray))

    def as_cuda_array(a, sync=True):
        record["sync"].append(sync)
        return a.view(np.ndarray)

    monkeypatch.setattr(cuda_target(), "as_cuda_array", as_cuda_array)
    for name in ("vanka_sweep", "vanka_patches", "vanka_factors", "velocity_rows", "reaction_rows",
                 "apply_cells_sweep", "apply_cells"):
        record["kernels"][name] = Recorder()
        monkeypatch.setattr(_kernels, name, record["kernels"][name])
    return record


def fake_backend():
    """A backend of stand-in CuPy arrays (NumPy's underneath)."""
    from fbmflow.gpu.device import Backend

    xp = types.SimpleNamespace(empty=lambda *a, **k: fake(np.empty(*a, **k)),
                               zeros=lambda *a, **k: fake(np.zeros(*a, **k)))
    backend = Backend(xp, None, "stand-in", 128, 32)
    backend.put = lambda a, dtype=None: fake(np.array(a, dtype=dtype))
    return backend


def passed_arrays(recorder):
    return [a for args in recorder.calls for a in args if isinstance(a, np.ndarray)]


@pytest.mark.parametrize("one_launch", [True, False])
def test_a_smoothers_launches_pass_views_made_once_without_a_sync(fake_cupy, monkeypatch, one_launch):
    """A :class:`~fbmflow.gpu.vanka.DeviceVanka` on a backend of (stand-in) CuPy arrays factors and
    sweeps (a sharp disk's system: the cells', the interface's and the agglomerated patches'
    colours): every array its launches pass is a view (no CuPy array reaches a kernel), every view
    was made with ``sync=False``, and a sweep makes views of its two vectors only (the patches,
    factors, operator and work arrays were made views at set-up), in one launch per sweep and in
    one launch per colour. Checked to fail with the launches passing CuPy's arrays."""
    from fbmflow.gpu import colours
    from fbmflow.gpu.vanka import DeviceVanka

    prob, con = sharp_disk_problem(StructuredMesh.box((12, 12)), [0.513, 0.521], 0.3)
    system = prob.linear_system(prob.zero_state(), 100.0, 1.0, con)
    system = system.preconditioner or system
    backend = fake_backend()
    monkeypatch.setattr(colours, "ONE_LAUNCH", one_launch)
    monkeypatch.setattr(colours.DeviceColours, "_cooperative_blocks", lambda self, sweep, threads, args: 1)
    smoother = DeviceVanka(FactoredVankaSmoother(system, order="colours", factor=False), backend)
    kernels = fake_cupy["kernels"]
    assert kernels["vanka_factors"].calls
    made = len(fake_cupy["sync"])
    n = system.n_u + system.n_p
    smoother.smooth(fake(np.ones(n)), fake(np.zeros(n)), 1)
    swept = [c for c in [smoother.sweeps[0]] + [smoother.interface] * smoother.interface_sweeps
             + [smoother.merged] if c.largest]
    launches = kernels["vanka_sweep" if one_launch else "vanka_patches"].calls
    assert len(swept) == 2 + smoother.interface_sweeps
    assert len(launches) == (len(swept) if one_launch else sum(len(c) for c in swept))
    assert not kernels["vanka_patches" if one_launch else "vanka_sweep"].calls
    arrays = passed_arrays(kernels["vanka_factors"]) + passed_arrays(kernels["vanka_sweep"]) \
        + passed_arrays(kernels["vanka_patches"])
    assert arrays and not any(isinstance(a, FakeCupyArray) for a in arrays)
    assert not any(fake_cupy["sync"])
    assert len(fake_cupy["sync"]) - made == 2 * len(swept)  # b and x, once per sweep's colours


def test_a_spaces_operator_passes_its_cells_as_views_made_once(fake_cupy, monkeypatch):
    """A :class:`~fbmflow.gpu.space.DeviceSpace` holds its cells' geometry as views (made once,
    with ``sync=False``): its operator's launch is passed no CuPy array and makes views of its two
    vectors only."""
    from fbmflow.fem import FlowSpace
    from fbmflow.gpu import colours, operators
    from fbmflow.gpu.space import DeviceSpace

    monkeypatch.setattr(colours.DeviceColours, "_cooperative_blocks", lambda self, sweep, threads, args: 1)
    monkeypatch.setattr(operators, "_no_convection", lambda: np.zeros((1, 1, 1)))  # numba-cuda's, no GPU here
    space = DeviceSpace(FlowSpace(StructuredMesh.box((3, 3, 2))), fake_backend())
    assert not any(isinstance(a, FakeCupyArray) for a in space.geometry)
    made = len(fake_cupy["sync"])
    space.apply_mass_laplace(1.0, 0.5, np.ones(space.dim * space.n_v))
    launches = fake_cupy["kernels"]["apply_cells_sweep"].calls
    assert len(launches) == 1 and not any(isinstance(a, FakeCupyArray) for a in launches[0])
    assert len(fake_cupy["sync"]) - made == 2 and not any(fake_cupy["sync"])


def test_the_coefficients_launches_pass_views_and_numpy_arrays_pass_as_they_are(fake_cupy):
    """The Newton term's and the convection's coefficient kernels are passed views of CuPy arrays
    (made with ``sync=False``); a NumPy array (the simulator's backend) passes unchanged."""
    from fbmflow.gpu.device import launch_view
    from fbmflow.gpu.operators import reaction_coefficients, velocity_coefficients

    arrays = [fake(np.zeros(3)) for _ in range(7)]
    velocity_coefficients(*arrays[:5])
    reaction_coefficients(*arrays)
    kernels = fake_cupy["kernels"]
    passed = passed_arrays(kernels["velocity_rows"]) + passed_arrays(kernels["reaction_rows"])
    assert len(passed) == 12 and not any(isinstance(a, FakeCupyArray) for a in passed)
    assert fake_cupy["sync"] == [False] * 12
    plain = np.zeros(3)
    assert launch_view(plain) is plain and len(fake_cupy["sync"]) == 12
