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
(``"galerkin"``, :mod:`fbmflow.solvers.galerkin`). ``benchmarks/bench_multigrid_fbm.py`` compares
them.

Cycles: V (gamma = 1), W (gamma = 2) and F. Used stand-alone (cycles until the residual drops by
``rtol``) or as the preconditioner of FGMRES.
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np

from .direct import factorize
from .galerkin import truncated_prolongation
from .krylov import fgmres
from .reports import LinearReport
from .system import SaddlePointSystem, expansion
from .vanka import VANKA_VARIANTS, FactoredVankaSmoother, VankaSmoother

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


@dataclass(frozen=True)
class MultigridSettings:
    """Multigrid parameters (see the module docstring)."""

    cycle: str = "V"
    smoother: str = "auto"  # "auto": vanka-factored (smoother_for)
    omega: float | None = None  # None: the smoother's default damping
    pre_smooth: int = 2
    post_smooth: int = 2
    rtol: float = 1e-8
    max_iterations: int = 100
    krylov: str = "fgmres"  # or "none": multigrid as a stand-alone iteration
    restart: int = 30
    coarse_obstacle: str = "nodes"  # or "galerkin" (solvers/galerkin.py)
    linearisation: str = "auto"  # of the hierarchy: "newton", "picard" or "auto" (LINEARISATIONS)
    sweeps: str = "auto"  # "forward", "symmetric" or "auto" (SWEEPS)

    def __post_init__(self):
        if self.cycle not in CYCLES:
            raise ValueError(f"unknown cycle {self.cycle!r}; choose one of {CYCLES}")
        if self.smoother != "auto" and self.smoother not in VANKA_VARIANTS:
            raise ValueError(f"unknown smoother {self.smoother!r}; choose 'auto' or one of "
                             f"{sorted(VANKA_VARIANTS)}")
        if self.coarse_obstacle not in COARSE_OBSTACLES:
            raise ValueError(f"unknown coarse obstacle {self.coarse_obstacle!r}; choose one of "
                             f"{COARSE_OBSTACLES}")
        if self.coarse_obstacle == "galerkin" and self.smoother not in ("auto", "vanka-factored"):
            # the other smoothers re-assemble cell blocks from the element matrices, not the
            # Galerkin rows (measured: overflow on the 3D ball, 8^3)
            raise ValueError("coarse_obstacle 'galerkin' needs the vanka-factored smoother, not "
                             f"{self.smoother!r}")
        if self.krylov not in ("fgmres", "none"):
            raise ValueError(f"unknown Krylov method {self.krylov!r}; choose 'fgmres' or 'none'")
        if self.sweeps not in SWEEPS:
            raise ValueError(f"unknown sweep order {self.sweeps!r}; choose one of {SWEEPS}")
        if self.linearisation not in LINEARISATIONS:
            raise ValueError(f"unknown linearisation {self.linearisation!r}; choose one of {LINEARISATIONS}")
        if self.linearisation == "picard" and self.krylov != "fgmres":
            raise ValueError("a Picard hierarchy only preconditions the Newton system inside FGMRES; "
                             "set krylov = 'fgmres' or linearisation = 'newton'")

    def symmetric_sweeps(self, time_step: bool) -> bool:
        """Whether the smoothers sweep forwards and backwards in turn: ``"symmetric"``, or
        ``"auto"`` outside time steps, where convection dominates and a sweep against the flow
        is needed as much as one with it; in time steps the mass term dominates, and the cheaper
        forward sweeps take as many cycles (docs/validation.md, "Multigrid with fictitious
        boundaries")."""
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
                 symmetric: bool = False):
        self.system = system
        self.n_u, self.n_p = system.n_u, system.n_p
        self.d = system.space.dim if system.space is not None else None
        if coarsest:
            self.direct = factorize(system)
            return
        omega = settings.omega if settings.omega is not None else VANKA_VARIANTS[smoother]
        if smoother == "vanka-factored":
            self.smoother = FactoredVankaSmoother(system, omega, symmetric=symmetric)
        else:
            self.smoother = VankaSmoother(system, smoother, omega, symmetric=symmetric)
        # prolongation truncated on the fine DOFs that are no PDE unknowns; restriction its transpose
        self.P = truncated_prolongation(system, *system.prolongation)
        self.R = self.P.T.tocsr()
        coarse = system.coarser
        self.coarse_fixed = coarse.fixed if coarse.fixed is not None else np.zeros(0, dtype=np.int64)
        self.coarse_orphans = coarse.orphans

    def restrict(self, r: np.ndarray, coarse: "_Level") -> np.ndarray:
        rc = self.R @ r
        rc[self.coarse_fixed] = 0.0
        if self.coarse_orphans is not None:  # modes no coarse velocity sees: no correction
            rc[coarse.n_u:] -= self.coarse_orphans @ rc[coarse.n_u:]
        return rc

    def prolongate(self, e: np.ndarray, coarse: "_Level") -> np.ndarray:
        return self.P @ e


