"""Short-range repulsion without fluid: range, magnitude at contact, direction, action = reaction."""
import numpy as np
import pytest

from fbmflow.contact import Repulsion
from fbmflow.particles import Ball, Particles

G = np.array([0.0, -10.0])


def _weight(p, rho_f=1.0):
    return np.abs(p.mass - rho_f * p.volume) * 10.0


def test_wall_force_is_zero_beyond_the_range_and_strength_times_weight_at_contact():
    rep = Repulsion(0.1, (0.0, 0.0), (2.0, 2.0), strength=50.0)
    far = Particles.at_rest([Ball(0.2)], 2.0, [[1.0, 0.35]])  # gap 0.15 > range
    assert np.all(rep.forces(far, G, 1.0) == 0.0)
    touching = Particles.at_rest([Ball(0.2)], 2.0, [[1.0, 0.2]])  # gap 0
    F = rep.forces(touching, G, 1.0)
    assert F[0, 0] == 0.0
    assert F[0, 1] == pytest.approx(50.0 * _weight(touching)[0])
    top = Particles.at_rest([Ball(0.2)], 2.0, [[1.0, 1.85]])  # inside the range of the top wall
    assert rep.forces(top, G, 1.0)[0, 1] < 0.0


def test_pair_forces_are_equal_and_opposite_and_grow_with_overlap():
    rep = Repulsion(0.1, (-5.0, -5.0), (5.0, 5.0))
    forces = []
    for gap in (0.08, 0.04, 0.0):
        p = Particles.at_rest([Ball(0.2), Ball(0.3)], [2.0, 3.0], [[0.0, 0.0], [0.5 + gap, 0.0]])
        F = rep.forces(p, G, 1.0)
        np.testing.assert_allclose(F[0], -F[1], atol=1e-14)
        assert F[0, 0] < 0.0 and F[0, 1] == 0.0  # pushes particle 0 away from particle 1
        forces.append(-F[0, 0])
    assert forces[0] < forces[1] < forces[2]


def test_fixed_particles_get_no_force_and_bad_parameters_are_refused():
    rep = Repulsion(0.1, (0.0, 0.0), (1.0, 1.0))
    p = Particles.at_rest([Ball(0.2)], 2.0, [[0.5, 0.2]])
    p.fixed[:] = True
    assert np.all(rep.forces(p, G, 1.0) == 0.0)
    with pytest.raises(ValueError, match="positive"):
        Repulsion(0.0, (0.0, 0.0), (1.0, 1.0))


def test_neutrally_buoyant_particle_is_still_repelled():
    rep = Repulsion(0.1, (0.0, 0.0), (1.0, 1.0))
    p = Particles.at_rest([Ball(0.2)], 1.0, [[0.5, 0.2]])  # same density as the fluid, touching
    F = rep.forces(p, G, 1.0)
    assert F[0, 1] == pytest.approx(10.0 * p.mass[0] * 10.0)
