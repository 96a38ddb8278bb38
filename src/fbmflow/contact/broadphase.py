"""Broadphase: candidate particle pairs and particle–wall candidates from bounding balls.

A pair ``(i, j)``, ``i < j``, is a candidate when the bounding balls come within ``margin``:

    ``|X_i - X_j| <= R_i + R_j + margin``.

Particle–plane candidates (domain walls) come from :func:`plane_candidates`. In a box with
periodic axes the pairs meet through their nearest images (:func:`candidate_pairs` with
``periods``): the particles near a periodic side get images beyond the opposite one, the
broadphase runs on both, and image pairs map back to their particles.

Broadphases (a registry, :data:`BROADPHASES`), all returning the same pairs sorted by ``(i, j)``:

* ``brute-force``: all ``n (n - 1) / 2`` pairs tested; the reference, O(N^2).
* ``grid``: a uniform grid of cell size ``h = 2 R_max + margin``; particles sorted by cell, the
  occupied cells found through an open-addressing hash table, each particle tested against the
  ``3^dim`` cells around its own. O(N) on average for particles of similar size.
* ``hierarchical-grid``: particles put on levels by size (cell sizes ``h_0 2^k``, ``h_0`` from
  the smallest particles), each level its own hashed grid; a particle is tested against its
  own level and every coarser one, so that a few large particles do not make the cells of the many
  small ones large (the hierarchical hash grid of pe/waLBerla). O(N) on average for any mix.
"""
from __future__ import annotations

import numpy as np

from .._jit import njit

_EMPTY = -1


@njit
def _cell_coords(X, h, origin):
    n, dim = X.shape
    c = np.empty((n, dim), dtype=np.int64)
    for i in range(n):
        for a in range(dim):
            c[i, a] = np.int64(np.floor((X[i, a] - origin[a]) / h))
    return c


@njit
def _linear_key(cell, cmin, extent):
    """Row-major linear index of ``cell (dim,)`` in the box of occupied cells (-1 outside it)."""
    k = np.int64(0)
    for a in range(cell.shape[0]):
        c = cell[a] - cmin[a]
        if c < 0 or c >= extent[a]:
            return np.int64(-1)
        k = k * extent[a] + c
    return k


@njit
def _hash(key, mask):
    return (key * np.int64(2654435761)) & mask


@njit
def _build_grid(keys):
    """Sort particles by cell key and hash the occupied cells. Returns the particle order, the
    start of each occupied cell in it (n_cells + 1,), the table (slot -> cell) and its mask."""
    n = keys.shape[0]
    order = np.argsort(keys, kind="mergesort")
    starts = np.empty(n + 1, dtype=np.int64)
    n_cells = 0
    for k in range(n):
        if k == 0 or keys[order[k]] != keys[order[k - 1]]:
            starts[n_cells] = k
            n_cells += 1
    starts[n_cells] = n
    size = 1
    while size < 2 * n_cells + 2:
        size *= 2
    mask = np.int64(size - 1)
    table = np.full(size, _EMPTY, dtype=np.int64)
    for c in range(n_cells):
        s = _hash(keys[order[starts[c]]], mask)
        while table[s] != _EMPTY:
            s = (s + 1) & mask
        table[s] = c
    return order, starts[:n_cells + 1], table, mask


@njit
def _find_cell(key, keys, order, starts, table, mask):
    if key < 0:
        return _EMPTY
    s = _hash(key, mask)
    while table[s] != _EMPTY:
        c = table[s]
        if keys[order[starts[c]]] == key:
            return c
        s = (s + 1) & mask
    return _EMPTY


