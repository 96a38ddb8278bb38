"""The typed Python API: sections checked when made, registries behind the choices, a simulation
built, stepped and read through public names only."""
import re

import numpy as np
import pytest

import fbmflow as fb
from fbmflow.config import derive, tree


def test_sections_check_their_values_when_made():
    with pytest.raises(fb.ParamError, match=r"FluidParams.viscosity: must be positive, got -1.0"):
        fb.FluidParams(viscosity=-1.0)
    with pytest.raises(fb.ParamError, match=r"TimeParams.scheme: 'euler' is not allowed; choose one of"):
        fb.TimeParams(scheme="euler")
    assert fb.TimeParams(dt=1).dt == 1.0 and isinstance(fb.TimeParams(dt=1).dt, float)
    with pytest.raises(fb.ParamError, match="expected a number"):
        fb.FluidParams(density="water")


def test_derive_changes_defaults_and_keeps_the_rest():
    Slow = derive(fb.TimeParams, "Slow", "Slow time stepping.", dt=0.5)
    assert Slow() == Slow(dt=0.5, t_end=1.0, scheme="fractional-step-theta")
    assert issubclass(Slow, fb.TimeParams)
    assert Slow.__dataclass_fields__["dt"].metadata["doc"] == "time step"
    with pytest.raises(fb.ParamError, match="must be positive"):
        Slow(dt=0.0)
    with pytest.raises(ValueError, match="TimeParams has no field 'dtt'"):
        derive(fb.TimeParams, "Bad", "", dtt=0.5)
    Both = tree("Both", "Two sections.", fluid=fb.FluidParams, time=Slow)
    assert fb.from_dict(Both, {"time": {"t_end": 2}}).time == Slow(t_end=2.0)


@pytest.mark.parametrize("registry, key", [(fb.COUPLINGS, "scheme"), (fb.FORCE_ESTIMATORS, "force")])
def test_the_registries_are_the_parameter_choices(registry, key):
    """Every registered name is a choice, and ``auto`` (which picks one)."""
    section = fb.CouplingParams if key == "scheme" else fb.FictitiousBoundaryParams
    assert tuple(registry) + ("auto",) == section.__dataclass_fields__[key].metadata["choices"]


def _falling_disk(**sections):
    mesh = fb.StructuredMesh.box((16, 24), upper=(2.0, 3.0))
    disk = fb.Particles.at_rest([fb.Ball(0.5, dim=2)], density=1.5, position=[[1.0, 1.5]])
    return fb.Simulation(mesh, disk, fb.FluidParams(density=1.0, viscosity=0.1, gravity=980.0),
                         time=fb.TimeParams(dt=0.005, t_end=0.01, scheme="backward-euler"), **sections)


@pytest.mark.parametrize("scheme", list(fb.COUPLINGS))
def test_every_coupling_scheme_steps(scheme):
    """Each registered scheme: a falling disk slows the fall below reduced-gravity free fall."""
    sim = _falling_disk(coupling=fb.CouplingParams(scheme=scheme))
    reports = sim.run()
    assert [r.step for r in reports] == [1, 2] and reports[-1].t == pytest.approx(0.01)
    v = reports[-1].velocity[0, 1]
    assert -(1 - 1 / 1.5) * 980.0 * 0.01 < v < 0.0
    assert (reports[-1].flow_solves == 1) == (scheme in ("explicit", "stabilised", "newton-krylov"))


@pytest.mark.parametrize("force", list(fb.FORCE_ESTIMATORS))
def test_every_force_estimator_resists_the_fall(force):
    """Each registered estimator (sharp boundary, balls): the drag points up, less than the net
    weight early in the fall."""
    sim = _falling_disk(fbm=fb.FictitiousBoundaryParams(boundary="sharp", force=force))
    report = sim.run()[-1]
    net_weight = (1.5 - 1.0) * np.pi * 0.5**2 * 980.0
    assert 0.0 < report.force[0, 1] < net_weight
    np.testing.assert_array_equal(sim.force, report.force)


