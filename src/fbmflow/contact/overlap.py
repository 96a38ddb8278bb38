"""How deep particles reach into the walls and into each other: the physical sanity check a run
makes after every step, whatever keeps the particles apart (hard contact, repulsion, or nothing).

The depths are the narrowphase's gaps (:mod:`~fbmflow.contact.narrowphase`), negated: into a wall
exact for every shape with an exact support; between two balls exact; between other shapes the
separation of their projections on the centre line, a lower bound of their distance (so a depth
that can exceed the true overlap, never fall short of it). Candidate pairs come from the
broadphase within the larger bounding radius, so nothing loops over particles in Python.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..particles import Particles
from .broadphase import candidate_pairs
from .narrowphase import Planes, pair_contacts, plane_contacts


@dataclass(frozen=True)
class Overlap:
    """The deepest reach of one particle: ``depth`` [m] (> 0 inside), over ``radius`` the
    particle's (the smaller bounding radius of a pair) in ``fraction``; ``particle`` and ``other``
    (another particle's index, or -1 for a wall, then ``wall`` its ``(axis, side)``)."""

    fraction: float
    depth: float
    particle: int
    other: int
    wall: tuple | None


def deepest_overlap(p: Particles, planes: Planes | None, periods: np.ndarray | None = None,
                    origin: np.ndarray | None = None) -> Overlap | None:
    """The deepest overlap of the particles ``p`` with the ``planes`` (a box's walls, inward
    normals; None: none) and with each other (through the nearest image along the axes with
    ``periods > 0``, the box's lower corner ``origin``), relative to the particle's bounding
    radius; None when nothing overlaps."""
    n = p.n
    if n == 0:
        return None
    R = p.bounding_radius
    best: Overlap | None = None
    if planes is not None and planes.n:
        part = np.repeat(np.arange(n), planes.n)
        plane = np.tile(np.arange(planes.n), n)
        c = plane_contacts(p, part, plane, planes)
        frac = -c.gap / R[c.i]
        k = int(np.argmax(frac))
        if frac[k] > 0.0:
            w = plane[k]
            axis = int(np.argmax(np.abs(planes.normals[w])))
            side = 0 if planes.normals[w, axis] > 0 else 1
            best = Overlap(float(frac[k]), float(-c.gap[k]), int(c.i[k]), -1, (axis, side))
    if n > 1:
        pairs = candidate_pairs(p.position, R, 0.0, periods=periods, origin=origin)
        if len(pairs):
            c = pair_contacts(p, pairs, periods)
            frac = -c.gap / np.minimum(R[c.i], R[c.j])
            k = int(np.argmax(frac))
            if frac[k] > 0.0 and (best is None or frac[k] > best.fraction):
                best = Overlap(float(frac[k]), float(-c.gap[k]), int(c.i[k]), int(c.j[k]), None)
    return best
