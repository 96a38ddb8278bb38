"""Hard contact between rigid particles and walls: a velocity-level LCP per sub-step, solved by
projected Gauss–Seidel in named stages (Box2D's sequential impulses).

One contact sub-step of length ``h`` (:meth:`ContactSet.substep`):

1. **kick**: ``v += h a``, ``w += h alpha`` with the accelerations from gravity, buoyancy and the
   hydrodynamic force (held constant over the fluid step);
2. **detect**: broadphase with margin ``2 h max|v| + R_min / 10`` (every pair that could touch
   within the sub-step, and near neighbours for the position projection), narrowphase (contact
   points, normals, gaps ``g``);
3. **prepare**: per contact a normal row and (with friction) two tangent rows, their effective
   masses, and the normal target velocity ``u*``: *speculative* ``u* = -g / h`` for ``g > 0``
   (the pair may close its gap in this sub-step but not more) and ``0`` for ``g <= 0``; for a
   *collision*, ``u_n < -u_threshold`` and ``g + h u_n < 0`` (it would arrive within the
   sub-step), ``u* = -e u_n`` with restitution ``e``, so an elastic pair leaves with its approach
   speed reversed exactly and an inelastic one with none;
   With a lubrication correction, the film force of close pairs damps their approach
   implicitly here (:mod:`fbmflow.contact.lubrication`).
4. **warm start** with the impulses stored for the same pair ``(i, j)`` at the last sub-step;
5. **iterate**: PGS sweeps on the LCP ``lambda >= 0, u_n - u* >= 0, lambda (u_n - u*) = 0``
   with Coulomb friction ``|lambda_t| <= mu lambda_n`` (accumulated impulses clamped);
6. **store** the impulses for the next warm start;
7. **drift**: ``X += h v``, orientations by ``w``; then a Gauss–Seidel **position projection**
   (positions only, so it adds no kinetic energy) removes what overlap is left (from sweeps that
   stopped short) and puts each pair that collided at the gap ``e (h |u_n| - g)`` it would have
   had, had it met at ``t = g / |u_n|`` and left at ``e |u_n|``: for a binary collision positions
   and velocities are then those of an exact event-driven collision, and an inelastic pair ends
   in contact.

With a single contact the PGS reduces to the classical pair impulse
``lambda = -(1 + e) u_n / k``. Simultaneous collisions inside one sub-step are one LCP (momentum
kept, energy in general not, as in every velocity-level method); collisions in successive
sub-steps are resolved one after another, so a Newton's cradle with gaps larger than ``h |v|``
transmits its momentum ball by ball.

Coupled to a fluid step of length ``dt`` (:meth:`ContactSet.advance`) the particles take
``substeps`` such sub-steps with the fluid's force held constant, so the contact resolution does
not depend on the fluid time step.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..particles import Particles, quaternion_step
from . import _kernels
from .broadphase import BROADPHASES, candidate_pairs, plane_candidates
from .narrowphase import Contacts, Planes, concatenate, pair_contacts, plane_contacts


@dataclass
class ContactReport:
    """What the contact solver did over one call of :meth:`ContactSet.advance` (or one sub-step)."""

    substeps: int = 0
    contacts: int = 0          # most contacts in one sub-step
    sweeps: int = 0            # PGS sweeps, all sub-steps
    residual: float = 0.0      # natural LCP residual after the last sub-step's sweeps [N s]
    max_overlap: float = 0.0   # largest overlap after the position projection [m]
    history: np.ndarray = field(default_factory=lambda: np.zeros(0))  # last sub-step's residuals
    detect_s: float = 0.0      # wall time of broadphase + narrowphase [s]
    solve_s: float = 0.0       # wall time of prepare, warm start, sweeps, store, projection [s]


@dataclass
class _Rows:
    """The prepared LCP of one sub-step (3D-padded arrays over contacts)."""

    contacts: Contacts
    keys: np.ndarray
    ci: np.ndarray
    cj: np.ndarray
    D: np.ndarray   # (m, 3, 3) row directions: normal, tangent 1, tangent 2
    Ai: np.ndarray
    Aj: np.ndarray
    Bi: np.ndarray
    Bj: np.ndarray
    K: np.ndarray   # (m, 3) effective inverse masses
    target: np.ndarray
    goal: np.ndarray  # (m,) gap at the end of the sub-step for collisions, NaN otherwise
    lam: np.ndarray  # (m, 3) accumulated impulses


def _pad(a: np.ndarray) -> np.ndarray:
    """``a (m, k)``, k <= 3, as a C-contiguous float (m, 3) array, zeros in the added columns."""
    if a.shape[1] == 3:
        return np.ascontiguousarray(a, dtype=float)
    out = np.zeros((a.shape[0], 3))
    out[:, :a.shape[1]] = a
    return out


def _tangents(n: np.ndarray, dim: int):
    """Unit tangents (m, 3) x 2 of unit normals ``n (m, 3)``; in 2D the second is zero."""
    if dim == 2:
        return np.column_stack([-n[:, 1], n[:, 0], np.zeros(len(n))]), np.zeros_like(n)
    e = np.eye(3)[np.argmin(np.abs(n), axis=1)]
    t1 = np.cross(n, e)
    t1 /= np.linalg.norm(t1, axis=1)[:, None]
    return t1, np.cross(n, t1)


class ContactSet:
    """Contacts of a set of particles with each other and with planes (the domain walls).

    Parameters
    ----------
    planes : :class:`~fbmflow.contact.narrowphase.Planes` or None, e.g. ``Planes.box(lower, upper)``
    restitution : coefficient of restitution ``e`` in [0, 1]
    friction : Coulomb coefficient ``mu >= 0`` (0: frictionless, no tangent rows)
    iterations : PGS sweeps per sub-step at most
    tol : stop the sweeps once the natural residual is below ``tol`` times the largest impulse
    restitution_threshold : approach speeds below this [m/s] are resting contact, not collisions;
        default (None) ``2 h max|a|``, twice what the other forces add in one sub-step ``h``, so
        that particles resting under gravity do not bounce on every sub-step
    broadphase : name in :data:`~fbmflow.contact.broadphase.BROADPHASES`
    slop : overlap the position projection leaves alone [m]
    projection_sweeps : Gauss–Seidel sweeps of the position projection at most
    skin : contact distance [m]: surfaces touch when their gap is ``skin`` (0: at the true
        surfaces). Coupled to a fluid on a fixed mesh, a skin of a mesh cell keeps a layer of
        free fluid nodes between surfaces, which the fictitious boundary method needs.
    lubrication : :class:`~fbmflow.contact.lubrication.Lubrication` or None, the film force
        below the resolved gap, applied implicitly before the contact impulses of each sub-step
    periods : (dim,) or None, the period of every axis of a box with periodic sides (0 along
        the others), whose lower corner is ``origin (dim,)``: pairs meet through their nearest
        images (:func:`~fbmflow.contact.broadphase.candidate_pairs`); the planes should then
        leave out the periodic faces
    """

    def __init__(self, planes: Planes | None = None, restitution: float = 0.0, friction: float = 0.0,
                 iterations: int = 50, tol: float = 1e-8, restitution_threshold: float | None = None,
                 broadphase: str = "grid", slop: float = 0.0, projection_sweeps: int = 20,
                 skin: float = 0.0, lubrication=None, periods=None, origin=None):
        if not 0.0 <= restitution <= 1.0:
            raise ValueError(f"restitution must lie in [0, 1], got {restitution}")
        if friction < 0 or (restitution_threshold or 0.0) < 0 or slop < 0 or skin < 0:
            raise ValueError("friction, restitution_threshold, slop and skin must be non-negative")
        if iterations < 1 or projection_sweeps < 0:
            raise ValueError("iterations must be >= 1 and projection_sweeps >= 0")
        if broadphase not in BROADPHASES:
            raise ValueError(f"unknown broadphase {broadphase!r}; choose one of {sorted(BROADPHASES)}")
        self.planes = planes
        self.restitution = float(restitution)
        self.friction = float(friction)
        self.iterations = int(iterations)
        self.tol = float(tol)
        self.restitution_threshold = restitution_threshold
        self.broadphase = broadphase
        self.slop = float(slop)
        self.projection_sweeps = int(projection_sweeps)
        self.skin = float(skin)
        self.lubrication = lubrication
        self.periods = None if periods is None or not np.any(np.asarray(periods) > 0) else \
            np.asarray(periods, dtype=float)
        self.origin = None if origin is None else np.asarray(origin, dtype=float)
        # warm-start state: sorted pair keys, normal impulses, friction impulses (world vectors)
        self._stored_keys = np.zeros(0, dtype=np.int64)
        self._stored_normal = np.zeros(0)
        self._stored_friction = np.zeros((0, 3))
        # pair list of the current advance (Verlet list): positions, reach and pairs of its broadphase
        self._pair_list = None

    # --- warm-start state (for checkpoints) -------------------------------------------------
    def state(self) -> dict:
        """The warm-start impulses, to be saved with a checkpoint."""
        return {"keys": self._stored_keys.copy(), "normal": self._stored_normal.copy(),
                "friction": self._stored_friction.copy()}

    def set_state(self, state: dict) -> None:
        keys = np.asarray(state["keys"], dtype=np.int64)
        normal = np.asarray(state["normal"], dtype=float)
        friction = np.asarray(state["friction"], dtype=float)
        if normal.shape != keys.shape or friction.shape != (len(keys), 3) or np.any(np.diff(keys) <= 0):
            raise ValueError("contact warm-start state is inconsistent: keys must be sorted and unique, "
                             "with one normal impulse and one friction vector (3,) per key")
        self._stored_keys, self._stored_normal, self._stored_friction = keys, normal, friction

    # --- stages --------------------------------------------------------------------------------
    def detect(self, p: Particles, margin: float) -> Contacts:
        """Contacts of every pair (and particle–plane pair) whose gap may be below ``margin``; the
        gaps are measured from the skin (``gap - skin``)."""
        margin = margin + self.skin
        R = p.bounding_radius
        pairs = self._candidate_pairs(p.position, R, margin)
        contacts = pair_contacts(p, pairs, self.periods)
        if self.planes is not None:
            part, plane = plane_candidates(p.position, R, self.planes.points, self.planes.normals, margin)
            contacts = concatenate(contacts, plane_contacts(p, part, plane, self.planes))
        both_fixed = p.fixed[contacts.i] & np.where(contacts.j >= 0, p.fixed[np.maximum(contacts.j, 0)], True)
        if both_fixed.any():
            contacts = contacts.select(~both_fixed)
        contacts.gap = contacts.gap - self.skin
        return contacts

    def _candidate_pairs(self, X: np.ndarray, R: np.ndarray, margin: float) -> np.ndarray:
        """The broadphase's pairs within ``margin`` (:func:`~fbmflow.contact.broadphase.
        candidate_pairs`). Inside :meth:`advance` they come from a pair list of twice the reach,
        kept while no particle has moved far enough since its broadphase to bring in a pair the
        list lacks (``margin + 2 max|X - X_0| <= reach``), and picked from it by the
        broadphase's own test ``|X_i - X_j| <= R_i + R_j + margin`` (nearest images on
        periodic axes): the same pairs, one broadphase per few sub-steps."""
        kept = self._pair_list
        if kept is None:
            return candidate_pairs(X, R, margin, self.broadphase, self.periods, self.origin)
        moved = np.inf if kept[0] is None else float(np.max(np.linalg.norm(X - kept[0], axis=1), initial=0.0))
        if margin + 2.0 * moved > kept[1]:
            reach = 2.0 * margin
            pairs = candidate_pairs(X, R, reach, self.broadphase, self.periods, self.origin)
            kept = self._pair_list = (X.copy(), reach, pairs)
        pairs = kept[2]
        d = X[pairs[:, 0]] - X[pairs[:, 1]]
        if self.periods is not None:
            L = self.periods[None, :]
            d = np.where(L > 0, d - L * np.round(d / np.where(L > 0, L, 1.0)), d)
        return pairs[np.linalg.norm(d, axis=1) <= R[pairs[:, 0]] + R[pairs[:, 1]] + margin]

    def prepare(self, p: Particles, contacts: Contacts, v: np.ndarray, w: np.ndarray, h: float,
                inv_m: np.ndarray, inv_I: np.ndarray, threshold: float) -> _Rows:
        """Rows, effective masses and targets of the LCP (module docstring, stage 3)."""
        ci, cj = contacts.i, contacts.j
        jj = np.maximum(cj, 0)
        wall = (cj < 0)[:, None]
        n = _pad(contacts.normal)
        t1, t2 = _tangents(n, p.dim)
        if self.friction == 0.0:
            t1, t2 = np.zeros_like(n), np.zeros_like(n)
        D = np.ascontiguousarray(np.stack([n, t1, t2], axis=1))
        X, point = _pad(p.position), _pad(contacts.point)
        ri, rj = point - X[ci], np.where(wall, 0.0, point - X[jj] - _pad(contacts.image))
        Ai, Aj, Bi, Bj, K = _kernels.row_masses(ci, cj, D, ri, rj, inv_m, inv_I)
        gap = contacts.gap
        u_n = _kernels.row_velocities(ci, cj, D, Ai, Aj, v, w, 0)
        target = np.where(gap > 0, -gap / h, 0.0)
        collide = (u_n < -threshold) & (gap + h * u_n < 0)
        target = np.where(collide, -self.restitution * u_n, target)
        # where the pair is at the end of the sub-step had it met at t = g / |u_n| and left at e |u_n|
        goal = np.where(collide, self.restitution * np.maximum(-h * u_n - np.maximum(gap, 0.0), 0.0), np.nan)
        keys = contacts.keys(0 if self.planes is None else self.planes.n)
        return _Rows(contacts, keys, ci, cj, D, Ai, Aj, Bi, Bj, K, target, goal, np.zeros((len(ci), 3)))

    def lubricate(self, p: Particles, rows: _Rows, v, w, h: float, inv_m) -> None:
        """Implicit lubrication damping of the approach of close pairs (before the warm start)."""
        R = p.bounding_radius
        R_j = np.where(rows.cj >= 0, R[np.maximum(rows.cj, 0)], np.inf)
        c = self.lubrication.coefficient(rows.contacts.gap + self.skin, R[rows.ci], R_j, p.dim)
        _kernels.lubricate(rows.ci, rows.cj, rows.D, rows.Ai, rows.Aj, rows.Bi, rows.Bj, rows.K, c, h, inv_m,
                           v, w)

    def warm_start(self, rows: _Rows, v, w, inv_m) -> None:
        """Start from the impulses of the same pairs at the last sub-step (stage 4); the friction
        impulse is kept as a world vector and projected on the new tangents."""
        if len(self._stored_keys) and len(rows.keys):
            at = np.clip(np.searchsorted(self._stored_keys, rows.keys), 0, len(self._stored_keys) - 1)
            hit = self._stored_keys[at] == rows.keys
            rows.lam[hit, 0] = self._stored_normal[at[hit]]
            if self.friction > 0:
                rows.lam[hit, 1:] = np.einsum("ma,mqa->mq", self._stored_friction[at[hit]], rows.D[hit, 1:])
        _kernels.warm_start(rows.ci, rows.cj, rows.D, rows.Bi, rows.Bj, inv_m, rows.lam, v, w)

    def iterate(self, rows: _Rows, v, w, inv_m) -> tuple[int, np.ndarray]:
        """PGS sweeps (stage 5); returns the sweeps done and the natural residual after each."""
        history = np.zeros(self.iterations)
        scale = max(float(np.abs(rows.lam[:, 0]).max(initial=0.0)),
                    float(np.max(np.abs(rows.target) / rows.K[:, 0], initial=0.0)), 1e-300)
        done = _kernels.pgs(rows.ci, rows.cj, rows.D, rows.Ai, rows.Aj, rows.Bi, rows.Bj, rows.K,
                            rows.target, self.friction, inv_m, rows.lam, v, w, self.iterations,
                            self.tol * scale, history)
        return done, history[:done]

    def store(self, rows: _Rows) -> None:
        """Keep the impulses, keyed by pair, for the next warm start (stage 6)."""
        order = np.argsort(rows.keys)
        self._stored_keys = rows.keys[order]
        self._stored_normal = rows.lam[order, 0].copy()
        self._stored_friction = np.einsum("mq,mqa->ma", rows.lam[order, 1:], rows.D[order, 1:])

    # --- time stepping -------------------------------------------------------------------------
    def substep(self, p: Particles, lin_acc: np.ndarray, ang_acc: np.ndarray,
                h: float) -> tuple[Particles, ContactReport]:
        """One contact sub-step of length ``h`` [s] (module docstring): the new particle state.

        ``lin_acc (n, dim)`` [m/s^2] and ``ang_acc`` ((n,) in 2D, (n, 3) in 3D) [1/s^2] are the
        accelerations of every force but contact."""
        if not h > 0:
            raise ValueError(f"contact sub-step must be positive, got {h}")
        dim, n = p.dim, p.n
        free = ~p.fixed
        inv_m = np.where(free, 1.0 / p.mass, 0.0)
        inv_I = np.zeros((n, 3, 3))
        if dim == 2:
            inv_I[:, 2, 2] = 1.0 / p.inertia_world()[:, 0, 0]
        else:
            inv_I[:] = np.linalg.inv(p.inertia_world())
        inv_I[~free] = 0.0
        v = _pad(p.velocity + h * np.where(free[:, None], lin_acc, 0.0))
        ang = np.reshape(p.angular_velocity + h * np.where(free.reshape((n,) + (1,) * (np.ndim(ang_acc) - 1)),
                                                           ang_acc, 0.0), (n, -1))
        w = np.zeros((n, 3))
        w[:, 3 - ang.shape[1]:] = ang
        speed = float(np.linalg.norm(v, axis=1).max(initial=0.0))
        # every pair that may touch within the sub-step, and the near neighbours the position
        # projection may push a particle into
        start = time.perf_counter()
        margin = 2.0 * h * speed + 0.1 * float(p.bounding_radius.min())
        if self.lubrication is not None:
            margin = max(margin, self.lubrication.range_ - self.skin)
        contacts = self.detect(p, margin)
        report = ContactReport(substeps=1, contacts=contacts.m, detect_s=time.perf_counter() - start)
        start = time.perf_counter()
        dX = h * v
        if contacts.m:
            threshold = self.restitution_threshold
            if threshold is None:
                fastest = np.linalg.norm(np.where(free[:, None], lin_acc, 0.0), axis=1).max(initial=0.0)
                threshold = 2.0 * h * float(fastest)
            rows = self.prepare(p, contacts, v, w, h, inv_m, inv_I, threshold)
            if self.lubrication is not None:
                self.lubricate(p, rows, v, w, h, inv_m)
            self.warm_start(rows, v, w, inv_m)
            report.sweeps, report.history = self.iterate(rows, v, w, inv_m)
            report.residual = float(report.history[-1]) if len(report.history) else 0.0
            self.store(rows)
            dX = h * v
            report.max_overlap = max(_kernels.project_positions(
                rows.ci, rows.cj, np.ascontiguousarray(rows.D[:, 0]), contacts.gap, rows.goal, inv_m, dX,
                self.projection_sweeps, self.slop), 0.0)
        else:
            self._stored_keys, self._stored_normal, self._stored_friction = \
                np.zeros(0, dtype=np.int64), np.zeros(0), np.zeros((0, 3))
        report.solve_s = time.perf_counter() - start
        new = p.copy()
        new.velocity = v[:, :dim].copy()
        new.position = p.position + dX[:, :dim]
        if dim == 2:
            new.angular_velocity = w[:, 2].copy()
            new.orientation = p.orientation + h * new.angular_velocity
        else:
            new.angular_velocity = w.copy()
            new.orientation = quaternion_step(p.orientation, w, h)
        return new, report

    def advance(self, p: Particles, lin_acc: np.ndarray, ang_acc: np.ndarray, dt: float,
                substeps: int = 1) -> tuple[Particles, ContactReport]:
        """``substeps`` contact sub-steps over ``dt`` with the accelerations held constant."""
        if substeps < 1:
            raise ValueError(f"substeps must be >= 1, got {substeps}")
        total = ContactReport()
        self._pair_list = (None, 0.0, None)  # the sub-steps share a pair list (_candidate_pairs)
        try:
            for _ in range(substeps):
                p, r = self.substep(p, lin_acc, ang_acc, dt / substeps)
                total.substeps += 1
                total.contacts = max(total.contacts, r.contacts)
                total.sweeps += r.sweeps
                total.residual, total.history = r.residual, r.history
                total.max_overlap = max(total.max_overlap, r.max_overlap)
                total.detect_s += r.detect_s
                total.solve_s += r.solve_s
        finally:
            self._pair_list = None
        return p, total
