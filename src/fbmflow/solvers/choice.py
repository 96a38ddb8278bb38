"""Which linear solver a run takes, and whether it fits the machine: the one place where
``solver.linear = "auto"`` is resolved, and the memory guard.

**Cost.** The time of one linear solve (its share of the factorisation or the multigrid set-up
included) is modelled per engine as ``t = c n (n / n_ref)^p`` seconds for ``n`` unknowns, with
constants fitted to runs on this project's 2-core machine (benchmarks/results/solver_table.md and
the rows cited below). A multigrid solve costs cycles, whose number grows with the accuracy asked
of it: the model has one constant for loose solves (relative residual 1e-3 or more, two to four
cycles: inexact Newton steps, time steps) and one for tight ones (about ten cycles). A time step
of a coupled run also solves right-hand sides with the last Newton step's factorisation, the
implicit coupling's responses to the particles' rigid motions (three per disk, six per sphere):
a direct solver answers them by substitution (:data:`SUBSTITUTION_COST`), multigrid by a solve
each. :func:`cheapest_solver` compares a step of :data:`NEWTON_SOLVES_PER_STEP` Newton solves and
the responses. Candidates are the direct solver (PARDISO where installed, else SuperLU) and
multigrid; a candidate whose memory estimate exceeds what the machine has is left out.

**Memory.** :func:`estimate_memory` models a run's peak resident memory by engine
(:data:`MEMORY_MODEL`); :func:`check_memory` refuses, before the first solve, a run that cannot
fit (:class:`InsufficientMemory`, with the figure and a remedy) and warns above half of it.
"""
from __future__ import annotations

import logging
import sys
from collections.abc import Callable
from pathlib import Path

from ..config import ParamError
from . import direct
from .base import LinearSolver
from .direct import DirectSolver
from .multigrid import MultigridSettings, MultigridSolver

log = logging.getLogger(__name__)

#: (dim, engine) -> (c [s per unknown at n_ref], n_ref, p). Direct solvers fill more than
#: linearly; multigrid is linear. Measured per solve: cavity-2d level 3 (45 570 unknowns, steady
#: Newton): SuperLU 0.48 / 0.39 s, PARDISO 0.18 / 0.13 s, multigrid 0.31 / 0.32 s (2.4 cycles) at
#: Re 400 / 1000; glowinski-free-fall level 2 (17 106 unknowns, time steps to 1e-8): SuperLU
#: 0.19 s, multigrid 1.4 s (12 cycles); ten-cate (time steps to 1e-3): PARDISO about 1.0 / 11 s
#: at 64 547 / 278 739 unknowns, multigrid 0.5 / 1.7 s; channel-3d level 4 (486 979 unknowns,
#: steady Newton): multigrid 8.6 s (3.3 cycles). SuperLU in 3D (nested-dissection order), one
#: factorisation and solve of a channel-3d Stokes system: 0.13 / 16.0 s at 9 043 / 64 547
#: unknowns (idle machine; 0.35 / 42.7 s in COLAMD's order beside another job).
SOLVE_COST = {
    (2, "superlu"): (9.5e-6, 45_570, 0.5),
    (2, "pardiso"): (3.5e-6, 45_570, 0.2),
    (2, "multigrid"): (7.0e-6, 45_570, 0.0),
    (2, "multigrid-tight"): (8.0e-5, 17_106, 0.0),
    (3, "superlu"): (2.5e-4, 64_547, 1.45),
    (3, "pardiso"): (1.6e-5, 64_547, 0.5),
    (3, "multigrid"): (1.2e-5, 278_739, 0.0),
    (3, "multigrid-tight"): (4.0e-5, 278_739, 0.0),
}
#: (dim, engine) -> (c, n_ref, p) of one more right-hand side solved with a direct factorisation
#: (forward and back substitution), the same form. Measured with SuperLU, 90 right-hand sides at
#: once after one factorisation: sedimentation-2d level 1 (35 682 unknowns) 0.72 s against 0.90 s
#: for the factorisation, glowinski-free-fall level 2 (17 106) 0.22 s against 0.25 s,
#: sedimentation-3d level 1 (32 707) 1.46 s against 8.4 s. PARDISO's substitutions are taken to
#: cost SuperLU's (both are triangular solves with the fill of a nested-dissection order; not
#: measured).
SUBSTITUTION_COST = {
    (2, "superlu"): (2.3e-7, 35_682, 0.5),
    (2, "pardiso"): (2.3e-7, 35_682, 0.5),
    (3, "superlu"): (5.0e-7, 32_707, 1.0 / 3.0),
    (3, "pardiso"): (5.0e-7, 32_707, 1.0 / 3.0),
}
#: Newton solves in a time step of a coupled run, for :func:`cheapest_solver`: two or three flow
#: solves of two or three Newton steps each (measured: sedimentation-2d level 1 with 30 disks,
#: 127 Newton iterations in 20 steps)
NEWTON_SOLVES_PER_STEP = 6
#: multigrid solves asked for a relative residual below this count as tight
TIGHT_RTOL = 1e-3


