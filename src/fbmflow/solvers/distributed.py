"""Multigrid over several processes, each holding one block of every level's mesh.

Each process holds, on every level but the coarsest, the system assembled on its block mesh (its
owned cells and the halo layers around them, :mod:`fbmflow.parallel.blocks`): the rows of its owned
unknowns are the whole mesh's. Vectors are local and *consistent* (ghosts hold their owners'
values). One cycle per process:

* **smoothing:** the Vanka sweep (:class:`~fbmflow.solvers.vanka.FactoredVankaSmoother`) over the
  patches of the owned cells, the ghosts held fixed, then the ghosts updated from their owners
  (a restricted additive Schwarz step between the blocks, Gauss–Seidel within each): one
  exchange with each neighbour per sweep. A patch of an owned cell next to a lower block also
  moves the shared nodes, which the update then sets back to the owner's value. The
  smoother differs from the serial one at the blocks' boundaries, so the cycles per solve may grow
  with the number of processes;
* **residual:** the local system's product, masked to the owned unknowns;
* **restriction:** the transposed prolongation of the masked residual, each process's part of
  the coarse sums; the parts at the coarse ghosts are added to their owners
  (:meth:`~fbmflow.parallel.blocks.BlockPartition.add_ghosts`);
* **coarsest level:** the whole coarsest mesh's system, factorised on every process; its
  right-hand side is the sum of all processes' parts (one ``allreduce``), and every process
  solves it redundantly and takes the correction of its own block.

The Krylov method (FGMRES) sums its inner products over the owned unknowns, one reduction each.
"""
from __future__ import annotations

import time

import numpy as np

from ..parallel import sum_over
from .base import Factorization
from .direct import factorize
from .galerkin import truncated_prolongation
from .krylov import fgmres
from .multigrid import MultigridSettings
from .reports import LinearReport
from .system import SaddlePointSystem, balance_volume, expansion
from .vanka import VANKA_VARIANTS, FactoredVankaSmoother


