"""Fuzzed runs: random placements of mixed shapes, random scene parameters and random signal times
through short runs end in one of the documented ways, never in a traceback, a particle outside the
domain with exit 0, or a summary.json that is not JSON.

Derandomised (the same examples on every run, so CI is reproducible); ``--hypothesis-seed`` and a
larger ``max_examples`` explore further.
"""
import json
import signal

import h5py
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import fbmflow as fb
from fbmflow.cli import main
from fbmflow.solvers import ConvergenceError

#: exit statuses the command line documents: done, failed (a remedy named), refused input,
#: stopped by a signal (128 + the signal)
EXIT = {0, 1, 2, 128 + signal.SIGINT, 128 + signal.SIGTERM, 128 + signal.SIGHUP}
FUZZ = settings(max_examples=12, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])

shape = st.one_of(
    st.builds(lambda r: fb.Ball(r, 2), st.floats(0.04, 0.3)),
    st.builds(lambda a, b: fb.Box((a, b)), st.floats(0.04, 0.25), st.floats(0.04, 0.25)),
    st.builds(lambda a, b: fb.Ellipsoid((a, b)), st.floats(0.04, 0.25), st.floats(0.04, 0.25)),
)


@FUZZ
@given(shapes=st.lists(shape, min_size=1, max_size=3),
       xy=st.lists(st.tuples(st.floats(0.05, 0.95), st.floats(0.1, 1.9)), min_size=3, max_size=3),
       density=st.floats(0.3, 5.0), dt=st.sampled_from([0.002, 0.01, 0.05]),
       contact=st.booleans())
def test_random_placements_run_or_are_refused_cleanly(shapes, xy, density, dt, contact):
    mesh = fb.StructuredMesh.box((8, 16), upper=(1.0, 2.0))
    fluid = fb.FluidParams(density=1.0, viscosity=0.1, gravity=980.0)
    try:
        particles = fb.Particles.at_rest(shapes, density, xy[:len(shapes)])
        sim = fb.Simulation(mesh, particles, fluid, time=fb.TimeParams(dt=dt, t_end=3 * dt),
                            coupling=fb.CouplingParams(scheme="implicit"),
                            fbm=fb.FictitiousBoundaryParams(boundary="nodes"),
                            contact=fb.ContactParams(enabled=contact), repulsion=fb.RepulsionParams())
    except ValueError as err:  # ParamError included: refused, with one line that says why
        assert str(err) and "\n" not in str(err)
        return
    try:
        sim.run()
    except ConvergenceError as err:
        assert err.remedy, err
        return
    R = sim.particles.bounding_radius[:, None]
    X = sim.particles.position
    assert np.all(X > -0.5 * R) and np.all(X < np.array([1.0, 2.0]) + 0.5 * R), X


SCENES = {
    "glowinski-free-fall": {"particle.density": st.floats(0.2, 200.0), "time.dt": st.floats(1e-4, 0.2),
                            "fluid.viscosity": st.floats(1e-3, 10.0)},
    "sedimentation-2d": {"particles.count": st.integers(1, 12), "particles.density": st.floats(0.5, 20.0),
                         "time.dt": st.floats(1e-3, 0.05)},
    "dkt-2d": {"time.dt": st.floats(1e-3, 0.05)},
}


@st.composite
def scene_run(draw):
    name = draw(st.sampled_from(sorted(SCENES)))
    keys = draw(st.lists(st.sampled_from(sorted(SCENES[name])), unique=True, max_size=3))
    overrides = [f"{k}={draw(SCENES[name][k])}" for k in keys]
    return name, overrides, draw(st.sampled_from([None, 1, 2]))


@FUZZ
@given(run=scene_run())
def test_random_scene_runs_end_as_documented(run, tmp_path_factory, capsys, monkeypatch):
    """Short runs at level 0 with random parameters and a random step (or none) at which SIGTERM
    asks them to stop: an exit status of the documented set, one line on stderr for any but 0, a
    summary.json that is strict JSON, every particle inside the box."""
    from fbmflow import interrupt
    from fbmflow.scenes import load_scene

    name, overrides, stop_at = run
    monkeypatch.undo()  # the last example's signal
    out = tmp_path_factory.mktemp("fuzz")
    if stop_at is not None:  # SIGTERM arrives in step ``stop_at`` (the run loop asks once a step)
        asked = []
        monkeypatch.setattr(interrupt, "requested",
                            lambda: signal.SIGTERM if asked.append(1) or len(asked) >= stop_at else None)
    argv = ["run", name, "--level", "0", "--quiet", "--no-plot", "--set", "time.t_end=0.02", "--out",
            str(out), "--checkpoint-every", "1"]
    for item in overrides:
        argv += ["--set", item]
    code = main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert code in EXIT, (code, err)
    assert "Traceback" not in "\n".join(err)
    if code != 0:
        assert err and err[-1].startswith("fbmflow: "), err
        return
    json.loads((out / "summary.json").read_text(), parse_constant=pytest.fail)  # NaN is no JSON
    scene, params, _ = load_scene(name, 0, overrides + ["time.t_end=0.02"])
    mesh = scene.layout(params, 0).mesh
    with h5py.File(out / "run.h5") as f:
        X = f["position"][-1]
    assert np.all(X > mesh.lower) and np.all(X < mesh.upper), X
