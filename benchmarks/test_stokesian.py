"""The Stokesian-dynamics wrapper (fbmbench.stokesian) against exact results: one sphere per box
is the simple cubic array (Sangani & Acrivos 1982), to which Stokesian dynamics comes within 1 %
at phi = 0.05 (its far field, truncated at the stresslet, loses accuracy as the spheres crowd:
+3 % at 0.1, +15 % at 0.2); a translation of the spheres across the periodic faces changes
them by less than 1 % of the largest (the Ewald sums' precision: 0.3 %), also where a sphere
crosses a face during the solver's step. Runs only where ``FBMBENCH_SD`` names a checkout of
github.com/Pecnut/stokesian-dynamics (about a minute, most of it the solver's Numba compilation)."""

import math
import os

import numpy as np
import pytest
from fbmbench import stokesian
from fbmbench.common import RUNS

from fbmflow.scenes.suspension import random_positions, sangani_acrivos_velocity

SOURCE = os.environ.get("FBMBENCH_SD")
pytestmark = pytest.mark.skipif(not SOURCE, reason="FBMBENCH_SD (a Stokesian-dynamics checkout) not set")
A = 0.05


@pytest.fixture(scope="module")
def root():
    return stokesian.prepare(SOURCE, RUNS / "stokesian-dynamics-test")  # not the bench's copy


def test_one_sphere_per_box_settles_at_the_arrays_velocity(root):
    phi = 0.05
    side = (4.0 / 3.0 * math.pi * A**3 / phi) ** (1.0 / 3.0)
    u = stokesian.settling_velocities(root, np.full((1, 3), side / 2), side, A)
    exact = sangani_acrivos_velocity(3, phi, 3.0 * math.pi, 1.0, 1.0)
    assert u[0] == pytest.approx(exact, rel=0.01)


def test_a_translation_across_the_faces_changes_nothing(root):
    side = 0.3
    X = random_positions(8, 2 * A, np.full(3, side), 0.1 * A, seed=0)
    u = stokesian.settling_velocities(root, X, side, A)
    # sphere 0 a hundredth of a radius above the bottom face: it crosses it during the step
    moved = np.mod(X + [0.37 * side, 0.11 * side, 0.01 * A - X[0, 2]], side)
    v = stokesian.settling_velocities(root, moved, side, A)
    assert np.all(np.abs(v - u) < 0.01 * np.abs(u).max())
    assert np.all(u > 0.0)