class MultigridSolver:
    """Monolithic geometric multigrid, optionally inside FGMRES.

    Needs systems with a ``coarser`` chain (``needs_hierarchy``): the flow problem builds them.
    """

    name = "multigrid"
    needs_hierarchy = True

    def __init__(self, settings: MultigridSettings | None = None, **kwargs):
        self.settings = settings or MultigridSettings(**kwargs)

    def smoother_for(self, system: SaddlePointSystem) -> str:
        """The smoother used for ``system``: the configured one; ``"auto"`` is ``vanka-factored``,
        whose stored local factors make a sweep several times cheaper than ``vanka-full``'s,
        which factorises every cell's block in every sweep, and which alone handles row
        constraints and Galerkin rows.
        ``vanka-full`` stores nothing per cell, for a machine short of memory."""
        return "vanka-factored" if self.settings.smoother == "auto" else self.settings.smoother

    def setup(self, system: SaddlePointSystem) -> list[_Level]:
        chain = [system]
        while chain[-1].coarser is not None:
            chain.append(chain[-1].coarser)
        smoother = self.smoother_for(system)
        symmetric = self.settings.symmetric_sweeps(system.transient)
        return [_Level(s, self.settings, smoother, coarsest=(i == len(chain) - 1), symmetric=symmetric)
                for i, s in enumerate(chain)]

    def cycle(self, levels: list[_Level], b: np.ndarray, x: np.ndarray, depth: int = 0,
              kind: str | None = None) -> np.ndarray:
        """One cycle on level ``depth`` for ``K x = b`` from ``x`` (updated and returned)."""
        kind = kind or self.settings.cycle
        level = levels[depth]
        if depth == len(levels) - 1:
            u, p = level.direct(b[:level.n_u], b[level.n_u:])
            return np.concatenate([u, p])
        s = self.settings
        level.smoother.smooth(b, x, s.pre_smooth)
        self._sweeps += s.pre_smooth
        r = b - level.system.apply(x)
        coarse = levels[depth + 1]
        rc = level.restrict(r, coarse)
        ec = np.zeros_like(rc)
        if kind == "V":
            ec = self.cycle(levels, rc, ec, depth + 1, "V")
        elif kind == "W":
            ec = self.cycle(levels, rc, ec, depth + 1, "W")
            if depth + 1 < len(levels) - 1:
                ec = self.cycle(levels, rc, ec, depth + 1, "W")
        else:  # F: an F-cycle then a V-cycle on the coarser level
            ec = self.cycle(levels, rc, ec, depth + 1, "F")
            if depth + 1 < len(levels) - 1:
                ec = self.cycle(levels, rc, ec, depth + 1, "V")
        x += level.prolongate(ec, coarse)
        level.smoother.smooth(b, x, s.post_smooth)
        self._sweeps += s.post_smooth
        return x

    def factor(self, system: SaddlePointSystem):
        """Set up the hierarchy of ``system`` once (smoother blocks, coarse factorisation);
        returns ``solve(f, g, rtol=None) -> (u, p, LinearReport)`` (``rtol``: this solve's target,
        default ``settings.rtol``)."""
        if system.preconditioner is not None and self.settings.krylov != "fgmres":
            raise ValueError("a system with a separate preconditioner needs krylov = 'fgmres'")
        if system.rows is not None and system.mean_weights is not None and self.settings.krylov == "none":
            raise ValueError("stand-alone multigrid cycles cannot solve the sharp fictitious boundary in a "
                             "closed domain (its right-hand side is compatible only up to the mean-pressure "
                             "multiplier, which FGMRES solves for); set solver.mg_krylov = \"fgmres\"")
        if system.rows is not None and self.smoother_for(system) != "vanka-factored":
            raise ValueError("only the vanka-factored smoother handles row constraints (the sharp fictitious "
                             f"boundary), not {self.settings.smoother!r}; set solver.mg_smoother = "
                             "\"auto\" or \"vanka-factored\", or use the direct solver")
        t0 = time.perf_counter()
        levels = self.setup(system if system.preconditioner is None else system.preconditioner)
        pending = [time.perf_counter() - t0]  # the set-up time, charged to the first solve only

        def solve(f, g, rtol=None):
            return self._solve(system, levels, pending.pop() if pending else 0.0, f, g, rtol)

        solve.takes_rtol = True
        return solve

    def solve(self, system: SaddlePointSystem, f: np.ndarray, g: np.ndarray):
        """Solve ``[[A, B], [B^T, 0]] [u, p] = [f, g]`` to relative residual ``settings.rtol``."""
        return self.factor(system)(f, g)

    @staticmethod
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

    def _solve(self, system, levels, setup, f, g, rtol=None):
        t0 = time.perf_counter() - setup
        self._sweeps = 0
        s = self.settings
        rtol = s.rtol if rtol is None else rtol
        b = np.concatenate([f, system.balance(g)])
        x = np.zeros_like(b)
        if system.fixed is not None:
            x[system.fixed] = f[system.fixed]  # unit rows: the solution there is the rhs
        project = system.remove_pressure_mean if system.mean_weights is not None else None
        if s.krylov == "fgmres":
            def precondition(r):
                return self.cycle(levels, r, np.zeros_like(r))

            x, residuals, cycles = fgmres(system.apply, precondition, b, x, rtol, s.max_iterations,
                                          s.restart, project, self._border(system))
        else:
            r0 = float(np.linalg.norm(b - system.apply(x)))
            residuals, cycles = [r0], 0
            while residuals[-1] > rtol * r0 and cycles < s.max_iterations:
                x = self.cycle(levels, b, x)
                if project is not None:
                    project(x)
                residuals.append(float(np.linalg.norm(b - system.apply(x))))
                cycles += 1
        if project is not None:
            project(x)
        log.debug("multigrid: %d cycles, residual %.2e -> %.2e, %.2f s", cycles, residuals[0], residuals[-1],
                  time.perf_counter() - t0)
        converged = bool(residuals[-1] <= rtol * residuals[0])  # False for NaN as well
        report = LinearReport(self.name, time.perf_counter() - t0, iterations=cycles,
                              residuals=residuals, smoothing_sweeps=self._sweeps, setup_time_s=setup,
                              converged=converged)
        return x[:system.n_u], x[system.n_u:], report