def solve_time(engine: str, dim: int, n_unknowns: int, rtol: float | None = None) -> float:
    """Modelled seconds per linear solve (:data:`SOLVE_COST`): ``engine`` ``"superlu"``,
    ``"pardiso"`` or ``"multigrid"`` (``rtol``: the relative residual asked of it; None: tight)."""
    key = engine
    if engine == "multigrid" and (rtol is None or rtol < TIGHT_RTOL):
        key = "multigrid-tight"
    c, n_ref, p = SOLVE_COST[(dim, key)]
    return c * n_unknowns * (n_unknowns / n_ref) ** p


def substitution_time(engine: str, dim: int, n_unknowns: int) -> float:
    """Modelled seconds of one more right-hand side with a direct factorisation
    (:data:`SUBSTITUTION_COST`)."""
    c, n_ref, p = SUBSTITUTION_COST[(dim, engine)]
    return c * n_unknowns * (n_unknowns / n_ref) ** p


def cheapest_solver(dim: int, n_unknowns: int, rtol: float | None, pardiso: bool,
                    fits: Callable[[str], bool] = lambda solver: True, responses: int = 0) -> str:
    """``"direct"`` or ``"multigrid"``, whichever costs less per time step of
    :data:`NEWTON_SOLVES_PER_STEP` Newton solves (:func:`solve_time`) and ``responses`` more
    right-hand sides with the last of them (:func:`substitution_time` for the direct solver, a
    solve each for multigrid), the direct solver being PARDISO when ``pardiso``, else SuperLU;
    among those for which ``fits(name)`` (``"direct"`` / ``"multigrid"``: its memory fits the
    machine); multigrid when neither fits (it needs the least)."""
    engine = "pardiso" if pardiso else "superlu"
    direct_cost = (NEWTON_SOLVES_PER_STEP * solve_time(engine, dim, n_unknowns)
                   + responses * substitution_time(engine, dim, n_unknowns))
    multigrid_cost = (NEWTON_SOLVES_PER_STEP + responses) * solve_time("multigrid", dim, n_unknowns, rtol)
    if direct_cost <= multigrid_cost and fits("direct"):
        return "direct"
    return "multigrid"


def switch_point(dim: int, rtol: float | None, pardiso: bool, responses: int = 0) -> int | None:
    """The number of unknowns from which :func:`cheapest_solver` takes multigrid (memory aside),
    rounded to three significant digits; None when it takes the direct solver up to 10^9. (The
    documentation's table of ``solver.linear = "auto"`` is generated from it.)"""
    def multigrid(n: float) -> bool:
        return cheapest_solver(dim, int(n), rtol, pardiso, responses=responses) == "multigrid"

    lo, hi = 1.0e2, 1.0e9
    if not multigrid(hi):
        return None
    if multigrid(lo):
        return int(lo)
    while hi / lo > 1.0 + 1e-4:
        mid = (lo * hi) ** 0.5
        lo, hi = (lo, mid) if multigrid(mid) else (mid, hi)
    return int(float(f"{hi:.3g}"))


