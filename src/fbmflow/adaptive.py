"""Adaptive time stepping: each step's size from a local error estimate of the particles' motion
(``time.adaptive = true``; docs/method.md, "Adaptive time steps").

The estimate compares where a step moves the particles with where the linear extrapolation of
the step before would have moved them, an explicit scheme of first order. With the generalised
velocities ``g_i = (U_i, omega_i r_i)`` of the free particles (translation, and rotation at the
bounding radius ``r_i``) and their mean over a step ``gbar^n = (g^n + g^{n+1}) / 2``::

    e = dt_n max_i |gbar_i^n - gbar_i^{n-1}| / h,

the distance between the two, relative to ``h``, the smallest side of the cells that hold the
particles: about ``dt_n (dt_n + dt_{n-1}) |g'| / (2 h)`` for smooth motion. It is measured on the
path rather than on the velocity because the fictitious boundary's velocity jumps (nodes that
change between particle and fluid exchange momentum at once, whatever the step) do not shrink
with the step, while the distance they move a particle does. A step with ``e > tolerance`` is
taken again, shorter; the next step is ``dt_n min(1.25, max(0.2, 0.9 sqrt(tolerance / e)))`` (no
larger after a step taken again), and at most ``max_courant h / |U|`` (``|U|`` the fastest
particle's speed). A step whose solver fails
(:class:`~fbmflow.solvers.newton.ConvergenceError`) is taken again at a quarter of its size. The first
step is ``time.dt`` as given (there is no step before it to extrapolate), and the last one lands
on ``t_end``.

The controller's state (the next step, the last one, the mean velocities of the last step and
the counts) travels in the simulation's checkpoints, so that a resumed run takes the same steps.
"""
from __future__ import annotations

import numpy as np

from .solvers import ConvergenceError

#: the step may grow at most this factor per step (chosen while the trapezoidal integrator's
#: pressure pairing was not consistent under steps that jump, docs/validation/converged-answers.md;
#: not tuned since), and shrink at most to this fraction
GROWTH, SHRINK = 1.25, 0.2
#: safety factor of the step size formula
SAFETY = 0.9
#: a failed solve retries at this fraction of the step
RETRY = 0.25
#: the step may not fall below this fraction of ``time.dt`` (the run stops there)
MIN_FRACTION = 1e-4


