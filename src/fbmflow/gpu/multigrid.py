"""Multigrid on the GPU (``solver.device = "gpu"``).

The hierarchy is set up on the CPU as :class:`~fbmflow.solvers.multigrid.MultigridSolver` sets it
up, with the smoothers in colour order (``solver.multigrid.order = "colours"``) but without their
local factors, and copied to the device: every level but the coarsest holds its operator
(:class:`~fbmflow.gpu.operator.DeviceOperator`), its smoother's patches, colours and local
factors, these computed on the device (:class:`~fbmflow.gpu.vanka.DeviceVanka`), and its
transfers (the prolongation's scalar blocks and their transposes). What every set-up of a level
shares is copied once and kept (:meth:`Backend.kept <fbmflow.gpu.device.Backend.kept>`): the
level's divergence, which the operator's gradient and continuity rows and the smoother read,
its transfers' scalar blocks and its space's cells; a set-up copies the rest. FGMRES and the
cycles run on the device; the coarsest level's direct solve stays on the CPU, one transfer of its
right-hand side and its solution per cycle. Particles, forces and contact stay on the CPU: a
solve takes host vectors and returns host vectors.

The cycle is the CPU's own function (:func:`~fbmflow.solvers.multigrid.multigrid_cycle`) on the
device's levels, so a solve on the device gives what the CPU gives with the same settings
(``order = "colours"``) to the rounding of the sums' order, in as many cycles.
"""
from __future__ import annotations

import dataclasses
import logging
import time

import numpy as np

from ..config import ParamError
from ..solvers.base import Factorization
from ..solvers.choice import InsufficientMemory
from ..solvers.multigrid import (
    MultigridHierarchy,
    MultigridSolver,
    _border,
    multigrid_cycle,
    multigrid_iterations,
)
from ..solvers.reports import LinearReport
from .device import Backend, gpu_backend, gpu_problem, nbytes
from .operator import DeviceDivergenceProducts, DeviceOperator
from .space import device_space
from .vanka import FACTOR_SCRATCH, DeviceVanka

log = logging.getLogger(__name__)

#: device memory the GPU solver holds per unknown of the finest level [bytes]: the hierarchy's
#: arrays (operators, smoothers' factors and colours, transfers of all levels but the coarsest,
#: the kept copies they read, a Newton block's coefficients; measured on a set-up's arrays: ten
#: Cate 1 158 at level 1 and 1 111 at level 2, glowinski-free-fall 504 at level 3;
#: ``python -m fbmbench gpu_solver --rows arrays``, benchmarks/results/gpu_solver.md), FGMRES's
#: basis (61 vectors, 488) and ten work vectors (80), rounded up
DEVICE_BYTES = {2: 1100, 3: 1750}


class _DeviceTransfer:
    """A level's :class:`~fbmflow.solvers.transfer.BlockTransfer` on the device, applied from its
    scalar blocks as the CPU applies it: ``P_v`` and its transpose on the ``d`` velocity
    components at once (one sparse-times-dense product), ``P_p`` and its transpose on the
    pressure, the DOFs the transfer drops zeroed. The scalar blocks are the level's, kept
    (:meth:`Backend.kept <fbmflow.gpu.device.Backend.kept>`: copied once, with their transposes);
    a set-up copies only the dropped DOFs. ``nbytes``: those [bytes]; ``kept``: the kept
    matrices."""

    def __init__(self, transfer, backend: Backend):
        def pair(M):  # a scalar block and its transpose, CSR on the device
            return backend.csr(M), backend.csr(M.T)

        self.xp, self.d = backend.xp, transfer.dim
        self.P_v, self.R_v = backend.kept(transfer.P_v, "transfer", pair)
        self.P_p, self.R_p = backend.kept(transfer.P_p, "transfer", pair)
        #: the kept device matrices it reads
        self.kept = [self.P_v, self.R_v, self.P_p, self.R_p]
        self.dropped = backend.put(np.flatnonzero(~transfer.keep), np.int32)
        self.nbytes = int(self.dropped.nbytes)

    def prolongate(self, e):
        """``P e`` for a coarse device vector ``e`` -> the fine one."""
        xp, d = self.xp, self.d
        nf, nc = self.P_v.shape
        E = self.P_v @ xp.ascontiguousarray(e[:d * nc].reshape(d, nc).T)
        out = xp.concatenate([xp.ascontiguousarray(E.T).reshape(-1), self.P_p @ e[d * nc:]])
        out[self.dropped] = 0.0
        return out

    def restrict(self, r):
        """``P^T r`` for a fine device vector ``r`` -> the coarse one."""
        xp, d = self.xp, self.d
        nf, nc = self.P_v.shape
        r = r.copy()
        r[self.dropped] = 0.0
        F = self.R_v @ xp.ascontiguousarray(r[:d * nf].reshape(d, nf).T)
        return xp.concatenate([xp.ascontiguousarray(F.T).reshape(-1), self.R_p @ r[d * nf:]])


