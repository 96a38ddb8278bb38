"""Periodic suspensions: particles that cross periodic sides, the mean pressure gradient that
carries their weight, zero mean volume flux, and the settling velocity of a periodic array of disks
against Sangani & Acrivos' exact series (small and short)."""
import numpy as np
import pytest

from fbmflow import Simulation
from fbmflow.config import from_dict
from fbmflow.contact.settings import ContactParams
from fbmflow.coupling.placement import periodic_drive
from fbmflow.mesh import StructuredMesh
from fbmflow.params import FluidParams, TimeParams
from fbmflow.particles import Ball, Particles
from fbmflow.scenes import get_scene
from fbmflow.scenes.suspension import random_positions
from fbmflow.solvers.settings import SolverParams

FLUID = FluidParams(density=1.0, viscosity=1.0, gravity=1.0)


def _run(name, level, **sections):
    scene = get_scene(name)
    return scene.run(from_dict(scene.Params, sections), level).quantities


def _periodic_box(n=12, side=3.0, periodic=(True, True)):
    return StructuredMesh.box((n, n), upper=(side, side), periodic=periodic)


def test_drive_carries_the_free_particles_weight():
    mesh = StructuredMesh.box((4, 4, 4), upper=(2.0, 2.0, 4.0), periodic=(True, True, True))
    centres = np.array([[0.5, 0.5, 1.0], [1.5, 1.5, 3.0]])
    p = Particles.at_rest([Ball(0.3, 3)] * 2, np.array([2.0, 3.0]), centres)
    g = np.array([0.0, 0.0, -9.81])
    f = periodic_drive(mesh, p, g, 1.0)
    np.testing.assert_allclose(f * 16.0 + np.sum(p.mass - p.volume) * g, 0.0, atol=1e-12)
    p.fixed[1] = True  # a fixed particle's weight is carried by its support
    np.testing.assert_allclose(periodic_drive(mesh, p, g, 1.0) * 16.0, -(p.mass[0] - p.volume[0]) * g)
    walls = StructuredMesh.box((4, 4, 4), periodic=(True, True, False))  # gravity across walls: no drive
    assert not np.any(periodic_drive(walls, p, g, 1.0))


def test_disk_crossing_the_periodic_sides_moves_as_one_inside_the_box():
    """The same disk, once straddling the bottom/top sides and once in the middle (shifted by
    whole cells), settles alike: its centre wraps and the flow, forces and constraints take the
    nearest image."""
    runs = []
    for y in (0.037, 1.537):
        p = Particles.at_rest([Ball(0.5, 2)], 2.0, np.array([[1.513, y]]))
        sim = Simulation(_periodic_box(), p, FLUID, time=TimeParams(dt=0.5, t_end=3.0),
                         solver=SolverParams(linear="direct"))
        reports = sim.run()
        runs.append((np.array([r.velocity[0] for r in reports]), np.array([r.position[0] for r in reports])))
        assert sim.system.zero_flux and all(r.flux_correction is not None for r in reports)
    (v0, x0), (v1, x1) = runs
    assert x0[-1, 1] > 2.5  # the straddling disk went through the bottom and reappeared at the top
    np.testing.assert_allclose(v0, v1, rtol=1e-6, atol=1e-9)
    # the runs' centres differ by (0, -1.5) modulo the period 3: half a period, so wrap the
    # difference from that shift (wrapping x0 - x1 itself flips between -1.5 and +1.5 at round-off)
    off = np.mod(x0 - x1 - np.array([0.0, -1.5]) + 1.5, 3.0) - 1.5
    np.testing.assert_allclose(off, 0.0, atol=1e-9)


def test_overlap_across_periodic_sides_is_refused():
    p = Particles.at_rest([Ball(0.5, 2)] * 2, 2.0, np.array([[1.5, 0.2], [1.5, 2.9]]))  # 0.3 apart via y = 0
    with pytest.raises(ValueError, match="particles 0 and 1 overlap"):
        Simulation(_periodic_box(), p, FLUID)


