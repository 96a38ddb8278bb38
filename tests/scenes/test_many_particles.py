"""Scenes with contact: drafting–kissing–tumbling, sedimentation, fluidised bed (small and short)."""
import numpy as np
import pytest

from fbmflow.params import ParamError, from_dict
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


def test_fluidized_bed_inflow_lifts_the_bed():
    q = _run("fluidized-bed-2d", 1, particles={"count": 20}, inflow={"velocity": 20.0}, time={"t_end": 0.03})
    assert q["max_overlap"] == 0.0
    assert np.mean(q["mean_velocity"][1:]) > 0.0  # the fluid pushes the disks up
    assert len(q["bed_height"]) == len(q["t"])


def test_sedimentation_3d_runs_with_contact():
    q = _run("sedimentation-3d", 0, particles={"count": 2}, time={"t_end": 0.01})
    assert q["max_overlap"] == 0.0 and q["mean_velocity"][-1] < 0.0


def test_too_many_particles_are_refused_before_the_first_step():
    with pytest.raises(ParamError, match="do not fit"):
        _run("sedimentation-2d", 0, particles={"count": 10000})


def test_a_heavy_disk_lands_on_wall_contact_without_penetration():
    """Glowinski's disk at density ratio 100 hits the floor at about 80 cm/s: more than the
    repulsion can stop within its range (Newton then fails with the disk 45 % of its radius in
    the floor). With wall contact on it lands at the contact distance and stays there."""
    q = _run("glowinski-free-fall", 1, particle={"density": 100.0}, time={"t_end": 0.16},
             contact={"enabled": True}, coupling={"integrator": "semi-implicit-euler"})
    v, y = np.array(q["v"]), np.array(q["y"])
    r, cell = 0.125, 0.125
    assert np.all(np.isfinite(v)) and v.min() < -60.0  # a hard impact
    assert y.min() >= r + cell - 0.01 * r  # the skin of one cell, no penetration
    assert abs(v[-1]) < 1e-6 and abs(y[-1] - (r + cell)) < 0.01 * r  # at rest on the contact
