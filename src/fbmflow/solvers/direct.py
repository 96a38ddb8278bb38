"""The direct linear solver: a sparse LU of the saddle-point matrix, by SuperLU (SciPy, always
there) or Intel MKL PARDISO (the optional ``pardiso`` extra), with the constrained velocities
eliminated and, for PARDISO, the symbolic analysis kept between factorisations."""
from __future__ import annotations

import logging
import time

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from . import _kernels, mkl
from .base import Factorization, LinearSolver
from .krylov import fgmres
from .ordering import lattice_points, nested_dissection
from .reports import LinearReport
from .system import SaddlePointSystem, expansion

log = logging.getLogger(__name__)


DIRECT_BACKENDS = ("auto", "superlu", "pardiso")
BACKEND_NAMES = {"superlu": "SuperLU", "pardiso": "PARDISO"}  # for reports
#: 2D systems from this many unknowns go to PARDISO under ``backend="auto"`` (when installed).
#: glowinski-free-fall, six steps alternating in one process: 17 000 unknowns 2.6 s PARDISO
#: against 1.5 s SuperLU; 53 000: 11.0-11.4 against 14.3-14.4 s; 165 000: 31-37 against 90-99 s.
PARDISO_MIN_UNKNOWNS_2D = 40_000
# PARDISO settings (1-based keys): own parameters, METIS ordering, no internal refinement (ours
# is cheaper: MKL's 2 steps made every solve 4x slower), pivot perturbation 1e-13, scaling, no
# weighted matching (with it, MKL's default for unsymmetric matrices, the Jacobians of 3D
# periodic suspensions had perturbed pivots, refinement stalled and solves ended in FGMRES; other
# scenes solve the same, as fast or faster: docs/validation/); shift of the zero diagonal
# (relative)
PARDISO_IPARM = {1: 1, 2: 2, 8: 0, 10: 13, 11: 1, 13: 0}
REGULARISE = 1e-12
ROUNDOFF = 1e2 * np.finfo(float).eps  # attainable relative accuracy of a residual K x - b


def pardiso_available() -> bool:
    """True when the optional PARDISO backend (``pip install fbmflow[pardiso]``: MKL's runtime) is
    installed."""
    return mkl.available()


def auto_backend(dim: int, n_unknowns: int) -> str:
    """The direct backend ``"auto"`` stands for: ``"pardiso"`` when it is installed and the system
    is 3D (where SuperLU's ordering fills too much) or a 2D one of at least
    :data:`PARDISO_MIN_UNKNOWNS_2D` unknowns; else ``"superlu"``."""
    large = dim == 3 or n_unknowns >= PARDISO_MIN_UNKNOWNS_2D
    return "pardiso" if large and pardiso_available() else "superlu"


