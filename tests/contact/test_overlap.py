"""The sanity check's overlap depths: exact for balls and for any shape against a wall, through the
nearest image across periodic sides, None when nothing overlaps."""
import numpy as np
import pytest

from fbmflow.contact import Planes, deepest_overlap
from fbmflow.particles import Ball, Box, Particles


def test_nothing_overlaps_nothing_is_reported():
    p = Particles.at_rest([Ball(0.1, 2)] * 2, 2.0, [[0.3, 0.5], [0.6, 0.5]])
    assert deepest_overlap(p, Planes.box([0, 0], [1, 1])) is None


def test_a_ball_into_a_wall_and_into_another_ball():
    walls = Planes.box([0, 0], [1, 1])
    into_floor = Particles.at_rest([Ball(0.1, 2)], 2.0, [[0.5, 0.04]])
    o = deepest_overlap(into_floor, walls)
    assert (o.particle, o.other, o.wall) == (0, -1, (1, 0))
    assert o.depth == pytest.approx(0.06) and o.fraction == pytest.approx(0.6)
    pair = Particles.at_rest([Ball(0.1, 2), Ball(0.2, 2)], 2.0, [[0.3, 0.5], [0.55, 0.5]])
    o = deepest_overlap(pair, walls)
    assert {o.particle, o.other} == {0, 1} and o.depth == pytest.approx(0.05)
    assert o.fraction == pytest.approx(0.5)  # of the smaller radius


def test_a_rotated_box_reaches_the_wall_with_its_corner():
    """Every shape, not only balls: a square of half-side 0.1 turned by 45 degrees reaches
    0.1 sqrt(2) below its centre."""
    p = Particles.at_rest([Box((0.1, 0.1))], 2.0, [[0.5, 0.1]])
    p.orientation = np.array([np.pi / 4])
    o = deepest_overlap(p, Planes.box([0, 0], [1, 1]))
    assert o.depth == pytest.approx(0.1 * np.sqrt(2.0) - 0.1)
    assert o.fraction == pytest.approx(o.depth / p.bounding_radius[0])


def test_periodic_neighbours_overlap_through_their_images():
    p = Particles.at_rest([Ball(0.1, 2)] * 2, 2.0, [[0.05, 0.5], [0.9, 0.5]])
    assert deepest_overlap(p, None) is None  # 0.85 apart in the box
    o = deepest_overlap(p, None, periods=np.array([1.0, 0.0]), origin=np.zeros(2))
    assert o.depth == pytest.approx(0.05)  # 0.15 apart across the side x = 0