def test_positions_forces_and_fields_are_read_without_internals(tmp_path):
    sim = _falling_disk()
    assert sim.force.shape == (1, 2) and not sim.force.any()  # before the first step
    report = sim.step()
    assert report.step == 1 and sim.t == pytest.approx(sim.dt)
    np.testing.assert_array_equal(report.position, sim.particles.position)
    # inside the disk the flow is the disk's rigid motion (no rotation on the axis)
    np.testing.assert_allclose(sim.velocity_at(sim.particles.position), sim.particles.velocity, atol=1e-12)
    far = sim.velocity_at([[0.1, 0.1], [1.0, 2.8]])
    assert far.shape == (2, 2) and np.all(np.abs(far) < np.abs(sim.particles.velocity).max())
    assert np.all(np.isfinite(sim.pressure_at([[0.5, 2.5]])))
    out = sim.write_fields(tmp_path / "fields")
    assert any(out.glob("*.vtu"))


def test_a_wrong_section_type_names_the_fix():
    with pytest.raises(TypeError, match="fluid must be a FluidParams, got dict; make it with FluidParams"):
        fb.Simulation(fb.StructuredMesh.box((4, 4)),
                      fb.Particles.at_rest([fb.Ball(0.2, 2)], 1.5, [[0.5, 0.5]]), {"viscosity": 0.1})


def test_the_time_schemes_are_the_parameter_choices():
    """``params`` sits below the flow package and names the schemes itself: they must agree."""
    from fbmflow.params import SCHEMES

    assert SCHEMES == tuple(fb.TIME_SCHEMES)


@pytest.mark.parametrize("old, new", [("mg_cycle", "solver.multigrid.cycle"),
                                      ("mg_smoothing_steps", "solver.multigrid.pre_smooth and "
                                                             "solver.multigrid.post_smooth")])
def test_a_renamed_key_names_its_new_name(old, new):
    from fbmflow.scenes import load_scene

    with pytest.raises(fb.ParamError, match=f"parameter 'solver.{old}' was renamed; use {new}"):
        load_scene("cavity-2d", 0, [f"solver.{old}=2"])
    _, params, _ = load_scene("cavity-2d", 0, ["solver.multigrid.cycle=W"])
    assert params.solver.multigrid.cycle == "W"


@pytest.mark.parametrize("shapes, position, needle", [
    ([fb.Ball(0.1, 2)], [[0.5, 0.5, 0.5]], "shape 0 (Ball) is not 3D"),
    ([fb.Ball(0.1, 2)] * 2, [[0.5, 0.5]], "2 shapes for 1 positions"),
    ([fb.Ball(0.1, 2)], [[np.nan, 0.5]], "non-finite entries"),
    ([fb.Ball(0.1, 2)], [[[0.5, 0.5]]], "must be (n, 2) or (n, 3)"),
])
def test_particles_say_what_is_wrong_with_their_input(shapes, position, needle):
    """Wrong shapes and NaN positions were rejected from deep inside NumPy, or not at all."""
    with pytest.raises(ValueError, match=re.escape(needle)):
        fb.Particles.at_rest(shapes, 1.5, position)


@pytest.mark.parametrize("shapes, centres, needle", [
    ([fb.Ball(0.1, 3)], [[0.5, 0.5, 0.5]], "the particles are 3D and the mesh 2D"),
    ([fb.Box((0.1, 0.3))], [[0.5, 0.25]], "reaches outside the domain along axis 1"),  # its centre is inside
    ([fb.Box((0.1, 0.1))] * 2, [[0.5, 1.0], [0.65, 1.0]], "overlap by"),
])
def test_every_shape_is_placed_inside_and_apart(shapes, centres, needle):
    """Boxes through walls or overlapping were accepted (only balls were checked)."""
    mesh = fb.StructuredMesh.box((16, 32), upper=(1.0, 2.0))
    particles = fb.Particles.at_rest(shapes, 1.5, centres)
    with pytest.raises(ValueError, match=re.escape(needle)):
        fb.Simulation(mesh, particles, fb.FluidParams())


def test_a_file_named_like_a_scene_does_not_shadow_it(tmp_path, monkeypatch):
    from fbmflow.scenes import load_scene

    monkeypatch.chdir(tmp_path)
    (tmp_path / "cavity-2d").write_text("not a scene file")
    scene, _, _ = load_scene("cavity-2d", 0)
    assert scene.name == "cavity-2d"