def test_hard_contact_acts_across_the_periodic_sides():
    """A heavy disk settles onto a light one through the bottom/top sides: contact holds their
    nearest-image gap at the skin, and the heavy one pushes the light one down through the side."""
    mesh = _periodic_box(n=16)
    p = Particles.at_rest([Ball(0.5, 2)] * 2, np.array([4.0, 1.2]), np.array([[1.5, 0.75], [1.55, 2.25]]))
    fluid = FluidParams(density=1.0, viscosity=0.05, gravity=1.0)
    contact = ContactParams(skin_cells=0.5)
    sim = Simulation(mesh, p, fluid, time=TimeParams(dt=0.2, t_end=2.0), solver=SolverParams(linear="direct"),
                     contact=contact)
    reports = sim.run()
    skin = 0.5 * 3.0 / 16
    gaps = []
    for r in reports:
        d = r.position[0] - r.position[1]
        gaps.append(np.linalg.norm(d - 3.0 * np.round(d / 3.0)) - 1.0)
    touching = [r.contact.contacts > 0 for r in reports]
    assert gaps[0] > 0.4 and any(touching)
    assert min(gaps) >= skin * (1 - 1e-4)  # held at the skin, through the side
    assert reports[-1].position[0, 1] > 2.5  # the heavy disk went through the bottom
    v = reports[-1].velocity[:, 1]
    assert abs(v[1] - v[0]) < 0.05 * abs(v[0])  # and pushes the light one down at its own speed


def test_repulsion_acts_through_the_nearest_image():
    from fbmflow.contact.settings import RepulsionParams

    mesh = _periodic_box(periodic=(True, False))  # periodic in x, walls at y = 0 and 3
    rep = RepulsionParams().make(mesh, [(1, 0), (1, 1)])
    p = Particles.at_rest([Ball(0.5, 2)] * 2, 2.0, np.array([[0.1, 1.5], [2.8, 1.5]]))  # gap 0.1 via x = 0
    F = rep.forces(p, np.array([0.0, -1.0]), 1.0)
    assert F[0, 0] > 0 and F[1, 0] < 0  # pushed apart across the side, not towards each other
    np.testing.assert_allclose(F[0], -F[1])


def test_random_positions_keep_the_gap_across_the_sides():
    box = np.array([1.0, 1.0])
    X = random_positions(20, 0.1, box, 0.025, seed=3)
    diff = X[:, None] - X[None]
    diff -= box * np.round(diff / box)
    dist = np.linalg.norm(diff, axis=2) + 9.0 * np.eye(20)
    assert dist.min() >= 0.125 - 1e-12


def test_disk_array_settles_at_the_sangani_acrivos_velocity():
    """One disk in a doubly periodic box is a square array; in Stokes flow (Re 0.02) it settles,
    relative to the mixture, at Sangani & Acrivos' velocity (measured at c = 0.049: +0.05 % at
    4 cells/d, -0.02 % at 8; the error grows with c: -5.3 / -2.4 % at c = 0.104 and -6.5 / -3.5 %
    at c = 0.196, benchmarks/results/suspension.md). The mixture's flux stays zero."""
    q = _run("suspension-2d", 2, particles={"count": 1, "volume_fraction": 0.05}, fluid={"viscosity": 1.0},
             time={"t_end": 0.6, "dt": 0.02})
    assert q["mean_settling_velocity"] == pytest.approx(q["array_velocity"], rel=0.02)
    assert np.max(np.abs(q["mixture_velocity"])) < 1e-12


def test_a_denser_suspension_settles_slower():
    """Hindered settling: 4 disks at area fraction 0.3 settle at under half the velocity of 4 at
    0.05 (measured: 0.1 times; the square arrays at the same fractions, which the scene reports
    beside: 0.17 times), without overlap."""
    speed, array = {}, {}
    for phi in (0.05, 0.3):
        q = _run("suspension-2d", 2, particles={"count": 4, "volume_fraction": phi, "min_gap": 0.1},
                 time={"t_end": 0.2, "dt": 0.01})
        assert q["max_overlap"] < 0.01
        speed[phi], array[phi] = q["mean_settling_velocity"], q["array_velocity"]
    assert 0 < speed[0.3] < 0.5 * speed[0.05]
    assert 0 < array[0.3] < 0.5 * array[0.05]


