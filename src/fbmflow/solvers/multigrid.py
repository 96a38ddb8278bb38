"""Geometric multigrid for the Q2/P1disc saddle-point systems (monolithic, Vanka smoothing).

The solver is a list of levels, finest first; each holds the level's system, its smoother and the
prolongation from the next coarser level; the coarsest level is solved directly. Coarse systems
are *re-discretisations* of the same operator on the coarser meshes (with the convecting velocity
injected), built by the flow problem: on nested structured meshes this is cheap, exact for the
Stokes part, and avoids assembling Galerkin products of the coupled Q2 velocity block.

Constraints: the prolongation is truncated on the fine DOFs that are no PDE unknowns (fixed and
row-constrained velocities, orphaned or continued pressures) and the restriction is its
transpose, so that a coarse correction never moves a prescribed value and the residuals of
constraint rows never drive a coarse equation; coarse fixed DOFs and orphaned modes get no
correction. Near fictitious boundaries the coarse levels either constrain their own nodes inside
the particles (``coarse_obstacle = "nodes"``) or take Galerkin rows of the truncated prolongation
(``"galerkin"``, :mod:`fbmflow.solvers.galerkin`). ``benchmarks/studies/multigrid_fbm.py`` compares
them.

Cycles: V (gamma = 1), W (gamma = 2) and F. Used stand-alone (cycles until the residual drops by
``rtol``) or as the preconditioner of FGMRES.
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np

from ..config import ParamError, Section, param
from ..cores import FREE_CORES
from .base import Factorization, Hierarchy, LinearSolver
from .direct import factorize
from .galerkin import truncated_prolongation
from .krylov import array_module, fgmres
from .reports import LinearReport
from .system import SaddlePointSystem, expansion
from .vanka import ORDERS, VANKA_VARIANTS, FactoredVankaSmoother, VankaSmoother

log = logging.getLogger(__name__)

CYCLES = ("V", "W", "F")
#: how coarse levels see constraints beyond the walls: each level's own constrained nodes, or
#: Galerkin rows of the truncated prolongation near them (:mod:`fbmflow.solvers.galerkin`)
COARSE_OBSTACLES = ("nodes", "galerkin")
#: the order of a smoother's sweeps (:mod:`fbmflow.solvers.ordering`): every sweep forwards, or
#: forwards and backwards in turn (symmetric Gauss–Seidel); "auto": forward in time steps,
#: symmetric in steady solves
SWEEPS = ("auto", "forward", "symmetric")
#: the linearisation the hierarchy is built from (the flow problem reads it): the system's own
#: (Newton), the Picard one (FGMRES applies the Newton matrix), or "auto": Picard in time steps
LINEARISATIONS = ("auto", "newton", "picard")
#: how many threads the set-ups and solves use (:mod:`fbmflow.cores`)
THREADS = ("free", "fixed")


@dataclass(frozen=True)
class MultigridSettings(Section):
    """Multigrid (the table ``[solver.multigrid]``; see the module docstring)."""

    renamed = {"rtol": "solver.linear_rtol"}

    cycle: str = param("V", "multigrid cycle", choices=CYCLES)
    smoother: str = param("auto", "smoother ('auto': vanka-factored, local factors stored; vanka-full stores "
                          "none and factorises in every sweep)", choices=("auto",) + tuple(VANKA_VARIANTS))
    omega: float = param(0.0, "damping of the smoother's corrections (0: the smoother's own default)",
                         nonnegative=True, maximum=2.0)
    pre_smooth: int = param(2, "smoothing sweeps before the coarse-grid correction", minimum=1)
    post_smooth: int = param(2, "smoothing sweeps after the coarse-grid correction", minimum=1)
    max_iterations: int = param(100, "cycles (FGMRES iterations) per solve at most", minimum=1)
    krylov: str = param("fgmres", "Krylov acceleration: fgmres, or none (multigrid as a stand-alone "
                        "iteration)", choices=("fgmres", "none"))
    restart: int = param(30, "FGMRES restart length", minimum=1)
    coarse_obstacle: str = param("nodes", "how coarse levels see particles: their own nodes inside them, or "
                                 "Galerkin rows of the truncated prolongation", choices=COARSE_OBSTACLES)
    linearisation: str = param("auto", "operator the hierarchy is built from: newton, picard (FGMRES applies "
                               "the Newton matrix; dim times fewer velocity entries) or auto (picard in "
                               "time steps, newton in steady solves)", choices=LINEARISATIONS)
    sweeps: str = param("auto", "order of the smoothing sweeps: forward, symmetric (forward and backward "
                        "in turn) or auto (forward in time steps, symmetric in steady solves)",
                        choices=SWEEPS)
    threads: str = param("free", "Numba threads of the set-ups and solves: free (the cores other processes "
                         "leave free, looked at before each; the same results) or fixed (Numba's count as "
                         "set, NUMBA_NUM_THREADS)", choices=THREADS)
    order: str = param("slabs", "order of the factored smoother's cell patches: slabs (threads sweep slabs "
                       "at once) or colours (a colour's patches at once: the GPU's order, which "
                       "solver.device = 'gpu' takes; on the CPU for comparing with it)", choices=ORDERS)

    def validate(self):
        if self.coarse_obstacle == "galerkin" and self.smoother not in ("auto", "vanka-factored"):
            # the other smoothers re-assemble cell blocks from the element matrices, not the
            # Galerkin rows (measured: overflow on the 3D ball, 8^3)
            raise ParamError("multigrid: coarse_obstacle 'galerkin' needs the vanka-factored smoother, not "
                             f"{self.smoother!r}")
        if self.linearisation == "picard" and self.krylov != "fgmres":
            raise ParamError("multigrid: a Picard hierarchy only preconditions the Newton system inside "
                             "FGMRES; set krylov = 'fgmres' or linearisation = 'newton'")

    def symmetric_sweeps(self, time_step: bool) -> bool:
        """Whether the smoothers sweep forwards and backwards in turn: ``"symmetric"``, or
        ``"auto"`` outside time steps, where convection dominates and a sweep against the flow
        is needed as much as one with it; in time steps the mass term dominates, and the cheaper
        forward sweeps take as many cycles (docs/validation/multigrid-with-fictitious-boundaries.md)."""
        if self.sweeps == "auto":
            return not time_step
        return self.sweeps == "symmetric"

    def picard_hierarchy(self, time_step: bool) -> bool:
        """Whether the hierarchy is built from the Picard linearisation: ``"picard"``, or
        ``"auto"`` in a time step (``time_step``: the mass term dominates the Newton reaction
        term it leaves out; the cycles per solve stay, measured, while the velocity blocks get
        ``dim`` times fewer entries) with FGMRES."""
        if self.linearisation == "auto":
            return time_step and self.krylov == "fgmres"
        return self.linearisation == "picard"


class _Level:
    def __init__(self, system: SaddlePointSystem, settings: MultigridSettings, smoother: str, coarsest: bool,
                 symmetric: bool = False, factor: bool = True):
        self.system = system
        self.n_u, self.n_p = system.n_u, system.n_p
        self.d = system.space.dim if system.space is not None else None
        self.nnz = int(system.A.nnz) + 2 * int(system.BT.nnz)  # of the saddle-point matrix
        if coarsest:
            self.direct = factorize(system)
            return
        omega = settings.omega or VANKA_VARIANTS[smoother]
        if smoother == "vanka-factored":
            self.smoother = FactoredVankaSmoother(system, omega, symmetric=symmetric, order=settings.order,
                                                  factor=factor)
        else:
            self.smoother = VankaSmoother(system, smoother, omega, symmetric=symmetric)
        # prolongation truncated on the fine DOFs that are no PDE unknowns, restriction its
        # transpose: both from the scalar blocks (no block matrix, no transposed copy)
        self.P = truncated_prolongation(system, *system.prolongation)
        coarse = system.coarser
        self.coarse_fixed = coarse.fixed if coarse.fixed is not None else np.zeros(0, dtype=np.int64)
        self.coarse_orphans = coarse.orphans

    def smooth(self, b: np.ndarray, x: np.ndarray, sweeps: int) -> None:
        self.smoother.smooth(b, x, sweeps)

    def residual(self, b: np.ndarray, x: np.ndarray) -> np.ndarray:
        return b - self.system.apply(x)

    def solve(self, b: np.ndarray) -> np.ndarray:
        """The coarsest level's direct solve of ``K x = b``."""
        u, p = self.direct(b[:self.n_u], b[self.n_u:])
        return np.concatenate([u, p])

    def restrict(self, r: np.ndarray, coarse: "_Level") -> np.ndarray:
        rc = self.P.restrict(r)
        rc[self.coarse_fixed] = 0.0
        if self.coarse_orphans is not None:  # modes no coarse velocity sees: no correction
            rc[coarse.n_u:] -= self.coarse_orphans @ rc[coarse.n_u:]
        return rc

    def prolongate(self, e: np.ndarray, coarse: "_Level") -> np.ndarray:
        return self.P.prolongate(e)


