"""Set operations on sorted index arrays (DOFs, rows, cells), in time linear in their sizes.

NumPy's ``union1d``, ``setdiff1d`` and ``isin`` sort their inputs again (``np.unique`` over the
concatenation): at ten Cate level 2, where the walls constrain 106 899 velocity DOFs and the
sphere a few thousand, 20-45 ms a call, several per linear system. The index arrays this library
keeps are sorted and unique already; these functions use that, checked (a ValueError where an
input is not strictly increasing, rather than a wrong set).
"""
from __future__ import annotations

import numpy as np


def _checked(a: np.ndarray, name: str) -> np.ndarray:
    a = np.asarray(a)
    if a.size > 1 and not (a[1:] > a[:-1]).all():
        raise ValueError(f"{name}: not strictly increasing (sorted and unique indices expected)")
    return a


def among_sorted(a: np.ndarray, sorted_b: np.ndarray) -> np.ndarray:
    """``np.isin(a, sorted_b)`` for a sorted ``sorted_b`` by binary search, (len(a),) bool (``a``
    in any order): for a few particle rows against the walls' DOFs (ten Cate level 2: 2 625
    against 106 899) 0.07 ms where ``np.isin`` sorted both arrays together, 19-27 ms."""
    at = np.minimum(np.searchsorted(sorted_b, a), max(sorted_b.size - 1, 0))
    return (sorted_b[at] == a) if sorted_b.size else np.zeros(np.shape(a), dtype=bool)


def union_sorted(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.union1d(a, b)`` of two strictly increasing integer arrays: ``b``'s new entries put
    into ``a`` at their places (one binary search and one copy), sorted, the dtype of ``a``
    and ``b`` together."""
    a, b = _checked(a, "union_sorted: a"), _checked(b, "union_sorted: b")
    if a.size < b.size:
        a, b = b, a
    b = b[~among_sorted(b, a)]
    return np.insert(a.astype(np.result_type(a, b), copy=False), np.searchsorted(a, b), b)


def difference_sorted(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.setdiff1d(a, b)``: the entries of the strictly increasing ``a`` not in the strictly
    increasing ``b``, sorted."""
    a, b = _checked(a, "difference_sorted: a"), _checked(b, "difference_sorted: b")
    return a[~among_sorted(a, b)]
