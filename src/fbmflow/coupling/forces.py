"""Hydrodynamic forces and torques on fictitious-boundary particles (volume integral over the
cells cut by each particle)."""
from __future__ import annotations

import numpy as np

from ..fem.space import FlowSpace
from . import _kernels


def cut_cells(space: FlowSpace, owner: np.ndarray) -> np.ndarray:
    """Cells whose nodes are not all owned by one and the same particle but some are owned:
    (n_cut,) int64."""
    o = owner[space.V.cell_dofs]
    return np.flatnonzero((o.max(axis=1) >= 0) & (o.min(axis=1) != o.max(axis=1)))


def hydrodynamic_forces(space: FlowSpace, owner: np.ndarray, centres: np.ndarray, u: np.ndarray,
                        p: np.ndarray, mu: float):
    """Force (n_particles, dim) [N] and torque (n_particles, 3) [N m] from the flow ``u (dim * n_v,)``,
    ``p (n_p,)`` with dynamic viscosity ``mu``; periodic minimum images are not applied to the
    torque arm (particles must not straddle a periodic side)."""
    cells = cut_cells(space, owner)
    d = space.dim
    return _kernels.fbm_force_torque(cells, owner, len(centres), np.asarray(centres, dtype=float),
                                     np.ascontiguousarray(u.reshape(d, space.n_v)), p, mu,
                                     space.V.cell_dofs, space.phi, space.dphi, space.detJw,
                                     space.Jinv, space.psi, space.xq)


def mirror_images(force: np.ndarray, torque: np.ndarray, axes) -> tuple[np.ndarray, np.ndarray]:
    """Force and torque of whole particles cut by symmetry planes through their centres.

    ``axes``: the normal axis of every mirror plane (e.g. ``(0, 1)`` for a quarter domain cut by
    the planes x = X and y = Y). The mirror image across the plane with normal ``a`` flips the
    ``a`` component of the force and, the torque being a pseudo-vector, every other component of
    the torque; the whole particle gets the sum of all images. ``force (n, dim)``,
    ``torque (n, 3)``; returns new arrays.
    """
    F, T = np.array(force, dtype=float), np.array(torque, dtype=float)
    for a in axes:
        flip_f = np.ones(F.shape[1])
        flip_f[a] = -1.0
        flip_t = -np.ones(3)
        flip_t[a] = 1.0
        F, T = F + F * flip_f, T + T * flip_t
    return F, T
