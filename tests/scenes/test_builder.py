"""The one scene builder: every particle scene is built the same way from its parameter sections."""
import logging

import pytest

import fbmflow.solvers.choice as choice
from fbmflow.config import ParamError, from_dict
from fbmflow.scenes import SCENES, get_scene
from fbmflow.scenes.base import SimulationScene
from fbmflow.scenes.builder import STANDARD_SECTIONS, ParticleScene

PARTICLE_SCENES = [name for name, scene in SCENES.items() if isinstance(scene, SimulationScene)]


@pytest.mark.parametrize("name", PARTICLE_SCENES)
def test_every_particle_scene_is_built_by_the_builder_from_its_sections(name, monkeypatch):
    """The scheme, estimator, integrator, time scheme, step count and time step come from the
    parameter sections alone; every standard section is there."""
    monkeypatch.setattr(choice, "available_memory", lambda: None)
    scene = get_scene(name)
    assert isinstance(scene, ParticleScene)
    params = from_dict(scene.Params, {"coupling": {"scheme": "explicit"}, "fbm": {"force": "test-function"}})
    standard = {k for k, cls in STANDARD_SECTIONS.items() if cls is not None}
    assert standard <= set(scene.Params.__dataclass_fields__)
    setup = scene.build(params, 0)
    sim = setup.sim
    time = scene.time(params, scene.layout(params, 0))
    assert (sim.coupling.name, sim.system.estimator.name) == ("explicit", "test-function")
    assert (sim.system.integrator, sim.system.time_scheme) == (params.coupling.integrator, time.scheme)
    assert setup.n_steps == time.n_steps and setup.dt * setup.n_steps == pytest.approx(time.t_end)
    assert (sim.contact is not None) == (params.contact.enabled if hasattr(params, "contact") else False)


def test_a_contact_skin_of_a_diameter_warns_and_names_the_level(caplog):
    """dkt-2d at level 0: the skin of one cell is a whole diameter, which made t_kiss = 0 without a
    word; level 2 brings it to half a radius."""
    scene = get_scene("dkt-2d")
    params = from_dict(scene.Params, {})
    with caplog.at_level(logging.WARNING, logger="fbmflow.scenes.builder"):
        scene.build(params, 0)
    messages = [r.getMessage() for r in caplog.records]
    assert len(messages) == 1 and "is 2 particle radii" in messages[0]
    assert "use --level 2 or finer" in messages[0]
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="fbmflow.scenes.builder"):
        scene.build(params, 2)
        scene.build(from_dict(scene.Params, {"contact": {"skin_cells": 0.25}}), 0)  # a thinner skin
    assert not caplog.records


@pytest.mark.parametrize("name", ["glowinski-free-fall", "ten-cate"])
def test_the_default_time_step_follows_the_mesh_and_an_explicit_one_wins(name):
    """dt = courant h / U: each level halves it; time.dt set by hand is kept at every level."""
    scene = get_scene(name)
    params = from_dict(scene.Params, {})
    dts = []
    for level in (0, 1, 2):
        place = scene.layout(params, level)
        t = scene.time(params, place)
        h = float(place.mesh.cell_size_at(place.particles.position).min())
        assert t.dt == pytest.approx(params.time.courant * h / scene.velocity_scale(params), rel=1e-12)
        dts.append(t.dt)
    assert dts[0] / dts[1] == pytest.approx(2.0) and dts[1] / dts[2] == pytest.approx(2.0)
    fixed = from_dict(scene.Params, {"time": {"dt": 0.003}})
    assert {scene.time(fixed, scene.layout(fixed, level)).dt for level in (0, 2)} == {0.003}


def test_a_particle_expected_not_to_move_asks_for_a_time_step():
    scene = get_scene("glowinski-free-fall")
    params = from_dict(scene.Params, {"particle": {"density": 1.0}})
    with pytest.raises(ParamError, match="set time.dt"):
        scene.time(params, scene.layout(params, 0))


@pytest.mark.parametrize("name, expected", [("ten-cate", "surface"), ("glowinski-free-fall", "volume"),
                                            ("sedimentation-3d", "volume")])
def test_the_automatic_force_is_the_surface_force_for_balls_with_the_sharp_boundary_in_3d(name, expected,
                                                                                           monkeypatch):
    """fbm.force = auto: the surface force where the sphere array measured it the most accurate
    (balls, sharp boundary, 3D), the volume force elsewhere (2D, nodal boundary)."""
    monkeypatch.setattr(choice, "available_memory", lambda: None)
    scene = get_scene(name)
    params = from_dict(scene.Params, {})
    assert params.fbm.force == "auto"
    assert scene.build(params, 0).sim.system.estimator.name == expected