class StepControl:
    """The adaptive time step of one run.

    Parameters
    ----------
    time : TimeParams
        ``dt``: the first step [s]; ``t_end``: the final time [s], where the last step lands;
        ``tolerance``: the largest ``e`` (module docstring) a step may have, a fraction of a
        cell; ``max_courant``: the largest ``|U| dt / h`` of a step.
    particles : Particles
        The run's particles (at least one free).
    contact : bool
        Whether the run has hard contact (refused: its impulses are no smooth motion).

    Raises
    ------
    ValueError
        With hard contact, or without a free particle.

    Attributes
    ----------
    dt : float
        The next step's size [s] (before the landing on ``t_end``).
    last_dt : float
        The last accepted step [s] (0 before the first).
    rejected : int
        Steps taken again so far (error above the tolerance, or a failed solve).
    smallest, largest : float
        The smallest and largest accepted step [s] (0 before the first).
    """

    def __init__(self, time, particles, contact: bool = False):
        if contact or particles.fixed.all():
            raise ValueError("time.adaptive estimates the error from the free particles' smooth motion: "
                             + ("contact impulses break it; turn hard contact off" if contact
                                else "there is no free particle") + " or set time.adaptive = false")
        self.dt0, self.t_end = float(time.dt), float(time.t_end)
        self.tolerance, self.max_courant = time.tolerance, time.max_courant
        self.dt, self.last_dt, self.rejected = self.dt0, 0.0, 0
        self.smallest = self.largest = 0.0
        self._previous: np.ndarray | None = None  # the last accepted step's mean g

    def finished(self, t: float) -> bool:
        """Whether ``t`` [s] has reached ``t_end`` (to rounding)."""
        return t >= self.t_end - 1e-9 * self.t_end

    def remaining_steps(self, t: float) -> int:
        """Steps still to go at today's step size (for progress)."""
        return 0 if self.finished(t) else int(np.ceil((self.t_end - t) / self.dt - 1e-9))

    def next_dt(self, t: float) -> float:
        """The size of the step from ``t``: the attribute ``dt``, stretched or split so that the run lands on
        ``t_end`` without a sliver of a last step."""
        left = self.t_end - t
        if left <= 1.1 * self.dt:
            return left
        return min(self.dt, 0.5 * left)

    def step(self, sim):
        """Advance ``sim`` (a :class:`~fbmflow.simulation.Simulation`) by one accepted step; returns
        its :class:`~fbmflow.coupling.system.StepReport`. ConvergenceError when the step would fall
        below ``MIN_FRACTION * time.dt``."""
        before = velocities(sim.particles)
        h = float(sim.mesh.cell_size_at(sim.particles.position).min())
        saved, retried = sim.state(), False
        while True:
            dt = self.next_dt(sim.t)
            if dt < MIN_FRACTION * self.dt0 and not self.finished(sim.t + dt):
                raise ConvergenceError(
                    f"the adaptive time step fell to {dt:.3g} s, below {MIN_FRACTION:g} of time.dt "
                    f"({self.dt0:.3g} s), with {self.rejected} steps rejected so far",
                    "raise time.tolerance, or turn time.adaptive off and choose time.dt")
            try:
                report = sim.step(dt)
            except ConvergenceError as err:
                if not err.retry:  # no shorter step helps (the GPU's memory ran out, say)
                    raise
                if dt * RETRY < MIN_FRACTION * self.dt0:
                    why = f"the adaptive step cannot shrink further ({dt * RETRY:.3g} s would be below " \
                          f"{MIN_FRACTION:g} of time.dt)"
                    remedy = err.remedy or "check the set-up: the solver fails at every step size"
                    raise ConvergenceError(f"{err}; {why}", remedy) from None
                sim.set_state(saved)
                self.dt, self.rejected, retried = dt * RETRY, self.rejected + 1, True
                continue
            mean = 0.5 * (before + velocities(sim.particles))
            e = self.error(mean, dt, h)
            factor = GROWTH if e == 0.0 else min(GROWTH, max(SHRINK, SAFETY * np.sqrt(self.tolerance / e)))
            if e <= self.tolerance:
                break
            sim.set_state(saved)
            self.dt, self.rejected, retried = dt * factor, self.rejected + 1, True
        self._previous, self.last_dt = mean, dt
        self.smallest = min(self.smallest or dt, dt)
        self.largest = max(self.largest, dt)
        self.dt = min(dt * (min(factor, 1.0) if retried else factor), self._courant_limit(sim))
        return report

    def error(self, mean: np.ndarray, dt: float, h: float) -> float:
        """The estimate ``e`` of a step of ``dt`` [s] whose mean generalised velocities are ``mean``
        (:func:`velocities`), on cells of side ``h``; 0 for the first step."""
        if self._previous is None:
            return 0.0
        return float(dt * np.linalg.norm(mean - self._previous, axis=1).max(initial=0.0) / h)

    def _courant_limit(self, sim) -> float:
        """``max_courant h / |U|`` at the current state (inf where no particle moves)."""
        p = sim.particles
        speed = float(np.linalg.norm(p.velocity, axis=1).max(initial=0.0))
        if speed == 0.0:
            return np.inf
        return self.max_courant * float(sim.mesh.cell_size_at(p.position).min()) / speed

    def state(self) -> dict:
        """The controller's state as arrays and numbers (keys ``control_*``)."""
        out = {"control_dt": self.dt, "control_last_dt": self.last_dt, "control_rejected": self.rejected,
               "control_smallest": self.smallest, "control_largest": self.largest}
        if self._previous is not None:
            out["control_previous"] = self._previous.copy()
        return out

    def set_state(self, state: dict) -> None:
        """Restore :meth:`state` (a state without it: a fresh start, or ValueError past step 0)."""
        if "control_dt" not in state:
            if int(state.get("step_count", 0)) > 0:
                raise ValueError("the state was saved without adaptive time stepping; resume it with "
                                 "time.adaptive = false")
            return
        self.dt, self.last_dt = float(state["control_dt"]), float(state["control_last_dt"])
        self.rejected = int(state["control_rejected"])
        self.smallest, self.largest = float(state["control_smallest"]), float(state["control_largest"])
        previous = state.get("control_previous")
        self._previous = None if previous is None else np.array(previous, dtype=float)


def velocities(particles) -> np.ndarray:
    """The generalised velocities ``(U_i, omega_i r_i)`` of the free particles, (n_free, 3) in 2D
    and (n_free, 6) in 3D."""
    free = ~particles.fixed
    spin = particles.angular_velocity.reshape(particles.n, -1) * particles.bounding_radius[:, None]
    return np.column_stack([particles.velocity[free], spin[free]])