def choose_linear_solver(dim: int, n_unknowns: int, rtol: float | None = 1e-8, linear: str = "auto",
                         multigrid: MultigridSettings | None = None, responses: int = 0) -> LinearSolver:
    """The linear solver of a run: ``linear`` ``"direct"`` (:class:`~fbmflow.solvers.direct.DirectSolver`,
    PARDISO or SuperLU by :func:`~fbmflow.solvers.direct.auto_backend`), ``"multigrid"``
    (:class:`~fbmflow.solvers.multigrid.MultigridSolver` with ``multigrid``'s settings and ``rtol`` as its
    default target) or ``"auto"``: the cheaper of the two (:func:`cheapest_solver`, with the
    ``responses`` a coupled step solves besides its Newton steps) among those whose memory
    estimate fits the machine (:func:`estimate_memory`, :func:`available_memory`)."""
    if linear == "auto":
        have = available_memory()

        def fits(name: str) -> bool:
            return have is None or estimate_memory(n_unknowns, dim, name)[0] <= have

        linear = cheapest_solver(dim, n_unknowns, rtol, direct.pardiso_available(), fits, responses)
    if linear == "direct":
        return DirectSolver()
    if linear == "multigrid":
        return MultigridSolver(multigrid or MultigridSettings(), rtol=rtol if rtol is not None else 1e-8)
    raise ValueError(f"unknown linear solver {linear!r}; choose 'auto', 'direct' or 'multigrid'")


class InsufficientMemory(ParamError):
    """A run whose linear solver would need more memory than the machine has available."""


#: peak resident memory of a run by (dimension, engine): ``(c, n_ref, e)``, the memory per unknown
#: ``c`` [bytes] at ``n_ref`` unknowns, growing as ``(n / n_ref)^e`` (a factorisation fills more
#: than linearly: nested dissection ``O(n^(4/3))`` in 3D, ``O(n log n)`` in 2D; multigrid is
#: linear). Fitted, with a margin, to peak resident sets of whole runs measured on x86-64 Linux:
#: ten-cate 64 547 / 278 739 unknowns PARDISO 2.0 / 10.3 GB (benchmarks/results/tencate_solvers.md),
#: multigrid 278 739 / 2 012 403 unknowns 1.44 / 8.9 GB (three and two steps), channel-3d level 4
#: (486 979 unknowns, steady, Newton hierarchy) 3.4 GB (benchmarks/results/solver_table.md);
#: sedimentation-3d 32 707 unknowns PARDISO 1.22 GB, SuperLU 0.91 GB; glowinski-free-fall
#: 17 106 / 52 818 / 164 946 unknowns PARDISO or SuperLU 0.33 / 0.55 / 1.30 GB, multigrid 0.81 GB
#: at 164 946.
MEMORY_MODEL = {(2, "pardiso"): (6_500, 165_000, 0.1), (2, "superlu"): (7_600, 165_000, 0.25),
                (2, "multigrid"): (3_500, 165_000, 0.0), (3, "pardiso"): (40_000, 280_000, 0.15),
                (3, "superlu"): (30_000, 33_000, 0.5), (3, "multigrid"): (6_500, 280_000, 0.0)}
