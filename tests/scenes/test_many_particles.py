"""Scenes with contact: drafting–kissing–tumbling, sedimentation, fluidised bed (small and short)."""
import numpy as np
import pytest

from fbmflow.config import ParamError, from_dict
from fbmflow.scenes import get_scene


def _run(name, level, **sections):
    scene = get_scene(name)
    return scene.run(from_dict(scene.Params, sections), level).quantities


@pytest.mark.slow
def test_dkt_drafts_kisses_and_tumbles_without_overlap():
    """Uhlmann's set-up at 2 cells/d: the trailing disk catches up (drafting), the disks come
    within the kissing distance, and the trailing one passes the leading one (tumbling)."""
    q = _run("dkt-2d", 1, case={"setup": "uhlmann"}, time={"t_end": 0.25})
    assert q["t_kiss"] is not None and q["t_tumble"] is not None
    assert 0.05 < q["t_kiss"] < q["t_tumble"] < 0.25
    t, v_lead, v_trail = (np.array(q[k]) for k in ("t", "v_leading", "v_trailing"))
    before = t < q["t_kiss"]
    assert np.min(v_trail[before]) < 1.2 * np.min(v_lead[before])  # the trailing disk falls faster
    skin = 1.0 / 2.0  # one cell at 2 cells per diameter, in diameters
    assert q["min_distance_over_d"] >= 1.0 + skin - 1e-9


def test_sedimentation_2d_keeps_particles_apart_and_inside():
    q = _run("sedimentation-2d", 1, particles={"count": 30}, time={"t_end": 0.03})
    assert q["max_overlap"] == 0.0
    v = np.array(q["mean_velocity"])
    assert np.all(np.isfinite(v)) and v[-1] < 0.0
    X = np.array(q["final_positions"])
    assert np.all((X > 0.05) & (X < [2.0 - 0.05, 4.0 - 0.05]))
    front = np.array(q["front_height"])  # the suspension's top comes down with the disks
    assert front.shape == (len(q["t"]),) and front[-1] < front[0] <= 4.0
    top = np.sort(X[:, 1])[-3:]  # the highest tenth of 30
    assert front[-1] == pytest.approx(top.mean() + 0.05)


def test_fluidized_bed_inflow_lifts_the_bed():
    q = _run("fluidized-bed-2d", 1, particles={"count": 20}, inflow={"velocity": 20.0}, time={"t_end": 0.03})
    assert q["max_overlap"] == 0.0
    assert np.mean(q["mean_velocity"][1:]) > 0.0  # the fluid pushes the disks up
    assert len(q["bed_height"]) == len(q["t"])


def test_sedimentation_3d_runs_with_contact():
    q = _run("sedimentation-3d", 0, particles={"count": 2}, time={"t_end": 0.01})
    assert q["max_overlap"] == 0.0 and q["mean_velocity"][-1] < 0.0


@pytest.mark.parametrize("name", ["sedimentation-2d", "sedimentation-3d", "fluidized-bed-2d"])
def test_many_particle_scenes_choose_the_coupling_by_the_responses_it_would_store(name):
    """``coupling.scheme = auto``: the implicit scheme at the default counts and levels, the
    stabilised one (no stored responses) for 2 000 disks or 1 000 spheres, which the implicit
    scheme's responses (137 GB, 614 GB) refused."""
    from fbmflow.coupling.schemes import auto_coupling
    from fbmflow.fem import FlowSpace

    scene = get_scene(name)
    params = scene.Params()
    assert params.coupling.scheme == "auto"
    for count, level, scheme in ((params.particles.count, scene.default_level, "implicit"),
                                 (2000 if scene.dim == 2 else 1000, scene.default_level, "stabilised")):
        many = from_dict(scene.Params, {"particles": {"count": count}})
        layout = scene.layout(many, level)
        n = FlowSpace.estimate_dofs(layout.mesh)
        assert auto_coupling(n, layout.particles) == scheme, (count, n)


def test_too_many_particles_are_refused_before_the_first_step():
    with pytest.raises(ParamError, match="do not fit"):
        _run("sedimentation-2d", 0, particles={"count": 10000}, domain={"grow": False})


@pytest.mark.parametrize("name, count, scale", [("sedimentation-2d", 100, 1.0),
                                                 ("sedimentation-2d", 101, 1.5),
                                                 ("sedimentation-2d", 2000, 4.5),
                                                 ("sedimentation-3d", 1000, 3.5)])
def test_the_box_grows_until_the_particles_fit(name, count, scale):
    """The scene's box where its lattice holds the count; else the smallest box of its shape and
    cell size, in steps of half its size, whose lattice does (the volume fraction stays)."""
    scene = get_scene(name)
    params = from_dict(scene.Params, {"particles": {"count": count}})
    assert scene.scale(params) == scale
    mesh = scene.mesh(1, scene.scale(params))
    assert np.allclose(mesh.spacing, scene.mesh(1).spacing)
    assert np.allclose(mesh.upper, scale * np.array(scene.box))
    X = scene.initial_positions(params)
    assert X.shape == (count, scene.dim) and np.all((X > 0) & (X < mesh.upper))


