"""The far-field reference of the hindered-settling ensembles (fbmbench.ewald_rpy) against exact
results: one sphere per box is the simple cubic array, whose Stokes settling velocity begins
``1 - 1.7601 phi^(1/3) + phi`` (Hasimoto 1959; the RPY level is exact to these terms, its next
term is O(phi^2)); a 2 x 2 x 2 block of that array is the same array; the Ewald splitting
parameter changes nothing. Seconds."""

import math

import numpy as np
import pytest
from fbmbench.ewald_rpy import mean_settling

from fbmflow.scenes.suspension import random_positions

A = 0.05


def _side(phi, n=1):
    return (n * 4.0 / 3.0 * math.pi * A**3 / phi) ** (1.0 / 3.0)


@pytest.mark.quick
@pytest.mark.parametrize("phi", [0.001, 0.01, 0.05, 0.2])
def test_one_sphere_per_box_settles_at_hasimotos_velocity(phi):
    hasimoto = 1.0 - 1.7601 * phi ** (1 / 3) + phi
    assert mean_settling(np.zeros((1, 3)), _side(phi), A) == pytest.approx(hasimoto, abs=0.2 * phi**2 + 1e-5)


@pytest.mark.quick
def test_a_block_of_the_array_and_the_splitting_change_nothing():
    side = _side(0.05)
    block = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], dtype=float) * side
    one = mean_settling(np.zeros((1, 3)), side, A)
    assert mean_settling(block, 2 * side, A) == pytest.approx(one, rel=1e-6)
    X = random_positions(12, 2 * A, np.full(3, 3 * side), 0.0, seed=0)
    values = [mean_settling(X, 3 * side, A, xi=c / side) for c in (1.0, 3.0, 6.0)]
    assert max(values) - min(values) < 1e-7