def multigrid_cycle(levels: list, settings: MultigridSettings, b, x, depth: int = 0, kind: str | None = None):
    """One ``kind`` cycle (V, W or F; None: the settings') on ``levels[depth]`` for ``K x = b``
    from ``x`` (updated and returned): pre-smoothing, the restricted residual's correction from
    the coarser level's cycles (the coarsest level solved directly), its prolongation, post-
    smoothing. The levels' vectors are NumPy's or, on the GPU (:mod:`fbmflow.gpu`), CuPy's:
    every level but the last offers ``smooth(b, x, sweeps)``, ``residual(b, x)``,
    ``restrict(r, coarse)`` and ``prolongate(e, coarse)``, the last ``solve(b)`` and ``n_u``."""
    kind = kind or settings.cycle
    level = levels[depth]
    if depth == len(levels) - 1:
        return level.solve(b)
    level.smooth(b, x, settings.pre_smooth)
    coarse = levels[depth + 1]
    rc = level.restrict(level.residual(b, x), coarse)
    ec = array_module(rc).zeros_like(rc)
    last = depth + 1 == len(levels) - 1
    if kind == "V":
        ec = multigrid_cycle(levels, settings, rc, ec, depth + 1, "V")
    elif kind == "W":
        ec = multigrid_cycle(levels, settings, rc, ec, depth + 1, "W")
        if not last:
            ec = multigrid_cycle(levels, settings, rc, ec, depth + 1, "W")
    else:  # F: an F-cycle then a V-cycle on the coarser level
        ec = multigrid_cycle(levels, settings, rc, ec, depth + 1, "F")
        if not last:
            ec = multigrid_cycle(levels, settings, rc, ec, depth + 1, "V")
    x += level.prolongate(ec, coarse)
    level.smooth(b, x, settings.post_smooth)
    return x