def test_a_dense_lattice_keeps_its_gaps():
    """spacing 1.2 diameters: neighbours at least 0.7 x 0.2 d apart, the lowest row half a
    spacing above the floor."""
    scene = get_scene("sedimentation-2d")
    params = from_dict(scene.Params, {"particles": {"count": 100, "spacing": 1.2, "bottom": 0.0, "top": 0.2}})
    X, d = scene.initial_positions(params), 0.1
    dist = np.linalg.norm(X[:, None] - X[None], axis=-1) + np.eye(len(X)) * 1e9
    assert dist.min() >= d * (1 + 0.7 * 0.2) - 1e-12
    assert X[:, 1].min() >= 0.6 * d - 0.03 * d - 1e-12
    with pytest.raises(ParamError, match="particles.bottom"):
        from_dict(scene.Params, {"particles": {"bottom": 0.5, "top": 0.4}})


def test_a_lattice_closer_than_the_contact_skin_is_warned_of(caplog):
    scene = get_scene("sedimentation-2d")
    params = from_dict(scene.Params, {"particles": {"spacing": 1.2, "bottom": 0.0, "top": 0.3}})
    with caplog.at_level("WARNING"):
        scene.layout(params, 2)
    assert "use particles.spacing >= 1.36" in caplog.text
    caplog.clear()
    with caplog.at_level("WARNING"):
        scene.layout(from_dict(scene.Params, {"particles": {"spacing": 1.4, "bottom": 0.0, "top": 0.3}}), 2)
    assert "contact skin" not in caplog.text


@pytest.mark.parametrize("scheme, dt", [("implicit", 0.002), ("stabilised", 0.001)])
def test_a_heavy_disk_lands_on_wall_contact_without_penetration(scheme, dt):
    """Glowinski's disk at density ratio 100 hits the floor at about 80 cm/s: more than the
    repulsion can stop within its range (Newton then fails with the disk 45 % of its radius in
    the floor). With wall contact on it lands at the contact distance and stays there. The
    stabilised coupling needs the disk to cross at most half a cell per step for it (at a cell
    per step, dt = 0.002 s, the flow's Newton fails three steps after the impact)."""
    q = _run("glowinski-free-fall", 1, particle={"density": 100.0}, time={"t_end": 0.16, "dt": dt},
             contact={"enabled": True}, coupling={"integrator": "semi-implicit-euler", "scheme": scheme})
    v, y = np.array(q["v"]), np.array(q["y"])
    r, cell = 0.125, 0.125
    assert np.all(np.isfinite(v)) and v.min() < -60.0  # a hard impact
    assert y.min() >= r + cell - 0.01 * r  # the skin of one cell, no penetration
    assert abs(v[-1]) < 1e-6 and abs(y[-1] - (r + cell)) < 0.01 * r  # at rest on the contact


@pytest.mark.parametrize("density", [1.01, 10.0])
def test_extreme_density_ratios_settle_without_blow_up(density):
    """Almost neutrally buoyant disks (added mass dominates) and disks ten times the fluid's
    density: finite, downwards, no overlap; the heavy ones faster by far."""
    t_end = 0.03  # (0.05 until the test run neared its 20 minutes: 45 s for the heavy disks)
    q = _run("sedimentation-2d", 1, particles={"count": 20, "density": density}, time={"t_end": t_end})
    v = np.array(q["mean_velocity"])
    assert np.all(np.isfinite(v)) and v[-1] < 0.0
    assert q["max_overlap"] == 0.0
    # the first steps of free fall, v = -(1 - 1/density) g t at most (added mass slows it)
    assert abs(v[-1]) <= (1 - 1 / density) * 980.0 * t_end
    if density > 2:
        assert abs(v[-1]) > 0.2 * (1 - 1 / density) * 980.0 * t_end


def test_a_dense_packing_rests_on_the_bottom():
    """Disks on a lattice of 1.4 diameters from the floor (gaps above the contact skin of a
    quarter diameter) settle onto it over their first 0.05 s: no overlap at any step, no centre
    below a radius, and no disk pushed above the lattice's top row (a packing closer than the
    skin burst upwards by 0.4 cm in its first steps)."""
    particles = {"count": 30, "spacing": 1.4, "bottom": 0.0, "top": 0.2}
    q = _run("sedimentation-2d", 1, particles=particles, contact={"skin_cells": 0.5}, time={"t_end": 0.05})
    scene, r = get_scene("sedimentation-2d"), 0.05
    top = scene.initial_positions(from_dict(scene.Params, {"particles": particles}))[:, 1].max()
    assert max(q["overlap"]) == 0.0
    assert q["min_height"] >= r and q["max_height"] <= top + 1e-12
    assert np.all(np.isfinite(q["mean_velocity"])) and q["mean_velocity"][-1] < 0.0
