"""Multigrid over several processes, each holding one slab of every level's mesh.

Each process holds, on every level but the coarsest, the system assembled on its slab mesh (its
owned cell layers and one halo layer, :mod:`fbmflow.parallel.slabs`): the rows of its owned
unknowns are the whole mesh's. Vectors are local and *consistent* (ghosts hold their owners'
values). One cycle per process:

* **smoothing:** the Vanka sweep (:class:`~fbmflow.solvers.vanka.FactoredVankaSmoother`) over the
  patches of the owned cells, the ghosts held fixed, then the ghosts updated from their owners
  (a restricted additive Schwarz step between the slabs, Gauss–Seidel within each): one
  exchange with each neighbour per sweep. A patch of an owned cell next to the slab below also
  moves the shared node plane, which the update then sets back to the owner's value. The
  smoother differs from the serial one at the slab boundaries, so the cycles per solve may grow
  with the number of processes;
* **residual:** the local system's product, masked to the owned unknowns;
* **restriction:** the transposed prolongation of the masked residual, each process's part of
  the coarse sums; the parts at the coarse ghosts are added to their owners
  (:meth:`~fbmflow.parallel.slabs.SlabPartition.add_ghosts`);
* **coarsest level:** the whole coarsest mesh's system, factorised on every process; its
  right-hand side is the sum of all processes' parts (one ``allreduce``), and every process
  solves it redundantly and takes the correction of its own slab.

The Krylov method (FGMRES) sums its inner products over the owned unknowns, one reduction each.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..parallel import sum_over
from .direct import factorize
from .galerkin import truncated_prolongation
from .krylov import fgmres
from .multigrid import MultigridSettings
from .reports import LinearReport
from .system import SaddlePointSystem, expansion
from .vanka import VANKA_VARIANTS, FactoredVankaSmoother


@dataclass
class SlabLevel:
    """One level of a process's slabs: its partition (:class:`~fbmflow.parallel.slabs.SlabPartition`:
    ``owned``, ``owned_cells``, ``update_ghosts``, ``add_ghosts``, ``dot``) and the system on the
    slab mesh, whose ``prolongation`` comes from the next coarser level's local vectors (the
    whole coarsest mesh's, below the last slab level)."""

    partition: object
    system: SaddlePointSystem