#: the same for the time steps of particle scenes where they need less (multigrid's Picard
#: hierarchy: the scalar velocity operator stored once,
#: :class:`~fbmflow.fem.velocity_block.VelocityBlock`, instead of the coupled Newton block; the
#: continuity rows as the level's divergence and the rows that differ,
#: :class:`~fbmflow.fem.continuity_block.ContinuityBlock`); fitted to ten-cate levels 1 / 2 / 3
#: (278 739 / 2 012 403 / 15 789 027 unknowns): 0.65-0.73 / 2.67 / 19.60 GB (one step of levels
#: 1 and 2, ``python -m fbmbench memory_model``, benchmarks/results/memory_model.md, and three of
#: level 1, ``thread_scaling``; one step of level 3, ``python -m fbmbench unguarded_steps``;
#: 28462f9 and 114f0e2), 1.02-1.14 times those of levels 1 and 2 and 1.16 times level 3's, which
#: it estimates at 22.8 GB (25.0 before the continuity block); sedimentation-3d with 1 000
#: spheres at level 2 (10 024 003 unknowns, 10.97 GB) gets 1.31 times
TRANSIENT_MODEL = {(3, "multigrid"): (1_320, 2_000_000, 0.035)}
#: what the interpreter, NumPy, SciPy and the compiled kernels take before any mesh [bytes]
MEMORY_BASE = 400e6
#: peak memory per unknown of each response the implicit coupling keeps [bytes]: about ten float64
#: fields (liftings, responses and their forces' work arrays); measured, sedimentation-2d level 2
#: (141 762 unknowns), 100 disks: 5.17 GB implicit against 1.70 GB explicit
#: (benchmarks/results/particle_scaling.md), 3.47 GB over 300 responses
RESPONSE_BYTES = 80
ENGINE_NAMES = {"superlu": "the direct solver (SuperLU)", "pardiso": "the direct solver (PARDISO)",
                "multigrid": "multigrid"}


def estimate_memory(n_unknowns: int, dim: int, solver: LinearSolver | str,
                    transient: bool = False) -> tuple[float, str]:
    """Rough, conservative peak memory of a run: ``(bytes, the solver in words)``.

    ``solver``: a :class:`~fbmflow.solvers.base.LinearSolver`, an engine (``"superlu"``,
    ``"pardiso"``, ``"multigrid"``) or ``"direct"`` (the backend the direct solver would take
    here). The estimate is ``MEMORY_BASE + n c (n / n_ref)^e`` with ``(c, n_ref, e)`` from
    :data:`TRANSIENT_MODEL` for the time steps of a particle scene (``transient``) where it has
    the engine, else from :data:`MEMORY_MODEL`; it is meant to tell a run that fits from one that
    cannot, not to predict the figure to better than a few tens of per cent.
    """
    if isinstance(solver, LinearSolver):
        engine = solver.engine(dim, n_unknowns)
    else:
        engine = direct.auto_backend(dim, n_unknowns) if solver == "direct" else solver
    model = TRANSIENT_MODEL if transient and (dim, engine) in TRANSIENT_MODEL else MEMORY_MODEL
    c, n_ref, growth = model[(dim, engine)]
    return MEMORY_BASE + n_unknowns * c * (n_unknowns / n_ref) ** growth, ENGINE_NAMES[engine]


def available_memory(meminfo="/proc/meminfo") -> float | None:
    """Memory a run may still take [bytes]: the least of ``MemAvailable`` of ``meminfo`` (Linux),
    what is left of the process's address-space limit (``ulimit -v``, what batch schedulers set:
    :func:`address_space_left`) and of its cgroup's memory limit (containers, Slurm:
    :func:`cgroup_left`); None where none can be read (no check is made then)."""
    found = []
    try:
        for line in Path(meminfo).read_text().splitlines():
            if line.startswith("MemAvailable:"):
                found.append(float(line.split()[1]) * 1024.0)
                break
    except (OSError, ValueError, IndexError):
        pass
    for left in (address_space_left(), cgroup_left()):
        if left is not None:
            found.append(left)
    return min(found) if found else None