def multigrid_iterations(apply, cycle, b, x, rtol: float, settings: MultigridSettings, project=None,
                         border=None):
    """Solve ``K x = b`` from ``x`` to the relative residual ``rtol``: FGMRES preconditioned by one
    ``cycle(r, e)`` from zero each (``settings.krylov = "fgmres"``), or stand-alone cycles, at most
    ``settings.max_iterations``; ``apply``: ``K x``; ``project`` (or None): the mean-pressure
    projection after each cycle and at the end; ``border``: see
    :func:`~fbmflow.solvers.krylov.fgmres`. Vectors NumPy's or CuPy's (:mod:`fbmflow.gpu`).
    Returns ``x``, the residual norms and the cycles."""
    xp = array_module(b)
    if settings.krylov == "fgmres":
        def precondition(r):
            return cycle(r, xp.zeros_like(r))

        x, residuals, cycles = fgmres(apply, precondition, b, x, rtol, settings.max_iterations,
                                      settings.restart, project, border)
    else:
        r0 = float(xp.linalg.norm(b - apply(x)))
        residuals, cycles = [r0], 0
        while residuals[-1] > rtol * r0 and cycles < settings.max_iterations:
            x = cycle(b, x)
            if project is not None:
                project(x)
            residuals.append(float(xp.linalg.norm(b - apply(x))))
            cycles += 1
    if project is not None:
        project(x)
    return x, residuals, cycles