class DistributedMultigrid:
    """The multigrid solver of one process among several (see the module docstring).

    Parameters
    ----------
    levels : list of SlabLevel, finest first, every one but the coarsest
    coarsest : SaddlePointSystem, the whole coarsest mesh's system
    comm : the processes' communicator (mpi4py's, or :class:`~fbmflow.parallel.comm.SerialComm`)
    settings : MultigridSettings (V-cycles, vanka-factored smoothing, FGMRES)
    rtol : float, the residual reduction a solve reaches
    """

    def __init__(self, levels: list[SlabLevel], coarsest: SaddlePointSystem, comm,
                 settings: MultigridSettings | None = None, rtol: float = 1e-8):
        t0 = time.perf_counter()
        self.settings = s = settings or MultigridSettings()
        if s.cycle != "V" or s.krylov != "fgmres" or s.smoother not in ("auto", "vanka-factored"):
            raise ValueError("the distributed multigrid runs V-cycles of the vanka-factored smoother inside "
                             f"FGMRES, not {s.cycle}-cycles of {s.smoother} with krylov = {s.krylov!r}")
        self.levels, self.coarsest, self.comm, self.rtol = levels, coarsest, comm, rtol
        fine = levels[0].system
        omega = s.omega or VANKA_VARIANTS["vanka-factored"]
        symmetric = s.symmetric_sweeps(fine.transient)
        self.smoothers = [FactoredVankaSmoother(lv.system, omega, symmetric=symmetric,
                                                cells=lv.partition.owned_cells) for lv in levels]
        self.transfers = [truncated_prolongation(lv.system, *lv.system.prolongation) for lv in levels]
        self.direct = factorize(coarsest)
        self.setup_time_s = time.perf_counter() - t0

    def _coarse(self, depth: int) -> SaddlePointSystem:
        return self.levels[depth + 1].system if depth + 1 < len(self.levels) else self.coarsest

    def cycle(self, b: np.ndarray, x: np.ndarray, depth: int = 0) -> np.ndarray:
        """One V-cycle on level ``depth`` for ``K x = b`` from ``x`` (both consistent; ``x``
        updated and returned, consistent)."""
        if depth == len(self.levels):
            n_u = self.coarsest.n_u
            return np.concatenate(self.direct(b[:n_u], b[n_u:]))
        s = self.settings
        level, smoother = self.levels[depth], self.smoothers[depth]
        part = level.partition
        self._smooth(smoother, part, b, x, s.pre_smooth)
        r = b - level.system.apply(x)
        r[~part.owned] = 0.0
        rc = self.transfers[depth].restrict(r)
        coarse = self._coarse(depth)
        if depth + 1 < len(self.levels):
            coarse_part = self.levels[depth + 1].partition
            coarse_part.add_ghosts(rc, self.comm)
        else:
            rc = sum_over(rc, self.comm)
        if coarse.fixed is not None:
            rc[coarse.fixed] = 0.0
        if coarse.orphans is not None:
            rc[coarse.n_u:] -= coarse.orphans @ rc[coarse.n_u:]
        if depth + 1 < len(self.levels):
            coarse_part.update_ghosts(rc, self.comm)
        ec = self.cycle(rc, np.zeros_like(rc), depth + 1)
        x += self.transfers[depth].prolongate(ec)
        self._smooth(smoother, part, b, x, s.post_smooth)
        return x

    def _smooth(self, smoother, part, b, x, sweeps):
        for k in range(sweeps):
            smoother.smooth(b, x, 1, first=k)
            part.update_ghosts(x, self.comm)

    def apply(self, x: np.ndarray) -> np.ndarray:
        """``K x`` for a consistent local ``x``, consistent."""
        y = self.levels[0].system.apply(x)
        self.levels[0].partition.update_ghosts(y, self.comm)
        return y

    def solve(self, f: np.ndarray, g: np.ndarray, rtol: float | None = None):
        """Solve the whole system from each process's consistent local right-hand sides ``f``
        (velocity) and ``g`` (pressure) to the residual reduction ``rtol`` (None: the solver's);
        returns the local ``u``, ``p`` (consistent) and a
        :class:`~fbmflow.solvers.reports.LinearReport` (the same on every process)."""
        t0 = time.perf_counter()
        system, part, s = self.levels[0].system, self.levels[0].partition, self.settings
        rtol = self.rtol if rtol is None else rtol
        n_u = system.n_u
        b = np.concatenate([f, self._balance(system, part, g)])
        x = np.zeros_like(b)
        if system.fixed is not None:
            x[system.fixed] = f[system.fixed]
        project = augment = None
        if system.mean_weights is not None:
            def project(v):
                self._remove_pressure_mean(system, part, v)

            augment = np.zeros_like(b)
            augment[n_u:] = expansion(system.mean_weights, system.orphans, system.extension)

        def precondition(r):
            return self.cycle(r, np.zeros_like(r))

        x, residuals, cycles = fgmres(self.apply, precondition, b, x, rtol, s.max_iterations, s.restart,
                                      project, augment, inner=lambda v, w: part.dot(v, w, self.comm))
        if project is not None:
            project(x)
        converged = bool(residuals[-1] <= rtol * residuals[0])
        report = LinearReport("multigrid", time.perf_counter() - t0, iterations=cycles, residuals=residuals,
                              converged=converged)
        return x[:n_u], x[n_u:], report

    def _balance(self, system, part, g):
        """``g`` made solvable in a closed domain (:func:`~fbmflow.solvers.system.balance_volume`
        with the sums over the owned cells)."""
        if system.mean_weights is None:
            return g
        npl = system.space.dim + 1
        q = np.zeros(g.size)
        q[::npl] = 1.0
        if system.orphans is not None:
            q = q - system.orphans @ q
        w = expansion(system.mean_weights, system.orphans, system.extension)
        own = part.owned[system.n_u:]
        qg, qw = self.comm.allreduce(np.array([q[own] @ g[own], q[own] @ w[own]]))
        return g - (qg / qw) * w

    def _remove_pressure_mean(self, system, part, x):
        """Shift the pressure of ``x`` in place so that the whole mesh's ``mean_weights · p = 0``."""
        npl = system.space.dim + 1
        p, w = x[system.n_u:], system.mean_weights
        own = part.owned[system.n_u:]
        const = np.zeros(p.size)
        const[::npl] = 1.0
        wp, wc = self.comm.allreduce(np.array([w[own] @ p[own], w[own] @ const[own]]))
        p -= const * (wp / wc)