def factorize(system: SaddlePointSystem, backend: str = "auto", analysis: "PardisoAnalysis | None" = None,
              rtol: float = 1e-12):
    """Sparse LU of the saddle-point matrix with the constrained velocity DOFs eliminated; returns
    ``solve(f, g) -> (u, p)``.

    ``backend``: ``"superlu"`` (SciPy; always there; COLAMD's ordering in 2D, a geometric nested
    dissection of the mesh in 3D, :func:`~fbmflow.solvers.ordering.nested_dissection`),
    ``"pardiso"`` (Intel MKL PARDISO, the optional ``pardiso`` extra, :mod:`~fbmflow.solvers.mkl`:
    nested-dissection ordering, two threads; in 3D it factorises 200 000 unknowns in about 30 s) or ``"auto"``
    (:func:`auto_backend`: PARDISO for 3D and large 2D systems when installed, else SuperLU).

    ``analysis``: with PARDISO, factorise with this :class:`PardisoAnalysis`, which keeps the
    symbolic analysis between factorisations. Only the constrained DOFs in
    ``system.fixed_always`` are then eliminated; the others (a particle's) stay in the matrix as
    unit rows, so that the pattern does not change as they come and go.

    ``rtol``: with PARDISO, the relative residual to which each solve is refined
    (``_pardiso``); ``solve(f, g, rtol)`` asks for another one. SuperLU's solves are not
    refined.

    When the pressure is determined only up to a constant (``mean_weights`` given), the constant
    mode of one cell is pinned to zero instead of bordering the matrix with the dense row
    ``mean_weights``: the dense row would fill the LU factors completely (measured: 76 M non-zeros
    instead of a few M for 33 000 unknowns). The mean is removed afterwards, which gives the
    bordered system's solution for compatible data; the continuity right-hand side is made
    compatible first (:meth:`~fbmflow.solvers.system.SaddlePointSystem.balance`), which gives the bordered
    system's
    solution for any data.
    """
    if backend not in DIRECT_BACKENDS:
        raise ValueError(f"unknown direct backend {backend!r}; choose one of {DIRECT_BACKENDS}")
    if backend == "auto":
        backend = auto_backend(system.space.dim if system.space is not None else 2, system.n_u + system.n_p)
    if backend != "pardiso":
        analysis = None
    K = system.matrix(bordered=False)
    n = K.shape[0]
    eliminated = system.fixed
    if analysis is not None and system.fixed is not None and system.fixed_always is not None:
        eliminated = np.intersect1d(system.fixed, system.fixed_always)
    free = np.ones(n, dtype=bool)
    if eliminated is not None:
        free[eliminated] = False
    pinned = _pinned_pressure(system)
    if pinned is not None:
        pinned += system.n_u
    if pinned is not None:
        free[pinned] = False
    K_free = K[free]
    coupling = K_free[:, ~free]
    if backend == "pardiso":
        reserve = None
        if analysis is not None:
            npl = system.space.dim + 1 if system.space is not None else 1
            reserve = lambda: _pressure_cell_pattern(system.n_u, system.n_p, npl, free)  # noqa: E731
        lu_solve = _pardiso(K_free[:, free], rtol=rtol, analysis=analysis, reserve=reserve)
    else:  # in 3D, COLAMD's order fills several times more than a nested dissection
        order = None
        if system.space is not None and system.space.dim == 3:
            order = nested_dissection(lattice_points(system.space)[free])
        superlu = _superlu(K_free[:, free], order)
        lu_solve = lambda b, tol=None: superlu(b)  # noqa: E731

    border = None
    if pinned is not None and (system.rows is not None or system.extension is not None):
        # the left null vector is no longer [0, 1 - C 1] (the continuity rows are not the gradient's
        # transpose), so balancing alone leaves the pinned row unmet: solve the bordered system
        # K x + lambda [0, w] = b exactly instead, with the response to the border column
        column = np.zeros(n)
        column[system.n_u:] = expansion(system.mean_weights, system.orphans, system.extension)
        response = np.zeros(n)
        response[free] = lu_solve(column[free], None)
        row = K[pinned]
        border = (column, response, row, float(column[pinned] - (row @ response)[0]))

    def solve(f, g, rtol=None):  # (n_u,), (n_p,) or, for k right-hand sides at once, (n_u, k), (n_p, k)
        x = np.concatenate([f, system.balance(g)])
        if border is not None:
            column, response, row, pivot = border
            b_pinned = x[pinned].copy()
        if pinned is not None:
            x[pinned] = 0.0
        x[free] = lu_solve(x[free] - coupling @ x[~free], rtol)
        if border is not None:  # lambda from the pinned row, then x - lambda (response to the border)
            lam = (b_pinned - np.asarray(row @ x).reshape(x.shape[1:])) / pivot
            x -= np.multiply.outer(response, lam)
        if not np.all(np.isfinite(x)):
            raise np.linalg.LinAlgError("direct solve produced non-finite values (singular system?)")
        system.remove_pressure_mean(x)
        return x[:system.n_u], x[system.n_u:]

    return solve