class DistributedMultigrid(Factorization):
    """The multigrid solver of one process among several (see the module docstring), set up for
    ``system``.

    Parameters
    ----------
    system : SaddlePointSystem, this process's part of the fine system (its ``partition`` set),
        its ``coarser`` chain the block levels' systems (each with its ``partition`` and its
        ``prolongation`` from the next one's local vectors) down to the whole coarsest mesh's
        (``partition`` None); or a system whose ``preconditioner`` is such a chain (FGMRES then
        applies ``system``: the Newton operator of a Picard hierarchy)
    settings : MultigridSettings (V-cycles, vanka-factored smoothing, FGMRES)
    rtol : float, the residual reduction a solve reaches when it is asked for none
    """

    def __init__(self, system: SaddlePointSystem, settings: MultigridSettings | None = None,
                 rtol: float = 1e-8):
        t0 = time.perf_counter()
        self.settings = s = settings or MultigridSettings()
        if s.cycle != "V" or s.krylov != "fgmres" or s.smoother not in ("auto", "vanka-factored"):
            raise ValueError("the distributed multigrid runs V-cycles of the vanka-factored smoother inside "
                             f"FGMRES, not {s.cycle}-cycles of {s.smoother} with krylov = {s.krylov!r}")
        self.system, self.rtol = system, rtol
        chain = [system if system.preconditioner is None else system.preconditioner]
        while chain[-1].partition is not None:
            if chain[-1].coarser is None:
                raise ValueError("a process's part of a system needs its coarser chain down to the whole "
                                 "coarsest mesh")
            chain.append(chain[-1].coarser)
        self.levels, self.coarsest = chain[:-1], chain[-1]
        self.partition = system.partition
        self.comm = self.partition.comm
        omega = s.omega or VANKA_VARIANTS["vanka-factored"]
        symmetric = s.symmetric_sweeps(chain[0].transient)
        self.smoothers = [FactoredVankaSmoother(lv, omega, symmetric=symmetric,
                                                cells=lv.partition.owned_cells, order=s.order)
                          for lv in self.levels]
        self.transfers = [truncated_prolongation(lv, *lv.prolongation) for lv in self.levels]
        self.direct = factorize(self.coarsest)
        super().__init__(time.perf_counter() - t0)

    def _coarse(self, depth: int) -> SaddlePointSystem:
        return self.levels[depth + 1] if depth + 1 < len(self.levels) else self.coarsest

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
        r = b - level.apply(x)
        r[~part.owned] = 0.0
        rc = self.transfers[depth].restrict(r)
        coarse = self._coarse(depth)
        if depth + 1 < len(self.levels):
            coarse_part = self.levels[depth + 1].partition
            coarse_part.add_ghosts(rc)
        else:
            rc = sum_over(rc, self.comm)
        if coarse.fixed is not None:
            rc[coarse.fixed] = 0.0
        if coarse.orphans is not None:
            rc[coarse.n_u:] -= coarse.orphans @ rc[coarse.n_u:]
        if depth + 1 < len(self.levels):
            coarse_part.update_ghosts(rc)
        ec = self.cycle(rc, np.zeros_like(rc), depth + 1)
        x += self.transfers[depth].prolongate(ec)
        self._smooth(smoother, part, b, x, s.post_smooth)
        return x

    def _smooth(self, smoother, part, b, x, sweeps):
        for k in range(sweeps):
            smoother.smooth(b, x, 1, first=k)
            part.update_ghosts(x)

    def apply(self, x: np.ndarray) -> np.ndarray:
        """``K x`` (the system's, not the hierarchy's) for a consistent local ``x``, consistent."""
        y = self.system.apply(x)
        self.partition.update_ghosts(y)
        return y

    def solve(self, f: np.ndarray, g: np.ndarray, rtol: float | None = None):
        """Solve the whole system from each process's consistent local right-hand sides ``f``
        (velocity) and ``g`` (pressure) to the residual reduction ``rtol`` (None: the solver's);
        returns the local ``u``, ``p`` (consistent) and a
        :class:`~fbmflow.solvers.reports.LinearReport` (the same on every process)."""
        t0 = time.perf_counter()
        setup = self._charge_setup()
        system, part, s = self.system, self.partition, self.settings
        rtol = self.rtol if rtol is None else rtol
        n_u = system.n_u
        b = np.concatenate([f, self._balance(system, part, g)])
        x = np.zeros_like(b)
        if system.fixed is not None:  # the outer halo's fixed set may differ from the owners'
            x[system.fixed] = f[system.fixed]
            part.update_ghosts(x)
        project = augment = None
        if system.mean_weights is not None:
            def project(v):
                self._remove_pressure_mean(system, part, v)

            augment = np.zeros_like(b)
            augment[n_u:] = expansion(system.mean_weights, system.orphans, system.extension)
            part.update_ghosts(augment)  # a halo cell's extension may differ from its owner's

        def precondition(r):
            return self.cycle(r, np.zeros_like(r))

        x, residuals, cycles = fgmres(self.apply, precondition, b, x, rtol, s.max_iterations, s.restart,
                                      project, augment, inner=part.dot)
        if project is not None:
            project(x)
        converged = bool(residuals[-1] <= rtol * residuals[0])
        report = LinearReport("multigrid", setup + time.perf_counter() - t0, iterations=cycles,
                              residuals=residuals, setup_time_s=setup, converged=converged)
        return x[:n_u], x[n_u:], report

    def _balance(self, system, part, g):
        """``g`` made solvable in a closed domain (:func:`~fbmflow.solvers.system.balance_volume`
        with the sums over the owned cells)."""
        if system.mean_weights is None:
            return g
        return balance_volume(g, system.mean_weights, system.orphans, system.space.dim + 1, system.extension,
                              dot=part.pressure_dot)

    def _remove_pressure_mean(self, system, part, x):
        """Shift the pressure of ``x`` in place so that the whole mesh's ``mean_weights · p = 0``."""
        npl = system.space.dim + 1
        p, w = x[system.n_u:], system.mean_weights
        own = part.owned[system.n_u:]
        const = np.zeros(p.size)
        const[::npl] = 1.0
        wp, wc = self.comm.allreduce(np.array([w[own] @ p[own], w[own] @ const[own]]))
        p -= const * (wp / wc)