class _DeviceLevel:
    """One level's operator, smoother and transfers on the device. ``nbytes``: the device memory
    it adds to what the backend keeps [bytes]."""

    def __init__(self, level, backend: Backend):
        put = backend.put
        self.n_u, self.n_p = level.n_u, level.n_p
        self.operator = DeviceOperator(level.system, backend)
        op = level.smoother.op
        self.smoother = DeviceVanka(level.smoother, backend, self.operator.velocity_rows(op[3]),
                                    self.operator.divergence_rows(op[7]))
        self.transfer = _DeviceTransfer(level.P, backend)
        self.coarse_fixed = put(level.coarse_fixed)
        self.coarse_orphans = None if level.coarse_orphans is None else backend.csr(level.coarse_orphans)
        self.factor_time_s = self.smoother.factor_time_s
        self.nbytes = nbytes(self.operator, self.smoother, self.transfer, self.coarse_fixed,
                             self.coarse_orphans)

    def smooth(self, b, x, sweeps: int) -> None:
        self.smoother.smooth(b, x, sweeps)

    def residual(self, b, x):
        return b - self.operator.apply(x)

    def restrict(self, r, coarse):
        rc = self.transfer.restrict(r)
        rc[self.coarse_fixed] = 0.0
        if self.coarse_orphans is not None:  # modes no coarse velocity sees: no correction
            rc[coarse.n_u:] -= self.coarse_orphans @ rc[coarse.n_u:]
        return rc

    def prolongate(self, e, coarse):
        return self.transfer.prolongate(e)


class _HostCoarsest:
    """The coarsest level, solved on the CPU: its right-hand side brought over, its solution
    sent back."""

    def __init__(self, level, backend: Backend):
        self.level, self.backend, self.n_u = level, backend, level.n_u

    def solve(self, b):
        return self.backend.put(self.level.solve(self.backend.get(b)))


class DeviceHierarchy(Factorization):
    """A :class:`~fbmflow.solvers.multigrid.MultigridHierarchy` (set up on the CPU, smoothers in
    colour order) with its cycles and its FGMRES on the device of ``backend``. ``nbytes``:
    the device memory it holds, the copies it reads that the backend keeps for every set-up
    (the levels' divergences and transfers, the space's cells) included [bytes]."""

    def __init__(self, host: MultigridHierarchy, backend: Backend):
        t0 = time.perf_counter()
        self.host, self.backend = host, backend
        self.settings = host.settings
        self.levels = [_DeviceLevel(level, backend) for level in host.levels[:-1]]
        self._cycle_levels = self.levels + [_HostCoarsest(host.levels[-1], backend)]
        system = host.system
        first = host.levels[0].system
        if self.levels and system is first:
            self.operator = self.levels[0].operator
        else:  # a Newton system shares the blocks of its preconditioner, the finest level
            shares = (self.levels and system.preconditioner is first
                      and getattr(system.A, "base", None) is first.A)
            self.operator = DeviceOperator(system, backend, self.levels[0].operator if shares else None)
        parts = [self.operator] + [p for lv in self.levels for p in (lv.operator, lv.transfer)]
        kept = {id(k): k for part in parts for k in part.kept}
        self.nbytes = sum(lv.nbytes for lv in self.levels) + nbytes(*kept.values()) + (
            0 if self.levels and self.operator is self.levels[0].operator else self.operator.nbytes)
        self.factor_time_s = host.factor_time_s + sum(lv.factor_time_s for lv in self.levels)
        super().__init__(host.setup_time_s + time.perf_counter() - t0)

    def cycle(self, b, x, depth: int = 0, kind: str | None = None):
        """One cycle on level ``depth`` for ``K x = b`` from ``x`` (device vectors; ``x`` updated
        and returned): the CPU's cycle (:func:`~fbmflow.solvers.multigrid.multigrid_cycle`) on the
        device's levels, the coarsest solved on the CPU."""
        return multigrid_cycle(self._cycle_levels, self.settings, b, x, depth, kind)

    def _remove_pressure_mean(self, x) -> None:
        """:meth:`~fbmflow.solvers.system.SaddlePointSystem.remove_pressure_mean` on the device."""
        p = x[self.host.system.n_u:]
        p[::self._npl] -= float(self._mean_weights @ p) / self._mean_constant

    def solve(self, f, g, rtol=None):
        """As :meth:`MultigridHierarchy.solve <fbmflow.solvers.multigrid.MultigridHierarchy.solve>`,
        on the device: host vectors in and out, the report counting cycles and sweeps;
        :class:`~fbmflow.gpu.device.DeviceMemoryError` where the device's memory runs out."""
        with self.backend.memory_guard("in a linear solve"):
            return self._solve(f, g, rtol)

    def _solve(self, f, g, rtol):
        system, s, backend = self.host.system, self.settings, self.backend
        t0 = time.perf_counter()
        setup = self._charge_setup()
        rtol = self.host.rtol if rtol is None else rtol
        self.operator.refresh()
        host_b = np.concatenate([f, system.balance(g)])
        host_x = np.zeros_like(host_b)
        if system.fixed is not None:
            host_x[system.fixed] = f[system.fixed]  # unit rows: the solution there is the rhs
        b, x = backend.put(host_b), backend.put(host_x)
        project = None
        if system.mean_weights is not None:
            self._npl = system.space.dim + 1
            self._mean_weights = backend.put(system.mean_weights)
            self._mean_constant = float(system.mean_weights[::self._npl].sum())
            project = self._remove_pressure_mean
        border = _border(system)
        x, residuals, cycles = multigrid_iterations(self.operator.apply, self.cycle, b, x, rtol, s, project,
                                                    None if border is None else backend.put(border))
        host_x = backend.get(x)
        converged = bool(residuals[-1] <= rtol * residuals[0])
        report = LinearReport("multigrid (GPU)", setup + time.perf_counter() - t0, iterations=cycles,
                              residuals=residuals, smoothing_sweeps=cycles * self.host.sweeps_per_cycle,
                              setup_time_s=setup, factor_time_s=self.factor_time_s if setup else 0.0,
                              converged=converged)
        return host_x[:system.n_u], host_x[system.n_u:], report