@njit
def _grid_query(Xq, Rq, idq, Xg, Rg, idg, h, origin, margin, same, count_only, out):
    """Pairs between query particles and the particles of one grid (cell size ``h``). With
    ``same`` the two sets are one and only ``idq < idg`` pairs are kept. Returns the count; fills
    ``out`` (k, 2) unless ``count_only``."""
    dim = Xq.shape[1]
    cells = _cell_coords(Xg, h, origin)
    cmin = np.empty(dim, dtype=np.int64)
    extent = np.empty(dim, dtype=np.int64)
    for a in range(dim):
        cmin[a] = cells[:, a].min()
        extent[a] = cells[:, a].max() - cmin[a] + 1
    keys = np.empty(cells.shape[0], dtype=np.int64)
    for i in range(cells.shape[0]):
        keys[i] = _linear_key(cells[i], cmin, extent)
    order, starts, table, mask = _build_grid(keys)
    qcells = _cell_coords(Xq, h, origin)
    n_off = 3**dim
    cc = np.empty(dim, dtype=np.int64)
    m = 0
    for q in range(Xq.shape[0]):
        for o in range(n_off):
            r = o
            for a in range(dim):
                cc[a] = qcells[q, a] + (r % 3) - 1
                r //= 3
            c = _find_cell(_linear_key(cc, cmin, extent), keys, order, starts, table, mask)
            if c == _EMPTY:
                continue
            for k in range(starts[c], starts[c + 1]):
                g = order[k]
                if same and idg[g] <= idq[q]:
                    continue
                d2 = 0.0
                for a in range(dim):
                    d = Xq[q, a] - Xg[g, a]
                    d2 += d * d
                reach = Rq[q] + Rg[g] + margin
                if d2 <= reach * reach:
                    if not count_only:
                        a0, b0 = idq[q], idg[g]
                        out[m, 0] = min(a0, b0)
                        out[m, 1] = max(a0, b0)
                    m += 1
    return m


def _query(Xq, Rq, idq, Xg, Rg, idg, h, origin, margin, same):
    m = _grid_query(Xq, Rq, idq, Xg, Rg, idg, h, origin, margin, same, True, np.empty((0, 2), np.int64))
    out = np.empty((m, 2), dtype=np.int64)
    _grid_query(Xq, Rq, idq, Xg, Rg, idg, h, origin, margin, same, False, out)
    return out


def _sorted(pairs: np.ndarray) -> np.ndarray:
    if len(pairs) == 0:
        return np.empty((0, 2), dtype=np.int64)
    return pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]


def _prepare(X, R, margin):
    X = np.ascontiguousarray(X, dtype=float)
    if X.ndim == 2 and len(X) > 1:
        span = np.ptp(X, axis=0)
        if np.prod(span / (2.0 * np.max(R) + margin) + 3.0) > 2.0**62:
            raise ValueError("particles spread over more than 2^62 grid cells; use brute-force")
    R = np.ascontiguousarray(np.broadcast_to(np.asarray(R, dtype=float), (len(X),)))
    if X.ndim != 2 or X.shape[1] not in (2, 3):
        raise ValueError(f"centres must be an (n, 2) or (n, 3) array, got shape {X.shape}")
    if np.any(R <= 0) or margin < 0:
        raise ValueError("bounding radii must be positive and the margin non-negative")
    return X, R


def brute_force_pairs(X: np.ndarray, R: np.ndarray, margin: float = 0.0) -> np.ndarray:
    """Candidate pairs (k, 2) int64, ``i < j``, by testing every pair (the reference)."""
    X, R = _prepare(X, R, margin)
    i, j = np.triu_indices(len(X), k=1)
    near = np.linalg.norm(X[i] - X[j], axis=1) <= R[i] + R[j] + margin
    return np.column_stack([i[near], j[near]]).astype(np.int64)


def grid_pairs(X: np.ndarray, R: np.ndarray, margin: float = 0.0) -> np.ndarray:
    """Candidate pairs (k, 2) int64, ``i < j``, sorted, with one uniform hashed grid."""
    X, R = _prepare(X, R, margin)
    if len(X) < 2:
        return np.empty((0, 2), dtype=np.int64)
    h = 2.0 * R.max() + margin
    ids = np.arange(len(X), dtype=np.int64)
    return _sorted(_query(X, R, ids, X, R, ids, h, X.min(axis=0), margin, True))


