"""Where the particles may be and what the domain's faces are to them: the checks of a set-up
before anything is assembled (placement, mirror planes), the walls of contact and repulsion, the
wrap of centres across periodic sides, and the mean pressure gradient that carries a periodic
suspension's weight (the periodic drive). Functions of the mesh's box and the particles' state;
they solve nothing."""
from __future__ import annotations

import numpy as np

from ..contact import Planes, candidate_pairs
from ..contact.narrowphase import pair_contacts, plane_contacts
from ..particles import Particles


def check_symmetry(mesh, particles: Particles, gravity: np.ndarray, axes: tuple):
    """Mirror planes must be domain faces through every particle centre, parallel to gravity."""
    for a in axes:
        if not 0 <= a < mesh.dim:
            raise ValueError(f"symmetry axis {a} is not an axis of a {mesh.dim}D mesh")
        tol = 1e-9 * (mesh.upper[a] - mesh.lower[a])
        on = np.isclose(particles.position[:, a], mesh.lower[a], atol=tol) | \
            np.isclose(particles.position[:, a], mesh.upper[a], atol=tol)
        if not on.all():
            raise ValueError(f"symmetry plane with normal axis {a}: particles {np.flatnonzero(~on).tolist()} "
                             "are not centred on it; put their centres on the domain face or drop the "
                             "symmetry")
        if gravity[a] != 0.0:
            raise ValueError(f"symmetry plane with normal axis {a}: gravity has a component {gravity[a]} "
                             "across it; the motion would not be symmetric")


def periodic_drive(mesh, particles: Particles, gravity: np.ndarray, fluid_density: float,
                   symmetry: tuple = ()) -> np.ndarray:
    """Force per unit volume on the fluid [N/m^3], (dim,) float64, that carries the free particles'
    weight in the fluid along the periodic axes of ``mesh``: the mean pressure gradient of a
    periodic suspension, zero where gravity has no periodic component.

        f = - sum_i (M_i - rho_f V_i) g_per / Omega,

    ``g_per`` the components of ``gravity`` along periodic axes and ``Omega`` the box's volume
    (the particles counted by their share of the box, ``2^-k`` with ``k`` mirror planes through
    their centres). The fluid feels ``f`` and every free particle ``f V_i``, so the net force on
    fluid and particles together vanishes: without it a periodic suspension would accelerate
    without end. Its mean volume flux stays what it started with (zero from rest).
    """
    g = np.where(mesh.periodic, np.asarray(gravity, dtype=float), 0.0)
    if not np.any(g) or particles.n == 0:
        return np.zeros(mesh.dim)
    free = ~particles.fixed
    excess = float(np.sum(particles.mass[free] - fluid_density * particles.volume[free]))
    box = float(np.prod(np.array(mesh.upper) - np.array(mesh.lower)))
    return -excess * 0.5 ** len(symmetry) / box * g


def wrap(mesh, X: np.ndarray) -> np.ndarray:
    """Centres ``X (n, dim)`` moved into ``[lower, upper)`` along the periodic axes (a new array)."""
    L = mesh.periods
    if not np.any(L):
        return X
    lower = np.array(mesh.lower, dtype=float)
    return np.where(L > 0, lower + np.mod(X - lower, np.where(L > 0, L, 1.0)), X)


