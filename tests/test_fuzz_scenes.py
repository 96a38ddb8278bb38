"""Property-based fuzzing of scene files: any TOML file either loads or gives a ParamError (exit
status 2, one line), never a traceback; bad physical set-ups are refused before the first step."""
import math

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fbmflow.cli import main
from fbmflow.config import ParamError, to_dict
from fbmflow.scenes import SCENES, load_scene

# real section and key names, so that the fuzzer reaches the value checks, plus random ones
SECTIONS = sorted({s for sc in SCENES.values() for s in to_dict(sc.Params())})
KEYS = sorted({k for sc in SCENES.values() for sec in to_dict(sc.Params()).values() if isinstance(sec, dict)
               for k in sec})
names = st.one_of(st.sampled_from(SECTIONS), st.text("abcxyz_", min_size=1, max_size=6))
keys = st.one_of(st.sampled_from(KEYS), st.text("abcxyz_", min_size=1, max_size=6))
values = st.one_of(st.integers(-10**6, 10**6), st.floats(allow_nan=True, allow_infinity=True),
                   st.booleans(), st.text("abc -.0123456789e", max_size=8),
                   st.lists(st.integers(-3, 3), max_size=3))


def _toml_value(v):
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf") if math.isinf(v) else repr(v)
    if isinstance(v, str):
        return '"' + v.replace('\\', '\\\\').replace('"', '\\"') + '"'
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    return str(v)


def _real_entries(scene: str) -> list[tuple[str, str]]:
    tree = to_dict(SCENES[scene].Params())
    return [(sec, key) for sec, body in tree.items() if isinstance(body, dict) for key in body]


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data(), scene=st.one_of(st.sampled_from(sorted(SCENES)), st.text("abc-", max_size=6)),
       level=st.one_of(st.none(), st.integers(-2, 12), st.floats(-1, 3), st.text("ab", max_size=2)))
def test_any_scene_file_loads_or_gives_a_param_error(tmp_path_factory, data, scene, level):
    # mostly the scene's own (section, key) pairs with random values, so that the value checks are
    # reached; sometimes unknown sections and keys
    real = _real_entries(scene) if scene in SCENES else []
    pairs = st.tuples(names, keys) if not real else st.one_of(st.sampled_from(real), st.sampled_from(real),
                                                              st.tuples(names, keys))
    entries = data.draw(st.lists(st.tuples(pairs, values), max_size=4))
    sections: dict = {}
    for (sec, key), value in entries:
        sections.setdefault(sec, {})[key] = value
    lines = [f"scene = {_toml_value(scene)}"]
    if level is not None:
        lines.append(f"level = {_toml_value(level)}")
    for sec, body in sections.items():
        lines.append(f"[{sec}]")
        lines += [f"{k} = {_toml_value(v)}" for k, v in body.items()]
    path = tmp_path_factory.mktemp("fuzz") / "scene.toml"
    path.write_text("\n".join(lines) + "\n")
    try:
        load_scene(str(path), None, [])
    except ParamError as err:
        assert "\n" not in str(err) and str(err)


@pytest.mark.parametrize("overrides, needle", [
    (["particle.x=5.0"], "is not inside the 2 x 6 cm box"),
    (["particle.diameter=-0.1"], "particle.diameter: must be positive"),
    (["fluid.viscosity=0"], "fluid.viscosity: must be positive"),
    (["time.dt=-1"], "time.dt: must be zero or positive"),  # (0: the time step follows the mesh)
    (["time.t_end=1e308"], "steps, more than 1e+08"),  # was an OverflowError traceback
    (["fluid.viscosity=1e308"], "outside 1e-100 to 1e100"),  # was a singular factorisation
])
def test_bad_physical_setups_exit_2_before_the_first_step(overrides, needle, capsys, tmp_path):
    argv = ["run", "glowinski-free-fall", "--out", str(tmp_path), "--quiet"]
    for o in overrides:
        argv += ["--set", o]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and needle in err and "Traceback" not in err, err
    assert not (tmp_path / "run.h5").exists()  # refused before anything ran


def test_particles_that_do_not_fit_are_refused(capsys, tmp_path):
    """With the box kept (``domain.grow = false``) by the lattice; with it grown, by the memory
    check before the first step (5000 disks: a 7.9 M unknown mesh)."""
    assert main(["run", "sedimentation-2d", "--set", "particles.count=5000", "--set", "domain.grow=false",
                 "--out", str(tmp_path), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "do not fit" in err and err.count("\n") == 1
    assert main(["run", "sedimentation-2d", "--set", "particles.count=5000", "--out", str(tmp_path),
                 "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "GB available" in err and err.count("\n") == 1


def test_a_box_too_large_for_the_machine_is_refused_before_it_is_made(capsys, tmp_path):
    """A tiny volume fraction grew the periodic box until a 5.7 TiB MemoryError; now the cells it
    asks for are refused with the figure and the parameter that asked for them."""
    assert main(["run", "suspension-3d", "--set", "particles.volume_fraction=1e-9", "--out", str(tmp_path),
                 "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "particles.volume_fraction = 1e-09" in err and "GB available" in err, err


def test_a_light_sphere_s_terminal_velocity_is_real_and_upwards():
    """``suspension-3d`` with ``particles.density = 0.5`` computed a complex Reynolds number and
    died writing summary.json."""
    from fbmflow.scenes.suspension import terminal_velocity

    v_up, re_up = terminal_velocity(0.1, 0.5, 1.0, 0.01, 980.0)
    v_down, re_down = terminal_velocity(0.1, 1.5, 1.0, 0.01, 980.0)
    assert v_up == -v_down and re_up == re_down and isinstance(re_up, float) and re_up > 0