class MultigridHierarchy(Factorization):
    """The multigrid hierarchy of one system (PyAMG's ``MultilevelSolver``): its levels, finest
    first, each with its system, smoother and transfers, the coarsest factorised. Re-entrant: a
    solve keeps its counters to itself. ``repr`` shows the level table and the operator
    complexity; :meth:`aspreconditioner` gives one cycle as a SciPy ``LinearOperator``."""

    def __init__(self, system: SaddlePointSystem, levels: list[_Level], settings: MultigridSettings,
                 smoother: str, rtol: float, setup_time_s: float):
        super().__init__(setup_time_s)
        self.system, self.levels, self.settings, self.smoother, self.rtol = (system, levels, settings,
                                                                              smoother, rtol)
        self.sweeps_per_cycle = self._sweeps(0, settings.cycle)
        #: of the set-up, the seconds of the smoothers' local factors
        self.factor_time_s = sum(lv.smoother.factor_time_s for lv in levels[:-1])

    def _sweeps(self, depth: int, kind: str) -> int:
        """Smoothing sweeps of one ``kind`` cycle from level ``depth`` (all levels it visits)."""
        if depth == len(self.levels) - 1:
            return 0
        s = self.settings
        inner = self._sweeps(depth + 1, "F" if kind == "F" else kind)
        if depth + 1 < len(self.levels) - 1 and kind in ("W", "F"):
            inner += self._sweeps(depth + 1, "W" if kind == "W" else "V")
        return s.pre_smooth + s.post_smooth + inner

    def cycle(self, b: np.ndarray, x: np.ndarray, depth: int = 0, kind: str | None = None) -> np.ndarray:
        """One cycle on level ``depth`` for ``K x = b`` from ``x`` (updated and returned)."""
        return multigrid_cycle(self.levels, self.settings, b, x, depth, kind)

    def aspreconditioner(self):
        """One cycle from zero as a ``scipy.sparse.linalg.LinearOperator`` on the whole system's
        vectors ``(n_u + n_p,)``, for SciPy's Krylov methods."""
        from scipy.sparse.linalg import LinearOperator

        n = self.system.n_u + self.system.n_p
        return LinearOperator((n, n), matvec=lambda r: self.cycle(np.asarray(r, dtype=float).ravel(),
                                                                  np.zeros(n)), dtype=float)

    @property
    def operator_complexity(self) -> float:
        """Non-zeros of all levels' matrices over those of the finest (PyAMG's measure of the
        hierarchy's memory and work per cycle)."""
        nnz = [lv.nnz for lv in self.levels]
        return float(sum(nnz) / nnz[0])

    def __repr__(self) -> str:
        s = self.settings
        lines = [f"MultigridHierarchy: {s.cycle}-cycle, {self.smoother} "
                 f"({s.pre_smooth}+{s.post_smooth} sweeps), "
                 f"{'inside FGMRES' if s.krylov == 'fgmres' else 'stand-alone'}",
                 f"Number of levels:    {len(self.levels)}",
                 f"Operator complexity: {self.operator_complexity:6.3f}",
                 "  level   unknowns   non-zeros [%]"]
        total = sum(lv.nnz for lv in self.levels)
        for k, lv in enumerate(self.levels):
            where = " (direct)" if k == len(self.levels) - 1 else ""
            share = 100.0 * lv.nnz / total
            lines.append(f"  {k:5d} {lv.n_u + lv.n_p:10d} {lv.nnz:11d} [{share:5.2f}]{where}")
        return "\n".join(lines)

    def solve(self, f, g, rtol=None):
        """Cycles (inside FGMRES, or stand-alone) until the residual drops ``rtol`` times (None:
        the solver's target), on the free cores where the settings say so
        (:meth:`fbmflow.cores.FreeCores.adapt`); the report counts cycles and smoothing sweeps on
        all levels."""
        _take_free_cores(self.settings)
        return self._solve(f, g, rtol)

    def _solve(self, f, g, rtol):
        system, s = self.system, self.settings
        t0 = time.perf_counter()
        setup = self._charge_setup()
        rtol = self.rtol if rtol is None else rtol
        b = np.concatenate([f, system.balance(g)])
        x = np.zeros_like(b)
        if system.fixed is not None:
            x[system.fixed] = f[system.fixed]  # unit rows: the solution there is the rhs
        project = system.remove_pressure_mean if system.mean_weights is not None else None
        x, residuals, cycles = multigrid_iterations(system.apply, self.cycle, b, x, rtol, s, project,
                                                    _border(system))
        log.debug("multigrid: %d cycles, residual %.2e -> %.2e, %.2f s", cycles, residuals[0], residuals[-1],
                  time.perf_counter() - t0)
        converged = bool(residuals[-1] <= rtol * residuals[0])  # False for NaN as well
        report = LinearReport("multigrid", setup + time.perf_counter() - t0, iterations=cycles,
                              residuals=residuals, smoothing_sweeps=cycles * self.sweeps_per_cycle,
                              setup_time_s=setup, factor_time_s=self.factor_time_s if setup else 0.0,
                              converged=converged)
        return x[:system.n_u], x[system.n_u:], report


def _take_free_cores(settings: MultigridSettings) -> None:
    """Under ``threads = "free"`` Numba's count set to the cores other processes leave
    (:meth:`fbmflow.cores.FreeCores.adapt`); under ``"fixed"`` nothing."""
    if settings.threads == "free":
        FREE_CORES.adapt()