def check_placement(mesh, particles: Particles, symmetry: tuple):
    """The particles must fit the domain: of the same dimension, inside it (every shape by its
    support, :func:`~fbmflow.contact.narrowphase.plane_contacts`; along periodic axes anywhere;
    the walls' faces only, not symmetry planes; fixed particles, obstacles, may cross the walls),
    apart from each other (balls exactly, other shapes by their projections on the centre line,
    :func:`~fbmflow.contact.narrowphase.pair_contacts`; across periodic sides through the nearest
    image), and each must span the velocity-node spacing (half a cell) where it sits: a smaller
    one can cover no node and feel no drag. ValueError naming the particles and the remedy."""
    X, n = particles.position, particles.n
    if n == 0:
        return
    if particles.dim != mesh.dim:
        raise ValueError(f"the particles are {particles.dim}D and the mesh {mesh.dim}D; make the shapes and "
                         f"positions {mesh.dim}D (e.g. Ball(r, dim={mesh.dim}))")
    R = particles.bounding_radius
    free = np.flatnonzero(~particles.fixed)
    faces = walls(mesh, particles, symmetry)
    planes = Planes.box(mesh.lower, mesh.upper, faces)
    if planes.n and free.size:
        part, plane = np.repeat(free, planes.n), np.tile(np.arange(planes.n), free.size)
        c = plane_contacts(particles, part, plane, planes)
        out = np.flatnonzero(c.gap < -1e-9 * R[c.i])
        if out.size:
            k, w = int(c.i[out[0]]), plane[out[0]]
            axis = int(np.argmax(np.abs(planes.normals[w])))
            lo, hi = float(mesh.lower[axis]), float(mesh.upper[axis])
            raise ValueError(f"particle {k} (centre {X[k].tolist()}, bounding radius {R[k]:.4g}) reaches "
                             f"outside the domain along axis {axis} "
                             f"([{lo:.4g}, {hi:.4g}]) by {-c.gap[out[0]]:.4g}"
                             f"{_more(np.unique(c.i[out]))}; move it inside")
    if n > 1:
        periods = mesh.periods if any(mesh.periodic) else None
        pairs = candidate_pairs(X, R, 0.0, periods=periods, origin=np.array(mesh.lower, dtype=float))
        pairs = pairs[~(particles.fixed[pairs[:, 0]] & particles.fixed[pairs[:, 1]])] if len(pairs) else pairs
        if len(pairs):
            c = pair_contacts(particles, pairs, periods)
            scale = np.minimum(R[c.i], R[c.j])
            bad = np.flatnonzero(c.gap < -1e-9 * scale)
            if bad.size:
                i, j = int(c.i[bad[0]]), int(c.j[bad[0]])
                raise ValueError(f"particles {i} and {j} overlap by {-c.gap[bad[0]]:.4g} (centres "
                                 f"{X[i].tolist()} and {X[j].tolist()}){_more(bad)}; place them at least a "
                                 "diameter apart")
    if mesh.axis_coordinates is not None:
        small, h = too_small(mesh, particles.position, particles.bounding_radius)
        if small.size:
            k = small[0]
            raise ValueError(f"particle {k} (diameter {2 * particles.bounding_radius[k]:.4g}) is smaller "
                             "than the velocity-node spacing, half the cell it sits in (cell size "
                             f"{h[k]:.4g}){_more(small)}: it can cover no velocity node and feel no drag; "
                             "refine the mesh (cells of at most two diameters; 4 or more cells per diameter "
                             "for accurate forces) or enlarge the particles")


def too_small(mesh, X: np.ndarray, radius: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The particles at ``X (n, dim)`` with bounding ``radius (n,)`` that span less than the
    velocity-node spacing (half the cell) where they sit, (k,) int64, and the local cell size
    (the largest of the cell's sides), (n,) float64; on a uniform mesh its spacing."""
    axes = mesh.axis_coordinates
    if axes is None:
        h = np.full(len(X), float(np.max(mesh.spacing)))
    else:
        h = np.max([np.diff(ax)[np.clip(np.searchsorted(ax, X[:, a]) - 1, 0, ax.size - 2)]
                    for a, ax in enumerate(axes)], axis=0)
    return np.flatnonzero(2.0 * radius < 0.5 * h), h


def _more(indices: np.ndarray) -> str:
    return f" (and {indices.size - 1} more)" if indices.size > 1 else ""


def walls(mesh, particles: Particles, symmetry: tuple):
    """The domain faces ``(axis, side)`` that are walls for contact and repulsion: all of them
    (None) without mirror planes and periodic axes, else all but the periodic faces and those the
    particles are centred on."""
    if not symmetry and not any(mesh.periodic):
        return None
    walls = []
    for a in range(mesh.dim):
        if mesh.periodic[a]:
            continue
        for side, face in enumerate((mesh.lower[a], mesh.upper[a])):
            on_plane = a in symmetry and np.allclose(particles.position[:, a], face,
                                                     atol=1e-9 * (mesh.upper[a] - mesh.lower[a]))
            if not on_plane:
                walls.append((a, side))
    return walls
