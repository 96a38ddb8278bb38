"""Newton–Euler equations of the particles, with gravity and buoyancy.

    M_i dU_i/dt = F_i + (M_i - rho_f V_i) g,      d(I_i omega_i)/dt = T_i,
    dX_i/dt = U_i,                                 orientation by omega_i.

Integrators (a registry):

* ``explicit-euler``: ``U, omega`` and ``X, theta`` from the old accelerations and velocities.
* ``semi-implicit-euler`` (symplectic): velocities first, then positions with the new
  velocities; the default. With an explicit (staggered) fluid coupling both are stable only while
  the added mass is smaller than the particle mass, roughly ``rho_s / rho_f`` above about 1 for a
  disk or 0.5 for a sphere; density ratios closer to 1 need sub-iterated (implicit) coupling.
* ``trapezoidal``: velocities with the mean of the old and the new accelerations, positions with
  the mean of the old and the new velocities; second order when the forces are (with the
  Crank–Nicolson flow scheme and the implicit coupling, whose new forces belong to the new
  velocities). A-stable but not damping: a force relaxing the velocity in much less than a
  step (``dt`` above about twice the particle's response time) makes it oscillate.
"""
from __future__ import annotations

import numpy as np

from .state import Particles


def quaternion_step(q: np.ndarray, omega: np.ndarray, dt: float) -> np.ndarray:
    """Rotate unit quaternions ``q (n, 4)`` by world angular velocity ``omega (n, 3)`` over dt."""
    angle = np.linalg.norm(omega, axis=1) * dt
    axis = np.divide(omega, np.linalg.norm(omega, axis=1)[:, None], out=np.zeros_like(omega),
                     where=np.linalg.norm(omega, axis=1)[:, None] > 0)
    dq = np.column_stack([np.cos(angle / 2), axis * np.sin(angle / 2)[:, None]])
    w1, v1 = dq[:, 0], dq[:, 1:]
    w2, v2 = q[:, 0], q[:, 1:]
    out = np.column_stack([w1 * w2 - np.einsum("ij,ij->i", v1, v2),
                           w1[:, None] * v2 + w2[:, None] * v1 + np.cross(v1, v2)])
    return out / np.linalg.norm(out, axis=1)[:, None]


def accelerations(p: Particles, force: np.ndarray, torque: np.ndarray, gravity: np.ndarray,
                  fluid_density: float):
    """Linear (n, dim) and angular accelerations ((n,) in 2D, (n, 3) in 3D)."""
    mass = p.mass
    lin = force / mass[:, None] + (1.0 - fluid_density / p.density)[:, None] * gravity[None, :]
    inertia = p.inertia_world()
    if p.dim == 2:
        ang = torque[:, 2] / inertia[:, 0, 0]
    else:
        Iw = np.einsum("nij,nj->ni", inertia, p.angular_velocity)
        ang = np.linalg.solve(inertia, (torque - np.cross(p.angular_velocity, Iw))[:, :, None])[:, :, 0]
    lin[p.fixed] = 0.0
    ang[p.fixed] = 0.0
    return lin, ang


def pack_velocities(p: Particles) -> np.ndarray:
    """Generalised velocities ``[U_i, omega_i]`` of every particle, (n, r) with ``r = 3`` in 2D
    (``U_x, U_y, omega_z``) and 6 in 3D."""
    return np.column_stack([p.velocity, np.reshape(p.angular_velocity, (p.n, -1))])


def unpack_velocities(p: Particles, v: np.ndarray) -> None:
    """Set ``p``'s velocities from generalised velocities ``v (n, r)`` in place."""
    p.velocity = v[:, :p.dim].copy()
    p.angular_velocity = v[:, p.dim:].reshape(np.shape(p.angular_velocity)).copy()


