"""The sorted index sets' operations against NumPy's."""
import numpy as np
import pytest

from fbmflow.fem.sorted_sets import among_sorted, difference_sorted, union_sorted


def test_among_sorted_is_isin():
    """The binary search against ``np.isin``: values below, between, on and above the sorted
    array's, an empty array on either side."""
    rng = np.random.default_rng(7)
    b = np.unique(rng.integers(10, 1000, 300))
    a = rng.integers(0, 1100, 500)
    assert np.array_equal(among_sorted(a, b), np.isin(a, b)) and among_sorted(a, b).any()
    assert not among_sorted(a, b[:0]).any() and among_sorted(a[:0], b).shape == (0,)
    assert among_sorted(b, b).all()


@pytest.mark.parametrize("sizes", [(300, 20), (20, 300), (0, 50), (50, 0), (0, 0)])
def test_union_and_difference_are_numpys(sizes):
    """Overlapping sets of either size (the larger taken as the base), shared entries, entries
    below and above the other's, empty ones, and mixed integer types."""
    rng = np.random.default_rng(sum(sizes))
    a = np.unique(rng.integers(0, 2000, sizes[0])).astype(np.int64)
    b = np.unique(np.concatenate([rng.integers(-50, 2100, sizes[1]), a[:3]]))[:sizes[1]].astype(np.int32)
    union = union_sorted(a, b)
    assert np.array_equal(union, np.union1d(a, b)) and union.dtype == np.int64
    assert np.array_equal(difference_sorted(a, b), np.setdiff1d(a, b))
    assert np.array_equal(difference_sorted(b, a), np.setdiff1d(b, a))


def test_unsorted_input_is_refused():
    with pytest.raises(ValueError, match="not strictly increasing"):
        union_sorted(np.array([1, 3, 2]), np.array([0]))
    with pytest.raises(ValueError, match="not strictly increasing"):
        difference_sorted(np.array([1, 2]), np.array([4, 4]))