def _pressure_cell_pattern(n_u: int, n_p: int, npl: int, free: np.ndarray) -> sp.csr_matrix:
    """Every cell's ``npl x npl`` pressure block (ones) among the unknowns ``free`` (n,) bool of
    the saddle-point system, numbered as in the system reduced to them: where orphaned pressure
    modes of single cells put their entries."""
    position = np.cumsum(free) - 1
    first = n_u + np.arange(n_p // npl) * npl
    rows, cols = [], []
    for a in range(npl):
        for b in range(npl):
            keep = free[first + a] & free[first + b]
            rows.append(position[first[keep] + a])
            cols.append(position[first[keep] + b])
    rows = np.concatenate(rows)
    m = int(free.sum())
    return sp.csr_matrix((np.ones(rows.size), (rows, np.concatenate(cols))), shape=(m, m))


def _superlu(K: sp.spmatrix, order: np.ndarray | None = None):
    """SuperLU with threshold pivoting 0.01 (so that the ordering survives), eliminating in the
    fill-reducing ``order`` (a permutation of the unknowns) where given, else in COLAMD's."""
    if order is None:
        return spla.splu(K.tocsc(), permc_spec="COLAMD", diag_pivot_thresh=0.01).solve
    lu = spla.splu(sp.csr_matrix(K)[order][:, order].tocsc(), permc_spec="NATURAL", diag_pivot_thresh=0.01)

    def solve(b):
        x = np.empty_like(b)
        x[order] = lu.solve(b[order])
        return x

    return solve


def _ones(P: sp.csr_matrix) -> sp.csr_matrix:
    """The pattern of ``P`` (explicit zeros included) with all entries one."""
    return sp.csr_matrix((np.ones(P.nnz), P.indices, P.indptr), shape=P.shape)


class PardisoAnalysis:
    """PARDISO factorisations that share one symbolic analysis while their pattern allows.

    PARDISO's analysis (phase 11: nested-dissection ordering, symbolic factorisation and
    scaling) is about 40 % of a factorisation of the ten-cate Jacobians (level 0,
    54 468 unknowns, 8.7 M non-zeros: analysis and factorisation 2.8 s, factorisation alone
    1.5-1.7 s). A matrix whose entries all lie in the *reserved pattern* of the last analysis is
    only factorised numerically (phase 22) with that analysis. The reserved pattern is the union
    of the analysed matrix, the pattern reserved before (same size) and the caller's ``reserve``
    (the cells' pressure blocks, where orphaned pressure modes come and go).

    The scaling and matching stay those of the analysed values. Measured, that did not cost
    refinement steps: 0-2 against 0-1 at ten-cate level 0, 2-4 against 2-4 at level 1. A first
    solve that needs more than ``REUSE_REFINEMENTS`` steps, or FGMRES (refinement no longer
    halves the error), marks the analysis stale, and the next factorisation analyses again; a
    solve that fails with a reused analysis is repeated after a fresh one.

    One factorisation is live at a time: the next one overwrites its factors, and a solve
    function of an older one then factorises its own matrix again (in a private analysis).
    """

    def __init__(self):
        self._handle: mkl.Pardiso | None = None  # the live MKL handle; freed with this object
        self._pattern: sp.csr_matrix | None = None
        self._ia = self._ja = None  # its indptr and indices, 1-based int32 (MKL's CSR)
        self._diagonal: np.ndarray | None = None  # positions of the diagonal in the pattern
        self.stale = False
        self.generation = 0  # factorisations made so far
        self.analyses = 0    # of which with a new analysis

    def factor(self, K: sp.csr_matrix, reserve=None) -> tuple[sp.csr_matrix, bool]:
        """Factorise ``K`` (CSR, sorted indices) with its zero diagonal entries (the pressure
        block) shifted by ``-REGULARISE max|diag K|`` (see ``_pardiso``). ``reserve``:
        callable returning a CSR pattern to reserve as well, called only for a new analysis.
        Returns the factorised matrix (``K`` shifted, in the reserved pattern) and whether the
        analysis was reused."""
        M = None
        if not self.stale and self._pattern is not None and self._pattern.shape == K.shape:
            data = np.empty(self._pattern.nnz)
            if _kernels.scatter_into_pattern(K.indptr, K.indices, K.data, self._pattern.indptr,
                                             self._pattern.indices, data):
                M = self._shifted(data)
            else:
                log.debug("PARDISO: the matrix leaves the reserved pattern; analysing again")
        reused = M is not None
        if reused:
            self._factorise(22, M)
        else:
            t0 = time.perf_counter()
            P = _ones(K) + sp.identity(K.shape[0], format="csr")
            if self._pattern is not None and self._pattern.shape == K.shape:
                P = P + _ones(self._pattern)
            if reserve is not None:
                P = P + _ones(sp.csr_matrix(reserve()))
            P = P.tocsr()
            P.sort_indices()
            self._pattern = P
            self._ia, self._ja = P.indptr.astype(np.int32) + 1, P.indices.astype(np.int32) + 1
            rows = np.repeat(np.arange(P.shape[0]), np.diff(P.indptr))
            self._diagonal = np.flatnonzero(P.indices == rows)
            data = np.empty(P.nnz)
            _kernels.scatter_into_pattern(K.indptr, K.indices, K.data, P.indptr, P.indices, data)
            M = self._shifted(data)
            self.release()
            self._handle = mkl.Pardiso(PARDISO_IPARM)
            t1 = time.perf_counter()
            self._factorise(12, M)
            log.debug("PARDISO analysis: pattern %.1f s, analysis and factorisation %.1f s",
                      t1 - t0, time.perf_counter() - t1)
            self.analyses += 1
            self.stale = False
        self.generation += 1
        return M, reused

    def solve(self, M: sp.csr_matrix, B: np.ndarray) -> np.ndarray:
        """``M^-1 B`` (B (n,) or (n, k)) with the live factors (``M`` as returned by
        :meth:`factor`)."""
        return self._call(33, M, B.reshape(B.shape[0], -1)).reshape(B.shape)

    def _factorise(self, phase: int, M: sp.csr_matrix) -> None:
        """Phase 12 (analysis and factorisation) or 22 (factorisation with the stored analysis)."""
        self._call(phase, M, np.zeros((M.shape[0], 1)))

    def _call(self, phase: int, M: sp.csr_matrix, B: np.ndarray) -> np.ndarray:
        """One call of MKL's ``pardiso`` with the live handle (:class:`~fbmflow.solvers.mkl.Pardiso`),
        ``M`` in the reserved pattern (its 1-based indices converted once per analysis) and
        ``B (n, k)``. A wrapper that converted the indices and compared the whole matrix with a
        stored copy on every solve (pypardiso, which this replaced) cost 16 of 188 s over three
        ten-cate level-1 steps; ``tests/solvers/test_direct.py`` checks the results against
        SuperLU."""
        return self._handle.call(phase, M.data, self._ia, self._ja, B)

    def release(self) -> None:
        """Free the factors (MKL memory)."""
        if self._handle is not None:
            self._handle.release()
            self._handle = None

    def forget(self) -> None:
        """Free the factors and drop the analysis: the next factorisation analyses afresh (what a
        run resumed from a checkpoint does, so that both repeat the same iterations)."""
        self.release()
        self._pattern = self._diagonal = self._ia = self._ja = None
        self.stale = False

    def _shifted(self, data: np.ndarray) -> sp.csr_matrix:
        d = data[self._diagonal]
        data[self._diagonal] = np.where(d == 0.0, -REGULARISE * np.abs(d).max(), d)
        return sp.csr_matrix((data, self._pattern.indices, self._pattern.indptr), shape=self._pattern.shape)


# refinement steps of a first solve above which a reused analysis is stale (measured at ten-cate
# level 1: 2-4 steps with fresh and with reused analyses alike)
REUSE_REFINEMENTS = 6


def _pardiso(K: sp.spmatrix, rtol: float = 1e-12, max_refinements: int = 10, accept: float = 1e-8,
             analysis: PardisoAnalysis | None = None, reserve=None):
    """MKL PARDISO (real unsymmetric, METIS ordering, scaling, no weighted matching) of ``K``
    with its zero diagonal entries (the pressure block) shifted by ``-1e-12 max|diag K|``: on the
    unshifted saddle point PARDISO perturbs tiny pivots (5-18 of them in the 3D FBM Jacobians
    measured), after which refinement converges slowly or not at all (first-solve residuals from
    1e-4 to 1e5); a shift of 1e-8 perturbs the whole pressure block so much that refinement
    stalls near 1e-9 and FGMRES needed up to 60 iterations per solve (ten-cate, level 0). With
    1e-12 the first solve is accurate to 1e-10..1e-8 and one refinement step reaches 1e-13.

    Each solve is refined against the true ``K`` (iterative refinement, then FGMRES
    preconditioned by the factors where that stalls) to ``|b - K x| <= rtol |b|`` (``rtol``: the
    ``tol`` of ``solve(b, tol)``, else this function's), or to the round-off floor
    ``ROUNDOFF | |K| |x| + |b| |`` (entrywise absolute values) where that is larger: when ``b``
    is a nearly converged Newton residual, ``rtol |b|`` lies below the rounding error of ``K x``
    itself, and FGMRES then ran 60 useless iterations per solve. Only if the residual ends above
    ``max(accept, rtol)`` (same measure) is ``K`` factorised again, after a fresh analysis if
    ``analysis`` (a :class:`PardisoAnalysis`, else a private one) was reused, then with SuperLU,
    with a warning."""
    A = sp.csr_matrix(K)
    A.sort_indices()
    live = {"analysis": analysis if analysis is not None else PardisoAnalysis()}

    def factor():
        M, reused = live["analysis"].factor(A, reserve)
        live.update(M=M, reused=reused, generation=live["analysis"].generation, first=True)

    factor()
    fallback = []

    def lu(B):  # the factors' solve; refactorise privately when a later factorisation took them
        if live["analysis"].generation != live["generation"]:
            log.debug("PARDISO factors superseded by a later factorisation; factorising again")
            live["analysis"] = PardisoAnalysis()
            factor()
        return live["analysis"].solve(live["M"], B).reshape(B.shape)

    abs_A = abs(A)

    # per column (k,): |B - A X| over the larger of |B| and its round-off floor / tol; and B - A X
    def error(B, X, tol):
        R = B - A @ X
        floor = ROUNDOFF * np.linalg.norm(abs_A @ abs(X) + abs(B), axis=0) / tol
        return np.linalg.norm(R, axis=0) / np.maximum(np.maximum(np.linalg.norm(B, axis=0), floor), 1e-300), R

    def refined(B, tol):  # X, its error per column, refinement steps, whether FGMRES was needed
        X = lu(B)
        err, R = error(B, X, tol)
        previous, steps = np.inf, 0
        for steps in range(max_refinements + 1):
            size = np.max(err)
            if size <= tol or size > 0.5 * previous or steps == max_refinements:
                break
            previous = size
            X += lu(R)
            err, R = error(B, X, tol)
        stalled = np.flatnonzero(err > tol)
        for c in stalled:  # refinement stalled: FGMRES
            r0 = np.linalg.norm(R[:, c])
            target = tol * r0 / err[c]
            X[:, c] = fgmres(lambda v: A @ v, lambda r: lu(r[:, None])[:, 0], B[:, c], X[:, c].copy(),
                             target / r0, 60, 30)[0]
            err[c] = error(B[:, c:c + 1], X[:, c:c + 1], tol)[0][0]
        return X, np.max(err), steps, stalled.size > 0

    def solve(b, tol=None):  # tol: this solve's refinement target instead of rtol
        b = np.asarray(b, dtype=float)
        if fallback:
            return fallback[0](b)
        tol = rtol if tol is None else tol
        accepted = max(accept, tol)
        B = b.reshape(b.shape[0], -1)
        X, size, steps, stalled = refined(B, tol)
        log.debug("PARDISO solve: %d refinement steps%s (%s analysis)", steps, ", FGMRES" if stalled else "",
                  "reused" if live["reused"] else "fresh")
        if live["reused"] and live["first"] and (steps > REUSE_REFINEMENTS or stalled):
            log.debug("PARDISO: %d refinement steps%s with a reused analysis; the next factorisation "
                      "analyses again", steps, " and FGMRES" if stalled else "")
            live["analysis"].stale = True
        live["first"] = False
        if size > accepted and live["reused"]:
            log.info("PARDISO solve with a reused analysis inaccurate (relative residual %.1e); "
                     "analysing again", size)
            live["analysis"].stale = True
            factor()
            X, size, _, _ = refined(B, tol)
        if size > accepted:
            log.warning("PARDISO solve inaccurate (relative residual %.1e); factorising with SuperLU instead",
                        size)
            fallback.append(_superlu(A))
            return fallback[0](b)
        return X.reshape(b.shape)

    return solve


def _pinned_pressure(system: SaddlePointSystem) -> int | None:
    """Pressure DOF (constant mode of a cell) to pin when the pressure is fixed by its mean only
    (None otherwise): the first cell that no orphaned mode touches, else cell 0 (the constant
    pressure, the one null mode left, has a component on every cell)."""
    if system.mean_weights is None:
        return None
    npl = system.space.dim + 1 if system.space is not None else 1
    if system.orphans is None and system.extension is None:
        return 0
    touched = np.zeros(system.n_p // npl, dtype=bool)
    if system.orphans is not None:
        touched[system.orphans.tocoo().row // npl] = True
    if system.extension is not None:
        touched[system.extension.dofs // npl] = True
    return int(np.flatnonzero(~touched)[0]) * npl if not touched.all() else 0


class DirectFactorization(Factorization):
    """A sparse LU of one saddle-point system (:func:`factorize`); solves one or several
    right-hand sides at once."""

    multiple_rhs = True

    def __init__(self, solve, setup_time_s: float, name: str):
        super().__init__(setup_time_s)
        self._solve = solve
        self.name = name

    def solve(self, f, g, rtol=None):
        """``rtol``: PARDISO's refinement target for this solve (None: the solver's); SuperLU's
        solves are exact to round-off."""
        t1 = time.perf_counter()
        u, p = self._solve(f, g, rtol)
        setup = self._charge_setup()
        return u, p, LinearReport(self.name, setup + time.perf_counter() - t1, iterations=1,
                                  setup_time_s=setup)


class DirectSolver(LinearSolver):
    """Sparse LU of the saddle-point matrix with the constrained velocity DOFs eliminated
    (:func:`factorize`; ``backend`` ``"auto"``, ``"superlu"`` or ``"pardiso"``); for small and
    medium problems (2D: up to a few 10^5 unknowns; 3D: a few 10^4 with SuperLU, a few 10^5 with
    PARDISO). ``rtol``: PARDISO's solves are refined to this relative residual."""

    name = "direct"

    def __init__(self, backend: str = "auto", rtol: float = 1e-12):
        if backend not in DIRECT_BACKENDS:
            raise ValueError(f"unknown direct backend {backend!r}; choose one of {DIRECT_BACKENDS}")
        if not 0.0 < rtol < 1.0:
            raise ValueError(f"rtol (PARDISO's refinement target per solve) must lie in (0, 1), got {rtol}")
        self.rtol = rtol
        if backend == "pardiso" and not pardiso_available():
            raise ValueError("the PARDISO backend needs MKL's runtime: pip install 'fbmflow[pardiso]'")
        self.backend = backend
        self.analysis = PardisoAnalysis()  # kept between PARDISO factorisations; unused by SuperLU

    def engine(self, dim: int, n_unknowns: int) -> str:
        """``"pardiso"`` or ``"superlu"``: the backend, ``"auto"`` resolved (:func:`auto_backend`)."""
        return auto_backend(dim, n_unknowns) if self.backend == "auto" else self.backend

    def describe(self, dim: int, n_unknowns: int) -> str:
        return f"{self.name} ({BACKEND_NAMES[self.engine(dim, n_unknowns)]})"

    def factor(self, system: SaddlePointSystem) -> DirectFactorization:
        """Factorise ``system``. With PARDISO the factorisation reuses the last one's analysis
        where the pattern allows (:class:`PardisoAnalysis`) and replaces its factors: solve with
        the latest only."""
        t0 = time.perf_counter()
        direct = factorize(system, self.backend, self.analysis, self.rtol)
        return DirectFactorization(direct, time.perf_counter() - t0, self.name)

    def forget(self) -> None:
        """Drop the stored analysis: the next factorisation starts afresh, as after a restart."""
        self.analysis.forget()