def symmetric_motion(dim: int, axes) -> np.ndarray:
    """Generalised velocity components ``[U, omega]`` a particle centred on mirror planes with
    normals ``axes`` may have: (r,) bool. Across the plane with normal ``a`` the velocity's ``a``
    component and the angular velocity's other components change sign, so they must vanish."""
    free = np.ones(3 if dim == 2 else 6, dtype=bool)
    for a in axes:
        free[a] = False
        if dim == 2:
            free[2] = False  # omega_z is normal to neither x nor y
        else:
            free[dim + np.array([b for b in range(3) if b != a])] = False
    return free


def velocity_gain(p: Particles, dt: float, scheme: str = "semi-implicit-euler",
                  history: bool = True) -> np.ndarray:
    """``d v_new / d f``: how the new generalised velocities of :func:`integrate` respond to the
    (new) generalised force ``f = [F, T_z]`` (2D) or ``[F, T]`` (3D); (n, r, r), zero for fixed
    particles: ``dt / M_i`` for the translation, ``dt I_i^{-1}`` (world axes) for the rotation,
    half of that for the trapezoidal rule with a force ``history`` (its first step has none)."""
    r = 3 if p.dim == 2 else 6
    k = 0.5 * dt if scheme == "trapezoidal" and history else dt
    gain = np.zeros((p.n, r, r))
    idx = np.arange(p.dim)
    gain[:, idx, idx] = k / p.mass[:, None]
    gain[:, p.dim:, p.dim:] = k * np.linalg.inv(p.inertia_world())
    gain[p.fixed] = 0.0
    return gain


def integrate(p: Particles, force: np.ndarray, torque: np.ndarray, gravity, fluid_density: float,
              dt: float, scheme: str = "semi-implicit-euler", previous: tuple | None = None) -> Particles:
    """Advance the particles over ``dt`` under hydrodynamic ``force (n, dim)``, ``torque (n, 3)``,
    gravity ``(dim,)`` [m/s^2] and buoyancy; returns the new state (``p`` is not changed).

    ``previous``: the trapezoidal rule's force and torque at the start of the step (those of the
    previous step's end). None at a run's first step, where there is no force history: the
    start's accelerations are then taken to be the end's (a backward-Euler velocity step; the
    positions still move with the mean velocity). Not zero: the fluid resists a sudden
    acceleration from rest at once with its added mass, and a start with the force-free
    acceleration (gravity and buoyancy only, a third too large for a sphere at density ratio
    1.17) gave the velocity an offset of first order in dt (ten Cate E4, dt 0.01 s: 0.0120
    m/s after the first step against 0.0098 m/s from the initial acceleration with added
    mass)."""
    if scheme not in INTEGRATORS:
        raise ValueError(f"unknown integrator {scheme!r}; choose one of {sorted(INTEGRATORS)}")
    if not dt > 0:
        raise ValueError(f"time step must be positive, got {dt}")
    gravity = np.asarray(gravity, dtype=float)
    lin, ang = accelerations(p, force, torque, gravity, fluid_density)
    new = p.copy()
    if scheme == "trapezoidal" and previous is not None:
        lin_old, ang_old = accelerations(p, previous[0], previous[1], gravity, fluid_density)
        lin, ang = 0.5 * (lin + lin_old), 0.5 * (ang + ang_old)
    new.velocity = p.velocity + dt * lin
    new.angular_velocity = p.angular_velocity + dt * ang
    if scheme == "explicit-euler":
        v, w = p.velocity, p.angular_velocity
    elif scheme == "semi-implicit-euler":
        v, w = new.velocity, new.angular_velocity
    else:
        v, w = 0.5 * (p.velocity + new.velocity), 0.5 * (p.angular_velocity + new.angular_velocity)
    new.position = p.position + dt * v
    if p.dim == 2:
        new.orientation = p.orientation + dt * w
    else:
        new.orientation = quaternion_step(p.orientation, w, dt)
    return new


INTEGRATORS = ("explicit-euler", "semi-implicit-euler", "trapezoidal")