def peak_resident_memory() -> float | None:
    """The process's peak resident memory so far [bytes] (``ru_maxrss``: kilobytes on Linux,
    bytes on macOS); None where the platform does not report it (Windows)."""
    try:
        import resource

        peak = float(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
    except (ImportError, OSError, ValueError):
        return None
    return peak if sys.platform == "darwin" else peak * 1024.0


def address_space_left(status="/proc/self/status") -> float | None:
    """The soft ``RLIMIT_AS`` less the process's address space now (``VmSize``) [bytes]; None
    without a limit (or where it cannot be read)."""
    try:
        import resource

        soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    except (ImportError, OSError, ValueError):
        return None
    if soft == resource.RLIM_INFINITY or soft < 0:
        return None
    used = 0.0
    try:
        for line in Path(status).read_text().splitlines():
            if line.startswith("VmSize:"):
                used = float(line.split()[1]) * 1024.0
    except (OSError, ValueError, IndexError):
        pass
    return max(float(soft) - used, 0.0)


def cgroup_left(root="/sys/fs/cgroup") -> float | None:
    """The memory limit of the process's cgroup less its usage [bytes] (cgroup v2 ``memory.max``
    and ``memory.current``, or v1 ``memory.limit_in_bytes`` and ``memory.usage_in_bytes``); None
    without a limit."""
    for limit_name, usage_name in (("memory.max", "memory.current"),
                                   ("memory/memory.limit_in_bytes", "memory/memory.usage_in_bytes")):
        try:
            limit = Path(root, limit_name).read_text().strip()
            if limit == "max" or float(limit) >= 2.0**60:  # no limit (v1 writes a huge number)
                return None
            usage = float(Path(root, usage_name).read_text().strip())
            return max(float(limit) - usage, 0.0)
        except (OSError, ValueError):
            continue
    return None


def check_memory(n_unknowns: int, dim: int, solver: LinearSolver | str, responses: int = 0,
                 transient: bool = False, warn: bool = True) -> float:
    """Refuse (:class:`InsufficientMemory`) a run whose :func:`estimate_memory` (``transient``:
    a particle scene's time steps) plus the
    ``responses`` flow fields an implicit coupling keeps (:data:`RESPONSE_BYTES` per unknown
    each) exceeds the available memory, warn (unless not ``warn``: an early check that the run's
    own check repeats) when it exceeds half of it; returns the estimate
    [bytes]. Called before the first solve, so that a run too large for the machine stops with
    the figure and a remedy instead of a MemoryError, or the kernel's out-of-memory killer, in the
    factorisation or the responses."""
    need, words = estimate_memory(n_unknowns, dim, solver, transient)
    have = available_memory()
    if have is None:
        return need
    figure = f"{words} needs about {need / 1e9:.1f} GB for {n_unknowns} unknowns ({dim}D)"
    stored = RESPONSE_BYTES * n_unknowns * responses
    if stored and need <= have < need + stored:
        raise InsufficientMemory(
            f"the implicit coupling's responses to {responses} rigid-body velocity components need about "
            f"{stored / 1e9:.1f} GB for {n_unknowns} unknowns, and {words} {need / 1e9:.1f} GB: more "
            f"than the {have / 1e9:.1f} GB available; use fewer particles, a coarser mesh (a lower --level) "
            "or coupling.scheme = stabilised (one flow solve per step, no responses kept) or newton-krylov "
            "(the same, with a few linear responses per step; for dense suspensions)")
    need += stored
    if need > have:
        remedy = "a coarser mesh (a lower --level)"
        if words != "multigrid":
            mg, _ = estimate_memory(n_unknowns, dim, "multigrid", transient)
            remedy += f" or solver.linear = multigrid (about {mg / 1e9:.1f} GB)"
        raise InsufficientMemory(f"{figure}, more than the {have / 1e9:.1f} GB available; use {remedy}")
    if warn and need > 0.5 * have:
        log.warning("%s, more than half of the %.1f GB available", figure, have / 1e9)
    return need
