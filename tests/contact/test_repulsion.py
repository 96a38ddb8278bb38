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



def test_stiffness_is_the_forces_derivative_along_the_lines_of_action():
    """A pair in range, a pair in range across the periodic side, a disk near the bottom wall and
    a fixed one near the top: ``K`` is symmetric, negative semi-definite and zero for the fixed
    disk, and moving a pair apart along its normal or the disk along the wall's axis changes the
    forces by ``K v`` (central differences; ``K`` leaves out only the turn of the normal, which
    such motions do not cause)."""
    rep = Repulsion(0.1, (0.0, 0.0), (2.0, 2.0), strength=20.0, walls=((1, 0), (1, 1)), periods=(2.0, 0.0))
    X = np.array([[0.5, 1.0], [0.97, 1.05], [0.1, 0.6], [1.67, 0.62], [1.3, 0.25], [1.4, 1.75]])
    p = Particles.at_rest([Ball(0.2)] * 6, [2.0, 2.5, 3.0, 2.0, 1.5, 2.0], X)
    p.fixed = np.array([False, False, False, False, False, True])
    K = rep.stiffness(p, G, 1.0).toarray()
    np.testing.assert_allclose(K, K.T, atol=1e-12)
    assert np.linalg.eigvalsh(K).max() < 1e-9
    assert not K[10:].any() and not K[:, 10:].any()

    def normal(i, j):
        d = X[i] - X[j]
        d[0] -= 2.0 * np.round(d[0] / 2.0)
        return d / np.linalg.norm(d)

    motions = []
    for i, j in ((0, 1), (2, 3)):
        v = np.zeros((6, 2))
        v[i], v[j] = normal(i, j), -normal(i, j)
        motions.append(v)
    v = np.zeros((6, 2))
    v[4, 1] = 1.0
    motions.append(v)
    eps = 1e-7
    for v in motions:
        plus, minus = p.copy(), p.copy()
        plus.position, minus.position = X + eps * v, X - eps * v
        dF = (rep.forces(plus, G, 1.0) - rep.forces(minus, G, 1.0)).ravel() / (2 * eps)
        assert np.abs(dF).max() > 1.0  # in range: the forces do change
        np.testing.assert_allclose(K @ v.ravel(), dF, rtol=1e-6, atol=1e-6 * np.abs(dF).max())