def test_a_frozen_configuration_keeps_its_place_and_settles_to_its_steady_velocity():
    """``particles.frozen``: the disks stay where they were placed while their velocities and the
    flow evolve, so the settling velocity tends to the configuration's quasi-steady one (measured:
    steps 3 and 4 agree to 0.6 %, and the first is 6 % low; moving, the disks' steps 3 and 4 differ by
    3.3 %; spheres: docs/validation/periodic-suspensions.md, "Frozen random configurations")."""
    pp = {"count": 4, "volume_fraction": 0.2, "min_gap": 0.05, "seed": 1, "frozen": True}
    q = _run("suspension-2d", 2, particles=pp, time={"t_end": 0.4, "dt": 0.1},
             coupling={"scheme": "newton-krylov"}, repulsion={"enabled": False})
    box = np.array(q["box"])
    start = random_positions(4, 0.1, box, 0.05 * 0.1, seed=1)
    np.testing.assert_allclose(np.mod(q["final_positions"], box), start, atol=1e-12)
    s = q["settling_velocity"]
    assert s[-1] > 0.0 and abs(s[-1] - s[-2]) < 0.01 * s[-1]


def _count_responses(sim):
    """Wrap ``sim.system.rigid_responses`` to count its calls (each one linear solve here); returns the
    running count, a one-element list."""
    calls, solve = [0], sim.system.rigid_responses

    def counted(*args, **kwargs):
        calls[0] += 1
        return solve(*args, **kwargs)

    sim.system.rigid_responses = counted
    return calls


@pytest.mark.slow
def test_newton_krylov_coupling_keeps_a_dense_suspension_stable_where_the_stabilised_one_is_not():
    """24 disks at area fraction 0.3 (4 cells/d, dt 0.01 s): neighbours pull on each other
    through the fluid more than the stabilised scheme's per-particle stiffness holds, and its
    largest velocity grows every step (measured 0.98, 1.2, 1.1, 1.2, 1.6, 2.5, 6.1 cm/s).
    The Newton-Krylov scheme, which takes those couplings (and the repulsion at the step's end),
    stays between 0.49 and 0.72 cm/s, with 9 to 12 linear responses per step (FGMRES to 1e-2)."""
    from fbmflow.solvers import ConvergenceError

    scene = get_scene("suspension-2d")
    largest = {}
    for scheme in ("stabilised", "newton-krylov"):
        params = from_dict(scene.Params, {"particles": {"count": 24, "volume_fraction": 0.3},
                                          "coupling": {"scheme": scheme}, "time": {"t_end": 0.07}})
        sim = scene.build(params, 2).sim
        calls = _count_responses(sim)
        speeds, responses = [], []
        try:
            for _ in range(7):
                before = calls[0]
                sim.step()
                speeds.append(float(np.abs(sim.particles.velocity).max()))
                responses.append(calls[0] - before)
        except ConvergenceError:
            speeds.append(np.inf)
        largest[scheme] = np.array(speeds)
        if scheme == "newton-krylov":
            assert max(responses) <= 15
    nk, stabilised = largest["newton-krylov"], largest["stabilised"]
    assert len(nk) == 7 and nk.max() < 1.0
    assert stabilised[-1] > 4.0 * nk[-1]


def test_pardiso_solves_a_frozen_periodic_suspension_without_fgmres(monkeypatch):
    """Eight frozen spheres at a volume fraction of 0.2, level 2 (37 268 unknowns), one step of
    0.1 s with the newton-krylov coupling. With MKL's default weighted matching, PARDISO
    perturbed pivots of these Jacobians and 21 of the step's solves (Newton's and the
    responses) ended in FGMRES (66 s against 14 s for the step); without it, PARDISO's factors
    solve them to the refinement target (docs/method.md, "Direct solver")."""
    from fbmflow.solvers import direct

    if not direct.pardiso_available():
        pytest.skip("the pardiso extra (MKL) is not installed")
    fallbacks, fgmres = [], direct.fgmres
    monkeypatch.setattr(direct, "fgmres", lambda *a, **k: fallbacks.append(1) or fgmres(*a, **k))
    scene = get_scene("suspension-3d")
    params = from_dict(scene.Params, {
        "particles": {"count": 8, "seed": 11, "volume_fraction": 0.2, "min_gap": 0.02, "frozen": True},
        "repulsion": {"enabled": False}, "time": {"dt": 0.1, "t_end": 0.1},
        "coupling": {"scheme": "newton-krylov"}, "solver": {"linear": "direct"}})
    setup = scene.build(params, 2)
    setup.sim.step(setup.dt)
    assert setup.sim.flow.linear_solver_description == "direct (PARDISO)"
    assert not fallbacks