class DeviceMultigridSolver(MultigridSolver):
    """:class:`~fbmflow.solvers.multigrid.MultigridSolver` whose solves run on a GPU
    (:class:`DeviceHierarchy`); the smoothers in colour order whatever ``settings`` say.
    ``backend``: where the arrays go (default CuPy's, :func:`~fbmflow.gpu.device.gpu_backend`;
    the tests pass the simulator's)."""

    name = "multigrid"
    host_factors = False  # the smoothers' local factors are computed on the device

    def __init__(self, settings=None, rtol: float = 1e-8, backend=None, **kwargs):
        super().__init__(settings, rtol, **kwargs)
        if self.settings.smoother not in ("auto", "vanka-factored"):
            raise ValueError("the GPU smoothes with the vanka-factored smoother, not "
                             f"{self.settings.smoother!r}")
        self.settings = dataclasses.replace(self.settings, order="colours")
        self.backend = backend

    def describe(self, dim: int, n_unknowns: int) -> str:
        return "multigrid on the GPU"

    def velocity_operator(self, space):
        """The flow problem's ``(alpha M + beta L + convection N(u)) u`` on the device
        (:meth:`DeviceSpace.apply_mass_laplace <fbmflow.gpu.space.DeviceSpace.apply_mass_laplace>`;
        the space's cells copied once, shared with the Newton blocks' terms)."""
        if self.backend is None:
            self.backend = gpu_backend()
        with self.backend.memory_guard("copying the mesh's cells"):
            return device_space(space, self.backend).apply_mass_laplace

    def divergence_products(self, space, BT):
        """The flow problem's gradient and continuity products on the device
        (:class:`~fbmflow.gpu.operator.DeviceDivergenceProducts`; the level's divergence copied
        once, shared with the operators)."""
        if self.backend is None:
            self.backend = gpu_backend()
        return DeviceDivergenceProducts(space, BT, self.backend)

    def _factor(self, system) -> Factorization:
        host = super()._factor(system)
        if not isinstance(host, MultigridHierarchy):
            raise ValueError("the GPU solver runs on one process")
        if self.backend is None:
            self.backend = gpu_backend()
        with self.backend.memory_guard("setting up the multigrid hierarchy"):
            device = DeviceHierarchy(host, self.backend)
        n = system.n_u + system.n_p
        log.info("GPU: %.2f GB on the device, %.0f bytes per unknown", device.nbytes / 1e9, device.nbytes / n)
        return device


def gpu_solver(linear: MultigridSolver, dim: int, n_unknowns: int) -> DeviceMultigridSolver:
    """``linear``'s settings on the GPU, checked before any work: ParamError naming the fix where
    the ``gpu`` extra or a CUDA device is missing (:func:`~fbmflow.gpu.device.gpu_problem`),
    :class:`~fbmflow.solvers.choice.InsufficientMemory` with the figures where ``n_unknowns``
    of a ``dim``-dimensional flow need more device memory (:data:`DEVICE_BYTES` each) than the
    GPU has free, with the work of the factors' kernel (:data:`~fbmflow.gpu.vanka.FACTOR_SCRATCH`)."""
    problem = gpu_problem()
    if problem is not None:
        raise ParamError(problem)
    backend = gpu_backend()
    need, free = DEVICE_BYTES[dim] * n_unknowns + FACTOR_SCRATCH, backend.free_bytes()
    if free is not None and need > free:
        raise InsufficientMemory(f"the GPU solver needs about {need / 1e9:.1f} GB of device memory for "
                                 f"{n_unknowns} unknowns ({DEVICE_BYTES[dim]} bytes each, {dim}D, and "
                                 f"{FACTOR_SCRATCH / 1e9:.1f} GB to compute the smoothers' factors), more "
                                 f"than the {free / 1e9:.1f} GB free on the GPU; use a coarser mesh (a lower "
                                 "--level) or solver.device = 'cpu'")
    return DeviceMultigridSolver(linear.settings, linear.rtol, backend=backend)
