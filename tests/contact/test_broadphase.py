"""Broadphases equal the brute-force pairs (property-based), plane candidates, narrowphase gaps."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from fbmflow.contact import BROADPHASES, Planes, candidate_pairs, plane_candidates
from fbmflow.contact.broadphase import brute_force_pairs
from fbmflow.contact.narrowphase import pair_contacts, plane_contacts
from fbmflow.particles import Ball, Box, Ellipsoid, Particles


@st.composite
def particle_sets(draw):
    dim = draw(st.sampled_from([2, 3]))
    n = draw(st.integers(0, 60))
    X = draw(arrays(float, (n, dim), elements=st.floats(-3.0, 3.0)))
    # mixtures of sizes over two orders of magnitude exercise the hierarchical levels
    R = draw(arrays(float, (n,), elements=st.floats(0.01, 1.0)))
    margin = draw(st.floats(0.0, 0.5))
    return X, R, margin


@settings(max_examples=150, deadline=None)
@given(particle_sets())
def test_every_broadphase_finds_exactly_the_brute_force_pairs(case):
    X, R, margin = case
    ref = brute_force_pairs(X, R, margin)
    ref = ref[np.lexsort((ref[:, 1], ref[:, 0]))]
    for name in BROADPHASES:
        got = candidate_pairs(X, R, margin, name)
        assert got.dtype == np.int64 and got.shape[1] == 2
        assert np.array_equal(got, ref), name


def test_broadphase_on_a_dense_random_cloud_and_clustered_duplicates():
    rng = np.random.default_rng(3)
    X = rng.random((3000, 3)) * 10.0
    X[:50] = X[0]  # coincident centres
    R = np.where(rng.random(3000) < 0.02, 0.8, 0.1)
    ref = brute_force_pairs(X, R, 0.05)
    for name in ("grid", "hierarchical-grid"):
        assert np.array_equal(candidate_pairs(X, R, 0.05, name), ref)


def test_unknown_broadphase_and_bad_radii_are_refused():
    with pytest.raises(ValueError, match="unknown broadphase"):
        candidate_pairs(np.zeros((2, 2)), np.ones(2), 0.0, "octree")
    with pytest.raises(ValueError, match="positive"):
        candidate_pairs(np.zeros((2, 2)), np.array([1.0, -1.0]))


def test_plane_candidates_are_the_balls_within_the_margin():
    planes = Planes.box([0.0, 0.0], [2.0, 1.0])
    X = np.array([[0.2, 0.5], [1.0, 0.85], [1.0, 0.5]])
    part, plane = plane_candidates(X, np.full(3, 0.1), planes.points, planes.normals, margin=0.1)
    # particle 0 is 0.1 from the x = 0 wall (plane 0), particle 1 0.05 from y = 1 (plane 3)
    assert part.tolist() == [0, 1] and plane.tolist() == [0, 3]


def test_sphere_pair_gap_normal_and_point_are_exact():
    p = Particles.at_rest([Ball(0.5, 3), Ball(0.25, 3)], 1.0, [[0.0, 0.0, 0.0], [0.0, 0.9, 0.0]])
    c = pair_contacts(p, np.array([[0, 1]]))
    assert c.gap[0] == pytest.approx(0.15)
    assert np.allclose(c.normal[0], [0.0, -1.0, 0.0])  # from j towards i
    assert np.allclose(c.point[0], [0.0, 0.575, 0.0])


@pytest.mark.parametrize("shape, half_width", [
    (Ellipsoid((0.4, 0.1)), lambda th: np.sqrt((0.4 * np.sin(th))**2 + (0.1 * np.cos(th))**2)),
    (Box((0.4, 0.1)), lambda th: 0.4 * abs(np.sin(th)) + 0.1 * abs(np.cos(th))),
])
def test_rotated_shape_on_a_floor_has_the_exact_gap(shape, half_width):
    planes = Planes.box([-5.0, 0.0], [5.0, 5.0], faces=[(1, 0)])
    for th in np.linspace(0.0, np.pi, 7):
        p = Particles.at_rest([shape], 1.0, [[0.0, 1.0]])
        p.orientation[:] = th
        c = plane_contacts(p, np.array([0]), np.array([0]), planes)
        assert c.gap[0] == pytest.approx(1.0 - half_width(th), abs=1e-12)


def test_non_spherical_pair_gap_is_a_lower_bound_of_the_true_distance():
    rng = np.random.default_rng(0)
    shapes = [Ellipsoid((0.3, 0.1)), Box((0.2, 0.05))]
    t = np.linspace(0.0, 2 * np.pi, 2000, endpoint=False)
    for _ in range(20):
        p = Particles.at_rest(shapes, 1.0, [[0.0, 0.0], rng.uniform(-0.6, 0.6, 2) + [0.5, 0.0]])
        p.orientation[:] = rng.uniform(0, np.pi, 2)
        c = pair_contacts(p, np.array([[0, 1]]))
        # boundary samples of both shapes in world coordinates
        R = p.rotations()
        e = np.column_stack([0.3 * np.cos(t), 0.1 * np.sin(t)])
        s = np.linspace(-1, 1, 500)
        b = np.concatenate([np.column_stack([0.2 * s, np.full_like(s, 0.05)]),
                            np.column_stack([0.2 * s, np.full_like(s, -0.05)]),
                            np.column_stack([np.full_like(s, 0.2), 0.05 * s]),
                            np.column_stack([np.full_like(s, -0.2), 0.05 * s])])
        A = p.position[0] + e @ R[0].T
        B = p.position[1] + b @ R[1].T
        true = np.min(np.linalg.norm(A[:, None] - B[None], axis=2))
        overlapping = (shapes[0].inside((B - p.position[0]) @ R[0]).any()
                       or shapes[1].inside((A - p.position[1]) @ R[1]).any())
        if not overlapping:
            assert c.gap[0] <= true + 1e-3