def hierarchical_grid_pairs(X: np.ndarray, R: np.ndarray, margin: float = 0.0) -> np.ndarray:
    """Candidate pairs (k, 2) int64, ``i < j``, sorted, with one hashed grid per size level."""
    X, R = _prepare(X, R, margin)
    if len(X) < 2:
        return np.empty((0, 2), dtype=np.int64)
    h0 = 2.0 * R.min() + margin
    level = np.maximum(np.ceil(np.log2((2.0 * R + margin) / h0) - 1e-12), 0).astype(int)
    origin = X.min(axis=0)
    groups = [np.flatnonzero(level == k) for k in np.unique(level)]
    sizes = [2.0 * R[g].max() + margin for g in groups]  # cell size of each occupied level
    found = []
    for a, ga in enumerate(groups):
        for b in range(a, len(groups)):
            gb = groups[b]
            found.append(_query(X[ga], R[ga], ga.astype(np.int64), X[gb], R[gb], gb.astype(np.int64),
                                sizes[b], origin, margin, a == b))
    return _sorted(np.concatenate(found))


#: the broadphases by name (the parameter ``contact.broadphase``)
BROADPHASES = {"brute-force": brute_force_pairs, "grid": grid_pairs,
               "hierarchical-grid": hierarchical_grid_pairs}


def candidate_pairs(X: np.ndarray, R: np.ndarray, margin: float = 0.0, method: str = "grid",
                    periods: np.ndarray | None = None, origin: np.ndarray | None = None) -> np.ndarray:
    """Candidate pairs by the broadphase ``method`` (see :data:`BROADPHASES`), (k, 2) int64
    sorted by ``(i, j)``, ``i < j``. With ``periods (dim,)`` (0 along non-periodic axes) and the
    box's lower corner ``origin (dim,)``: the pairs with an image within reach (a pair meets
    through its nearest image only, so each period must hold two of the largest particles)."""
    if method not in BROADPHASES:
        raise ValueError(f"unknown broadphase {method!r}; choose one of {sorted(BROADPHASES)}")
    if periods is None or not np.any(np.asarray(periods) > 0):
        return BROADPHASES[method](X, R, margin)
    X = np.asarray(X, dtype=float)
    R = np.broadcast_to(np.asarray(R, dtype=float), (len(X),))
    L = np.asarray(periods, dtype=float)
    origin = np.zeros_like(L) if origin is None else np.asarray(origin, dtype=float)
    reach = 2.0 * float(R.max(initial=0.0)) + margin
    if np.any((L > 0) & (L < 4.0 * float(R.max(initial=0.0)))):
        raise ValueError(f"periods {L.tolist()} are shorter than two of the largest particles (diameter "
                         f"{2 * R.max():.3g}): a pair could touch two images of each other; use a larger box")
    Y = X.copy()
    periodic = L > 0
    Y[:, periodic] = origin[periodic] + np.mod(X[:, periodic] - origin[periodic], L[periodic])
    owner = np.arange(len(X))
    for a in np.flatnonzero(periodic):  # images of the particles near either side, corners too
        low = Y[:, a] - origin[a] < reach
        high = origin[a] + L[a] - Y[:, a] < reach
        shifted = np.concatenate([Y[low], Y[high]])
        shifted[:, a] += np.concatenate([np.full(low.sum(), L[a]), np.full(high.sum(), -L[a])])
        Y = np.concatenate([Y, shifted])
        owner = np.concatenate([owner, owner[low], owner[high]])
    pairs = BROADPHASES[method](Y, R[owner], margin)
    i, j = owner[pairs[:, 0]], owner[pairs[:, 1]]
    keep = i != j
    pairs = np.unique(np.column_stack([np.minimum(i, j), np.maximum(i, j)])[keep], axis=0)
    return pairs.reshape(-1, 2).astype(np.int64)


def plane_candidates(X: np.ndarray, R: np.ndarray, points: np.ndarray, normals: np.ndarray,
                     margin: float = 0.0):
    """Particle–plane candidates: (particle (k,), plane (k,)) int64, sorted, for planes through
    ``points (p, dim)`` with unit ``normals (p, dim)`` pointing into the domain; a particle is a
    candidate when its bounding ball comes within ``margin`` of the plane (O(N p))."""
    X, R = _prepare(X, R, margin)
    gap = (X @ normals.T - np.einsum("pk,pk->p", points, normals)[None, :]) - R[:, None]
    part, plane = np.nonzero(gap <= margin)
    return part.astype(np.int64), plane.astype(np.int64)
