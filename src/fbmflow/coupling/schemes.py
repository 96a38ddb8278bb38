"""Fluid–particle coupling schemes: strategies for one time step of flow and particles, registered
by name in :data:`~fbmflow.coupling.schemes.COUPLINGS` (the parameter ``coupling.scheme``).

* ``explicit`` (staggered): the flow is solved with the particles' current rigid velocities as
  fictitious-boundary constraints, and the hydrodynamic forces of the new flow advance the
  particles. Cheap; stable only while the added mass stays below the particle mass (see
  :mod:`fbmflow.particles.dynamics`); at rho_s / rho_f = 1.25 a disk already shows a damped
  step-to-step wobble.
* ``implicit``: the same step iterated to a fixed point, the flow constrained by the particles'
  *new* velocities, by Newton's method on the particle velocities with the discrete added-mass
  and drag matrix from the flow's linear response to unit rigid motions; removes the added-mass
  instability at the price of one linear response per rigid degree of freedom (3 per disk, 6 per
  sphere, back-substitutions with the last factorisation) and two to three flow solves per step.
* ``stabilised``: the explicit step with each particle's own added mass and drag implicit (a
  virtual mass); no responses.
* ``newton-krylov``: one flow solve and the implicit scheme's first Newton step on the particle
  velocities, solved matrix-free by FGMRES: one linear response per Krylov iteration, however
  many particles; takes the particles' pull on each other through the fluid, which the
  stabilised scheme misses in dense suspensions.

A scheme is made from the coupling parameters (``tol``, ``max_subiterations``, ``first_rtol``,
``flow_rtol``, ``added_mass``, ``krylov_rtol``: :class:`~fbmflow.coupling.settings.CouplingParams`)
and the Newton tolerance of the flow solves. Its ``advance(system, dt)`` takes a
:class:`CoupledProblem` (the :class:`~fbmflow.coupling.system.CoupledSystem`) and returns a
:class:`CoupledFlow` without changing the system; once the step has been committed, ``accept``
hands the scheme its own result, and a scheme that carries something from step to step keeps it
there, checkpointed through ``state()`` / ``set_state()``.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Protocol

import numpy as np
import scipy.sparse as sp

from ..particles import pack_velocities, symmetric_motion, unpack_velocities
from ..solvers import ConvergenceError, fgmres
from ..solvers.choice import RESPONSE_BYTES

log = logging.getLogger(__name__)


@dataclass
class CoupledFlow:
    """The flow and forces a coupling scheme ends a step with.

    x : (n_dofs,) float64, the new flow; reports : the Newton reports of its flow solves;
    force : (n, dim) float64 and torque : (n, 3) float64, the hydrodynamic force and torque on the
    particles; flow_solves : how many flow solves the step took; increment : (n, r) float64 or
    None, the change of the generalised velocities whose fluid reaction the scheme predicted
    instead of solving for it (the stabilised scheme: its step; the next flow solve measures it).
    """

    x: np.ndarray
    reports: list
    force: np.ndarray
    torque: np.ndarray
    flow_solves: int = 1
    increment: np.ndarray | None = None


class CoupledProblem(Protocol):
    """What a coupling scheme asks of the coupled system
    (:class:`~fbmflow.coupling.system.CoupledSystem`, where each member is documented)."""

    particles: object  # Particles: the state at the step's start
    gravity: np.ndarray  # (dim,)
    symmetry: tuple  # normal axes of the mirror planes
    flow: object  # NavierStokesProblem

    def flow_and_forces(self, dt: float, velocities=None, guess=None, rtol=None, linear_rtol=None): ...

    def integrate(self, force: np.ndarray, torque: np.ndarray, dt: float, contact: bool = True,
                  x: np.ndarray | None = None): ...

    def velocity_gain(self, dt: float) -> np.ndarray: ...

    def rigid_responses(self, x: np.ndarray, free: np.ndarray, dt: float, motions=None, rtol=None): ...

    def own_stiffness(self, x: np.ndarray, free: np.ndarray, dt: float, added_mass: float) -> np.ndarray: ...

    def repulsion_stiffness(self) -> sp.csr_matrix | None: ...


class CouplingScheme:
    """Base of the schemes: no state carried between steps, no flow fields kept."""

    name = ""

    def advance(self, system: CoupledProblem, dt: float) -> CoupledFlow:
        raise NotImplementedError

    @staticmethod
    def stored_responses(particles, symmetry) -> int:
        """Flow fields the scheme keeps per step besides the flow: none."""
        return 0

    def accept(self, solved: CoupledFlow) -> None:
        """The step ``solved`` (this scheme's own result) was committed."""

    def state(self) -> dict:
        """What a restart needs of the scheme, as arrays (names prefixed ``coupling_``)."""
        return {}

    def set_state(self, state: dict) -> None:
        """Restore :meth:`state` from a dict that may hold other entries too."""


class ExplicitCoupling(CouplingScheme):
    """One flow solve with the particles' current velocities; its forces advance the particles."""

    name = "explicit"

    def __init__(self, params=None, newton_rtol: float | None = None):
        """``params.flow_rtol`` (if given and above ``newton_rtol``): Newton's residual reduction
        in the flow solve (:func:`flow_rtol`)."""
        self.flow_rtol = flow_rtol(params, newton_rtol)

    def advance(self, system: CoupledProblem, dt: float) -> CoupledFlow:
        x, reports, force, torque = system.flow_and_forces(dt, rtol=self.flow_rtol,
                                                           linear_rtol=self.flow_rtol)
        return CoupledFlow(x, reports, force, torque)


class StabilisedCoupling(CouplingScheme):
    """One flow solve with the particles' current velocities, as :class:`ExplicitCoupling`; the
    particles then take one Newton step of the implicit scheme's fixed point with each particle's
    own stiffness only (see :meth:`~fbmflow.coupling.schemes.StabilisedCoupling.advance`).

    Parameters
    ----------
    params : :class:`~fbmflow.coupling.settings.CouplingParams` (``added_mass``, ``flow_rtol``)
    newton_rtol : float
        The solver's Newton residual reduction; ``params.flow_rtol`` above it replaces it in the
        step's flow solve (:func:`flow_rtol`).
    """

    name = "stabilised"

    def __init__(self, params, newton_rtol: float | None = None):
        self.added_mass = float(params.added_mass)
        self.flow_rtol = flow_rtol(params, newton_rtol)
        #: (n, r) float64 or None: the last committed step's increment ``s'`` (see :meth:`advance`)
        self.last_increment: np.ndarray | None = None

    def accept(self, solved: CoupledFlow) -> None:
        self.last_increment = solved.increment

    def state(self) -> dict:
        return {} if self.last_increment is None else {"coupling_increment": self.last_increment.copy()}

    def set_state(self, state: dict) -> None:
        increment = state.get("coupling_increment")
        self.last_increment = None if increment is None else np.array(increment, dtype=float)

    def advance(self, system: CoupledProblem, dt: float) -> CoupledFlow:
        """Solve the flow constrained by the current velocities ``v``; its forces ``f`` give the
        explicit update ``Phi(v)``. The new velocities ``v + s`` take each particle's own
        stiffness ``S_i`` (its force on its own velocity with the other particles and the flow
        held, :meth:`~fbmflow.coupling.system.CoupledSystem.own_stiffness`) implicitly, as a virtual
        mass acting on the change of the particle's increments (Schwarz, Kempe & Froehlich 2015,
        J. Comput. Phys. 281):

            (I - G_i S_i) s_i = Phi_i(v) - v_i - G_i S_i s'_i,

        one ``r x r`` solve per particle, ``G_i = d v / d f`` its gain. ``s'_i`` is this
        scheme's last increment (:attr:`last_increment`): the
        last step predicted the fluid's reaction to it, ``S_i s'_i``, which ``f`` now measures.
        Contact's jumps are not part of it: nothing predicted their reaction (with them in, a
        bed forming on the floor at 4 cells per diameter oscillated and failed). The step's force is
        ``f_i + S_i (s_i - s'_i)``, with which :meth:`~fbmflow.coupling.system.CoupledSystem.integrate`
        gives ``v + s`` (and contact then acts).

        The term vanishes at a steady state and in a steady acceleration (``s = s'``), so both
        are the implicit scheme's; it damps the step-to-step oscillation of the explicit scheme,
        whose error is amplified per step by the spectral radius of ``G S`` (added mass and drag
        of all particles; above one for light particles and for many particles in a closed box).
        Measured against the implicit scheme: docs/validation/many-particles.md."""
        p = system.particles
        x, reports, force, torque = system.flow_and_forces(dt, rtol=self.flow_rtol,
                                                           linear_rtol=self.flow_rtol)
        if p.fixed.all():
            return CoupledFlow(x, reports, force, torque)
        v = pack_velocities(p)
        new = system.integrate(force, torque, dt, contact=False, x=x)
        gain = system.velocity_gain(dt)
        r = gain.shape[1]
        free = np.zeros((p.n, r), dtype=bool)
        free[~p.fixed] = symmetric_motion(p.dim, system.symmetry)
        S = system.own_stiffness(x, free, dt, self.added_mass)
        GS = np.einsum("nab,nbc->nac", gain, S)
        lag = np.zeros((p.n, r)) if self.last_increment is None else np.where(free, self.last_increment, 0.0)
        res = np.where(free, pack_velocities(new) - v, 0.0) - np.einsum("nab,nb->na", GS, lag)
        step = np.linalg.solve(np.eye(r) - GS, res[:, :, None])[:, :, 0]
        f = np.einsum("nab,nb->na", S, step - lag)
        d = p.dim
        torque = torque.copy()
        torque[:, 3 - (r - d):] += f[:, d:]
        return CoupledFlow(x, reports, force + f[:, :d], torque, increment=step)


class NewtonKrylovCoupling(StabilisedCoupling):
    """The stabilised scheme's step with every particle's pull on the others taken too: one
    Newton step of the implicit scheme's fixed point from the current velocities, its linear
    system solved matrix-free by flexible GMRES, the stabilised scheme's per-particle stiffness
    its preconditioner (see :meth:`~fbmflow.coupling.schemes.NewtonKrylovCoupling.advance`). The parameters
    as :class:`StabilisedCoupling`'s,
    and ``params.krylov_rtol`` and ``params.max_subiterations`` (FGMRES's residual reduction and
    iteration limit). No flow fields are kept: each response is used and dropped.
    """

    name = "newton-krylov"

    def __init__(self, params, newton_rtol: float | None = None):
        super().__init__(params, newton_rtol)
        self.rtol = float(params.krylov_rtol)
        self.max_iterations = int(params.max_subiterations)

    def advance(self, system: CoupledProblem, dt: float) -> CoupledFlow:
        """Solve the flow constrained by the current velocities ``v``; its forces ``f`` give the
        explicit update ``Phi(v)``. The new velocities ``v + y`` solve the implicit scheme's
        Newton equation from ``v``,

            (I - G S) y = Phi(v) - v,

        ``S = d f / d v`` the flow's force response to the particles' rigid motions (added mass,
        drag and every particle's pull on the others through the fluid), ``G = d v / d f`` their
        gain. FGMRES (:func:`~fbmflow.solvers.krylov.fgmres`) solves it to a residual of ``krylov_rtol``
        times the smaller of ``|Phi(v) - v|`` and the velocities' size (:func:`relative_scale`:
        the residual is an error of the new velocities) in at most ``max_subiterations``
        iterations, each applying ``S`` to one combined motion: one linear solve with the step's
        Newton linearisation (:meth:`~fbmflow.coupling.system.CoupledSystem.rigid_responses`), whatever
        the number of particles, to FGMRES's reduction divided by the stiffness over the step
        (:func:`response_amplification`) where the linear solver takes a target (multigrid,
        PARDISO's refinement): ``I - G S`` multiplies a response's error by that much, and
        responses only as accurate as FGMRES's target made it stall (3D suspensions, dt = 0.1 s:
        a 35-fold reduction in 200 iterations where 150 were asked, against 9 iterations). The
        right preconditioner is the stabilised scheme's per-particle ``(I - G_i S_i)^-1``
        (:meth:`~fbmflow.coupling.system.CoupledSystem.own_stiffness`). The flow and the forces then
        follow ``y`` linearly, through the response to ``y`` itself (the last product FGMRES
        forms), without a second flow solve.

        The repulsion (:meth:`~fbmflow.coupling.system.CoupledSystem.repulsion_stiffness`) enters at the
        step's end, ``F(X) + dt K v'``, ``K`` its change along the lines of action: the Newton
        equation takes ``S + dt K`` and the preconditioner ``K``'s own blocks. Explicit, a pair
        in range overshoots once ``dt`` times its stiffness exceeds twice its drag (5 times over
        for spheres at 4 cells per diameter and dt = 0.01 s: docs/validation/periodic-suspensions.md).

        Where the particles pull on each other strongly through the fluid (close neighbours in a
        dense suspension) the per-particle stiffness of :class:`StabilisedCoupling` misses those
        couplings and its steps grow; this scheme takes them all, at the cost of the Krylov
        iterations' linear solves (measured: docs/validation/many-particles.md). Contact is
        left out of the map, as in :class:`ImplicitCoupling`."""
        p = system.particles
        x, reports, force, torque = system.flow_and_forces(dt, rtol=self.flow_rtol,
                                                           linear_rtol=self.flow_rtol)
        if p.fixed.all():
            return CoupledFlow(x, reports, force, torque)
        v = pack_velocities(p)
        gain = system.velocity_gain(dt)
        r, d = gain.shape[1], p.dim
        free = np.zeros((p.n, r), dtype=bool)
        free[~p.fixed] = symmetric_motion(d, system.symmetry)
        S = system.own_stiffness(x, free, dt, self.added_mass)
        K = system.repulsion_stiffness()
        push = np.zeros_like(force)
        if K is not None:  # the repulsion at the step's end, F(X + dt v') ~ F(X) + dt K v'
            K = dt * K
            blocks = K.tobsr(blocksize=(d, d))
            row = np.repeat(np.arange(p.n), np.diff(blocks.indptr))
            on = blocks.indices == row
            both = free[row[on], :d, None] & free[row[on], None, :d]
            S[row[on], :d, :d] += np.where(both, blocks.data[on], 0.0)
            push = (K @ v[:, :d].ravel()).reshape(p.n, d)
        new = system.integrate(force + push, torque, dt, contact=False, x=x)
        own_gs = np.einsum("nab,nbc->nac", gain, S)
        own = np.linalg.inv(np.eye(r) - own_gs)   # (n, r, r)
        last = {}

        def full(y: np.ndarray) -> np.ndarray:
            out = np.zeros((p.n, r))
            out[free] = y
            return out

        def precondition(q: np.ndarray) -> np.ndarray:
            return np.einsum("nab,nb->na", own, full(q))[free]

        res = (pack_velocities(new) - v)[free]
        rtol = self.rtol * relative_scale(v[free] + precondition(res), res)
        inner = rtol / response_amplification(own_gs)

        def apply(y: np.ndarray) -> np.ndarray:  # (I - G (S + dt K)) y, keeping the response of y
            f = np.zeros((p.n, r))
            if y.any():
                dX, dF, dT = system.rigid_responses(x, free, dt, motions=y[None], rtol=inner)
                last.update(dX=dX[0], dF=dF[0], dT=dT[0])
                f = np.concatenate([dF[0], dT[0][:, 2:] if d == 2 else dT[0]], axis=1)
            else:
                last.update(dX=np.zeros(len(x)), dF=np.zeros((p.n, d)), dT=np.zeros((p.n, 3)))
            if K is not None:
                f[:, :d] += (K @ full(y)[:, :d].ravel()).reshape(p.n, d)
            return y - np.einsum("nab,nb->na", gain, f)[free]

        y, residuals, iterations = fgmres(apply, precondition, res, np.zeros_like(res), rtol,
                                          self.max_iterations)
        log.debug("Newton-Krylov coupling: %d iterations, residual %.2e of %.2e", iterations,
                  residuals[-1], residuals[0])
        if residuals[-1] > rtol * residuals[0]:
            raise ConvergenceError(f"Newton-Krylov coupling: FGMRES reduced the residual only "
                                   f"{residuals[0] / max(residuals[-1], 1e-300):.3g} times of the "
                                   f"{1 / rtol:.3g} asked in {iterations} iterations (coupling.krylov_rtol "
                                   f"= {self.rtol:g}); raise coupling.max_subiterations or reduce the time "
                                   "step")
        # fgmres's last product is its answer's: the flow and the forces follow y through it
        force = force + last["dF"]
        if K is not None:  # the step's force carries the repulsion's change over the step
            force += (K @ (v + full(y))[:, :d].ravel()).reshape(p.n, d)
        return CoupledFlow(x + last["dX"], reports, force, torque + last["dT"])


def response_amplification(gs: np.ndarray) -> float:
    """How much the Newton–Krylov operator ``I - G S`` amplifies an error of the flow's force
    responses, estimated from the particles' own blocks ``gs = G_i S_i (n, r, r)``: the largest
    spectral radius among them, at least 1 (unit-free: a ratio of the step to the particles'
    response times, about 110 for spheres at dt = 0.1 s in ``suspension-3d``)."""
    if gs.size == 0:
        return 1.0
    return float(max(1.0, np.abs(np.linalg.eigvals(gs)).max()))


def relative_scale(estimate: np.ndarray, residual: np.ndarray, floor: float = 1e-3) -> float:
    """How far below the initial residual the Newton–Krylov step must drive its residual, per unit
    of ``krylov_rtol``: ``min(1, |estimate| / |residual|)``, at least ``floor``.

    The particles leave the step at ``v + y + r``, ``r`` FGMRES's residual, so ``r`` is an error
    of the velocities themselves; it must be small against the velocities (``estimate``: the
    stabilised scheme's answer), not only against the explicit update's error ``Phi(v) - v``,
    which over a step long against the particles' response time (a start from rest, a large
    ``dt``) is many times the velocities (docs/method.md, "Coupling")."""
    size = float(np.linalg.norm(residual))
    if size == 0.0:
        return 1.0
    return float(min(1.0, max(float(np.linalg.norm(estimate)) / size, floor)))


def flow_rtol(params, newton_rtol: float | None) -> float | None:
    """Newton's residual reduction for a scheme's single flow solve per step: ``params.flow_rtol``
    where it is above ``newton_rtol`` (the solver's), else None (the solver's own). A step's flow
    solve starts from the last step's flow, so its residual is the step's change, and a loose
    reduction of it errs by a fraction of that change (docs/validation/many-particles.md, "2 000 disks and 1
    000 spheres"). The
    schemes ask the solve's linear steps for no more than the same reduction."""
    loose = 0.0 if params is None else float(params.flow_rtol)
    return loose if newton_rtol is not None and loose > newton_rtol else None


class ImplicitCoupling(CouplingScheme):
    """Newton iteration on the particles' new generalised velocities ``v``
    (see :meth:`~fbmflow.coupling.schemes.ImplicitCoupling.advance`).

    Parameters
    ----------
    params : :class:`~fbmflow.coupling.settings.CouplingParams`
        ``tol``, ``max_subiterations``, ``first_rtol``.
    newton_rtol : float
        The flow solves' Newton residual reduction: a ``first_rtol`` above it makes each step's
        first flow solve a loose one, which only seeds the iteration (its forces give the first
        velocity update, its linearisation the responses); the step always ends on a solve to
        ``newton_rtol`` (measured effect: docs/validation/multigrid-with-fictitious-boundaries.md).
    """

    name = "implicit"

    def __init__(self, params, newton_rtol: float):
        self.tol = float(params.tol)
        self.max_subiterations = int(params.max_subiterations)
        self.first_rtol = float(params.first_rtol) if params.first_rtol > newton_rtol else None

    @staticmethod
    def stored_responses(particles, symmetry) -> int:
        """Flow fields the scheme keeps per step besides the flow: one response per iterated
        rigid-body component (3 per disk, 6 per sphere, fewer on mirror planes)."""
        return int((~particles.fixed).sum()) * int(np.sum(symmetric_motion(particles.dim, symmetry)))

    def advance(self, system: CoupledProblem, dt: float) -> CoupledFlow:
        """The fixed point ``v = Phi(v)``: integrate the particles with the forces of the flow
        constrained by ``v``.

        Its Jacobian ``I - G S`` is built once per step from the flow's response to unit rigid
        motions of each particle (``S = d f / d v``, the discrete added mass and drag,
        :meth:`~fbmflow.flow.navier_stokes.NavierStokesProblem.lifting_response`) and the particles' gain
        ``G = d v_new / d f``; each sub-iteration then costs one flow solve, whose Newton
        iteration starts from the flow those responses predict (``x + step dX``; its stopping rule
        stays relative to the residual at the step's start). The iteration stops when the error
        left after the next Newton step on ``v`` is below ``tol`` times the velocity scale,
        estimated from the contraction ``theta = |step_k| / |step_(k-1)|`` as
        ``theta / (1 - theta) |step_k|`` (Deuflhard's estimate; ``|step_0|`` itself for the
        first). That last step is taken without a further flow solve, the flow and the forces
        following it linearly through the same responses (``x + sum_k step_k dx_k``), if the
        flow's error in doing so is below the tolerance too. The responses belong to the first
        flow of the step; how much the flow's response bent over the previous step (``drift``,
        the part of its change that they do not explain, largest over the velocity DOFs) gives
        that error as ``2 drift |step_k| / |step_(k-1)|`` (a quadratic model). Otherwise the
        step is solved. Two flow solves per time step are typical near density ratio 1 (the
        first from the explicit prediction, the second after one Newton step, which contracts
        about 1e-4 times), three at larger ratios. Broyden's rank-one update corrects the
        Jacobian from each sub-iteration's change (the forces are not exactly linear in ``v``).
        Contact is left out of the iterated map (its non-smooth response, a constraint switching
        on and off between sub-iterations, stalls the iteration): it acts once the coupling has
        converged, with the converged hydrodynamic force.
        """
        p = system.particles
        loose = self.first_rtol is not None and not p.fixed.all()
        x, reports, force, torque = system.flow_and_forces(dt, rtol=self.first_rtol if loose else None)
        exact = not loose
        new = system.integrate(force, torque, dt, contact=False, x=x)
        gain = system.velocity_gain(dt)
        r = gain.shape[1]
        free = np.zeros((p.n, r), dtype=bool)  # the iterated components: movable, on the planes
        free[~p.fixed] = symmetric_motion(p.dim, system.symmetry)
        dX, dF, dT = system.rigid_responses(x, free, dt)
        # d f_i / d v_k for every iterated component k: (n, r, k)
        sens = np.concatenate([dF, dT[:, :, 2:] if p.dim == 2 else dT], axis=2).transpose(1, 2, 0)
        J = np.eye(len(dX)) - np.einsum("nab,nbk->nak", gain, sens)[free]
        guess = p.copy()
        v_guess = pack_velocities(p)
        # velocity scale of the convergence test: the step's velocities, at least what gravity adds
        floor = max(float(np.linalg.norm(v_guess)), float(np.linalg.norm(system.gravity)) * dt, 1e-30)
        all_reports = list(reports)
        n_u = system.flow.space.n_u
        res_old = step = size_old = x_old = drift = None
        for k in range(self.max_subiterations):
            res = (pack_velocities(new) - v_guess)[free]
            scale = max(float(np.linalg.norm(pack_velocities(new))), floor)
            if step is not None:  # Broyden's update: contact and nonlinearity bend the map
                dG = res_old - res
                if step @ step > 0.0:  # (a zero step, e.g. a particle in balance, teaches nothing)
                    J += np.outer(dG - J @ step, step) / (step @ step)
                # the flow's change over the last step that the responses do not explain
                drift = system.flow.max_abs((x - x_old - step @ dX)[:n_u])
            step = np.linalg.solve(J, res)
            size = float(np.linalg.norm(step))
            if k == 0 or size_old == 0.0:  # no contraction measured: the step bounds both errors
                error = flow_error = size
            else:
                theta = size / size_old  # contraction of the iteration
                error = size if theta >= 1.0 else min(size, theta / (1.0 - theta) * size)
                flow_error = 2.0 * drift * size / size_old
            log.debug("coupling sub-iteration %d: relative step %.3e, error after it %.3e, of the "
                      "flow following it %.3e", k, size / scale, error / scale, flow_error / scale)
            if (k > 0 or exact) and max(error, flow_error) <= self.tol * scale:  # the last step,
                # without a solve (not from a first flow solved to a looser tolerance)
                return CoupledFlow(x + step @ dX, all_reports, force + np.tensordot(step, dF, 1),
                                   torque + np.tensordot(step, dT, 1), k + 1)
            res_old, size_old, x_old = res, size, x
            v_guess[free] += step
            unpack_velocities(guess, v_guess)
            x, reports, force, torque = system.flow_and_forces(dt, velocities=guess, guess=x + step @ dX)
            all_reports += reports
            new = system.integrate(force, torque, dt, contact=False, x=x)
        raise ConvergenceError(f"fluid-particle coupling did not converge in {self.max_subiterations} "
                               f"sub-iterations (last step {np.linalg.norm(step) / scale:.1e})")


#: coupling schemes by name (the parameter ``coupling.scheme``)
COUPLINGS = {cls.name: cls for cls in (ExplicitCoupling, StabilisedCoupling, NewtonKrylovCoupling,
                                        ImplicitCoupling)}


def make_coupling(params, newton_rtol: float):
    """The registered scheme ``params.scheme`` made from ``params``
    (:class:`~fbmflow.coupling.settings.CouplingParams`); ValueError listing the names otherwise."""
    try:
        cls = COUPLINGS[params.scheme]
    except KeyError:
        raise ValueError(f"unknown coupling {params.scheme!r}; choose one of {sorted(COUPLINGS)}") from None
    return cls(params, newton_rtol)


#: the implicit coupling's responses that ``coupling.scheme = "auto"`` allows [bytes]
AUTO_RESPONSE_BYTES = 4e9


def auto_coupling(n_unknowns: int, particles, symmetry=()) -> str:
    """The scheme ``coupling.scheme = "auto"`` takes: ``"implicit"`` while the flow responses it
    keeps (:data:`~fbmflow.solvers.choice.RESPONSE_BYTES` per unknown each, one per free
    rigid-body component) fit :data:`AUTO_RESPONSE_BYTES`, else ``"stabilised"`` (one flow solve
    per step, none kept; less accurate in transients, and at a hard impact it needs half a cell
    per step: docs/validation/many-particles.md). The same for every machine."""
    responses = ImplicitCoupling.stored_responses(particles, symmetry)
    stored = RESPONSE_BYTES * n_unknowns * responses
    if stored <= AUTO_RESPONSE_BYTES:
        return "implicit"
    log.info("coupling.scheme = auto: stabilised, since the implicit scheme's %d responses would need "
             "%.1f GB for %d unknowns", responses, stored / 1e9, n_unknowns)
    return "stabilised"