def _border(system: SaddlePointSystem) -> np.ndarray | None:
    """The direction ``e`` of the mean-pressure border's multiplier in a closed domain (None
    where the pressure is determined): a uniform expansion rate of the fluid
    (:func:`~fbmflow.solvers.system.expansion`). ``balance`` makes the continuity data
    compatible with the constant pressure, the left null vector of the nodal boundary's
    system; the sharp boundary's ghost rows give the left null vector velocity components
    as well, so the right-hand side can miss the range along ``e`` and FGMRES solves for
    that multiple too, as the bordered direct solve does."""
    if system.mean_weights is None:
        return None
    e = np.zeros(system.n_u + system.n_p)
    e[system.n_u:] = expansion(system.mean_weights, system.orphans, system.extension)
    return e


class MultigridSolver(LinearSolver):
    """Monolithic geometric multigrid, optionally inside FGMRES, with ``settings``
    (:class:`MultigridSettings`, or its fields as keywords); ``rtol``: the relative residual a
    solve reaches when it is asked for none. Needs systems with a ``coarser`` chain, which the
    flow problem builds as :meth:`hierarchy` asks."""

    name = "multigrid"
    #: whether the set-up computes the smoothers' local factors (the GPU's solver computes them
    #: on the device, :mod:`fbmflow.gpu`)
    host_factors = True

    def __init__(self, settings: MultigridSettings | None = None, rtol: float = 1e-8, **kwargs):
        self.settings = settings or MultigridSettings(**kwargs)
        if not 0.0 < rtol < 1.0:
            raise ValueError(f"rtol (multigrid's residual reduction per solve) must lie in (0, 1), got "
                             f"{rtol}")
        self.rtol = float(rtol)

    def engine(self, dim: int, n_unknowns: int) -> str:
        return "multigrid"

    def hierarchy(self, time_step: bool) -> Hierarchy:
        s = self.settings
        return Hierarchy(picard=s.picard_hierarchy(time_step), follows_iterates=s.krylov == "fgmres",
                         galerkin=s.coarse_obstacle == "galerkin")

    def smoother_for(self, system: SaddlePointSystem) -> str:
        """The smoother used for ``system``: the configured one; ``"auto"`` is ``vanka-factored``,
        whose stored local factors make a sweep several times cheaper than ``vanka-full``'s,
        which factorises every cell's block in every sweep, and which alone handles row
        constraints and Galerkin rows.
        ``vanka-full`` stores nothing per cell, for a machine short of memory."""
        return "vanka-factored" if self.settings.smoother == "auto" else self.settings.smoother

    def factor(self, system: SaddlePointSystem) -> Factorization:
        """Set up the hierarchy of ``system`` (of its ``preconditioner`` where it has one): the
        smoothers' blocks on every level and the coarsest level's factorisation, on the free
        cores where the settings say so (:meth:`fbmflow.cores.FreeCores.adapt`); a
        :class:`~fbmflow.solvers.distributed.DistributedMultigrid` for one process's part of a
        system (its ``partition`` set)."""
        _take_free_cores(self.settings)
        return self._factor(system)

    def _factor(self, system: SaddlePointSystem) -> Factorization:
        s = self.settings
        if system.preconditioner is not None and s.krylov != "fgmres":
            raise ValueError("a system with a separate preconditioner needs krylov = 'fgmres'")
        if system.rows is not None and system.mean_weights is not None and s.krylov == "none":
            raise ValueError("stand-alone multigrid cycles cannot solve the sharp fictitious boundary in a "
                             "closed domain (its right-hand side is compatible only up to the mean-pressure "
                             "multiplier, which FGMRES solves for); set solver.multigrid.krylov = \"fgmres\"")
        if system.rows is not None and self.smoother_for(system) != "vanka-factored":
            raise ValueError("only the vanka-factored smoother handles row constraints (the sharp fictitious "
                             f"boundary), not {s.smoother!r}; set solver.multigrid.smoother = "
                             "\"auto\" or \"vanka-factored\", or use the direct solver")
        t0 = time.perf_counter()
        base = system if system.preconditioner is None else system.preconditioner
        if base.partition is not None:  # one process's part: the hierarchy over the processes
            from .distributed import DistributedMultigrid  # it builds on this module's settings

            return DistributedMultigrid(system, s, self.rtol)
        chain = [base]
        while chain[-1].coarser is not None:
            chain.append(chain[-1].coarser)
        smoother = self.smoother_for(base)
        symmetric = s.symmetric_sweeps(base.transient)
        levels = [_Level(c, s, smoother, coarsest=(i == len(chain) - 1), symmetric=symmetric,
                         factor=self.host_factors) for i, c in enumerate(chain)]
        return MultigridHierarchy(system, levels, s, smoother, self.rtol, time.perf_counter() - t0)
