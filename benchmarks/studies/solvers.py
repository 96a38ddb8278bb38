"""Linear solvers for the Q2/P1disc saddle-point systems: multigrid against a sparse direct solve
and a pyamg-based block preconditioner, in one process.

Question: how fast and how mesh-independently does the multigrid solver solve the Q2/P1disc
Stokes and Oseen/Newton saddle-point systems of the lid-driven cavity, against a sparse direct
solve and a pyamg block preconditioner?
Answer: the multigrid cycle counts do not depend on the mesh (2D Stokes 5, 2D Oseen 12, 3D Stokes
7, 3D Oseen 15-16 cycles to 1e-8); 3D Stokes on 32^3 cells (954 947 unknowns) solves in 16.1 s,
2D Stokes on 256^2 in 6.1 s against 13.7 s with pyamg, and the direct solve takes 144 s and 9 GB
already at 128^2 (benchmarks/results/solvers.md).
Measured: 2026-11-21, commit 42093ae; quoted in docs/validation/discretisation-and-solvers.md
Run: python -m fbmbench solvers

For 2D and 3D Stokes and Oseen/Newton systems (lid-driven cavity; the Oseen/Newton systems are
linearised at a recirculating field with the lid's boundary values, Re = 100) of increasing size,
reports the time to a relative residual of 1e-8, the time of one matrix–vector product with the
same system matrix, the solve time in units of that matvec, iterations, and the growth of the
resident memory during the solve (sampled every 5 ms). The pyamg alternative is FGMRES with the
block-diagonal preconditioner ``diag(AMG(A), mu^-1 M_p)`` (smoothed aggregation on the velocity
block, the P1disc pressure mass matrix for the Schur complement): the standard Stokes
preconditioner of FEM codes without geometric multigrid.

Writes ``benchmarks/results/solvers.json`` and ``solvers.md``; ``--profile`` adds a cProfile of
the 3D 32^3 Stokes multigrid solve (``solvers_profile.txt``).
"""
from __future__ import annotations

import cProfile
import io
import json
import pstats
import threading
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from fbmflow.flow import Dirichlet, NavierStokesProblem, NoSlip
from fbmflow.mesh import StructuredMesh
from fbmflow.scenes.cavity import recirculating_state
from fbmflow.solvers import MultigridSettings, MultigridSolver, fgmres
from fbmflow.solvers.direct import factorize

RESULTS = Path(__file__).resolve().parents[1] / "results"


class PeakMemory:
    """Peak growth of the resident set size while the block runs (GB)."""

    def __enter__(self):
        self.base = self._rss()
        self.peak = self.base
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._watch, daemon=True)
        self._thread.start()
        return self

    def _watch(self):
        while not self._stop.wait(0.005):
            self.peak = max(self.peak, self._rss())

    @staticmethod
    def _rss() -> int:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * 4096

    def __exit__(self, *exc):
        self._stop.set()
        self._thread.join()
        self.peak = max(self.peak, self._rss())
        self.gb = (self.peak - self.base) / 1e9


def cavity_system(n: int, dim: int, oseen: bool, mg: MultigridSolver):
    mesh = StructuredMesh.box((n,) * dim)
    bcs = {t: NoSlip() for t in mesh.tags}
    bcs["ymax"] = Dirichlet((1.0,) + (0.0,) * (dim - 1))
    prob = NavierStokesProblem(mesh, 0.01 if oseen else 1.0, bcs, convection=oseen, linear_solver=mg)
    x = recirculating_state(prob) if oseen else prob.zero_state()
    con = prob.constraints()
    F = prob.residual(x, 0.0, 1.0, prob.load(), con)
    system = prob.linear_system(x, 0.0, 1.0, con)
    return prob, system, -F[:system.n_u], -F[system.n_u:]


def pressure_mass_inverse(prob) -> sp.csr_matrix:
    """Block-diagonal inverse of the P1disc mass matrix (exact: P1disc is cell-local)."""
    s = prob.space
    Mloc = np.einsum("cq,cqm,cqn->cmn", s.detJw, s.psi, s.psi)
    return sp.block_diag(list(np.linalg.inv(Mloc)), format="csr")


def solve_pyamg(prob, system, f, g, rtol=1e-8):
    import pyamg

    t0 = time.perf_counter()
    A = system.A.tocsr()
    ml = pyamg.smoothed_aggregation_solver(A, symmetry="hermitian" if not prob.convection else "nonsymmetric",
                                           max_coarse=2000)
    Mp_inv = pressure_mass_inverse(prob) * prob.mu
    n_u = system.n_u

    def precondition(r):
        return np.concatenate([ml.solve(r[:n_u], tol=1e-30, maxiter=1, cycle="V"), Mp_inv @ r[n_u:]])

    b = np.concatenate([f, g])
    x0 = np.zeros_like(b)
    x0[system.fixed] = f[system.fixed]
    project = system.remove_pressure_mean if system.mean_weights is not None else None
    x, res, its = fgmres(system.apply, precondition, b, x0, rtol, 400, 40, project)
    return x, its, time.perf_counter() - t0


def run_case(dim, oseen, n, methods, results, profile=False):
    smoother = "vanka-full" if dim == 2 or oseen else "vanka-diagonal"
    mg = MultigridSolver(MultigridSettings(smoother=smoother, krylov="fgmres"))
    t0 = time.perf_counter()
    prob, system, f, g = cavity_system(n, dim, oseen, mg)
    assemble = time.perf_counter() - t0
    b = np.concatenate([f, g])
    x = np.random.default_rng(0).standard_normal(b.size)
    system.apply(x)
    t0 = time.perf_counter()
    for _ in range(5):
        system.apply(x)
    matvec = (time.perf_counter() - t0) / 5
    label = f"{dim}D {'Oseen/Newton Re=100' if oseen else 'Stokes'}"
    row = dict(case=label, cells=f"{n}^{dim}", n_dofs=system.n_u + system.n_p, assembly_s=assemble,
               matvec_s=matvec, levels=1 + len(prob.coarse), smoother=smoother)

    def record(name, fn):
        with PeakMemory() as mem:
            t = time.perf_counter()
            x, its = fn()
            wall = time.perf_counter() - t
        r = b - system.apply(x)
        rel = float(np.linalg.norm(r) / np.linalg.norm(b))
        row[name] = dict(time_s=wall, iterations=its, matvecs=wall / matvec, memory_gb=mem.gb,
                         rel_residual=rel)
        print(f"  {label:<26} {row['cells']:>6} {row['n_dofs']:>8} {name:<9} {wall:8.2f} s {its:4d} its "
              f"{wall / matvec:7.0f} matvecs {mem.gb:6.2f} GB  rel.res {rel:.1e}", flush=True)

    def run_mg():
        u, p, rep = mg.solve(system, f, g)
        return np.concatenate([u, p]), rep.iterations

    if profile:
        pr = cProfile.Profile()
        pr.enable()
    record("multigrid", run_mg)
    if profile:
        pr.disable()
        out = io.StringIO()
        pstats.Stats(pr, stream=out).sort_stats("tottime").print_stats(15)
        (RESULTS / "solvers_profile.txt").write_text(out.getvalue())
    if "direct" in methods:
        def run_direct():
            u, p = factorize(system)(f, g)
            return np.concatenate([u, p]), 1
        record("direct", run_direct)
    if "pyamg" in methods:
        def run_amg():
            x, its, _ = solve_pyamg(prob, system, f, g)
            return x, its
        record("pyamg", run_amg)
    results.append(row)


def run(*, quick: bool = False, profile: bool = False) -> None:
    """Solve every case of the plan with each method; writes the table.

    Parameters
    ----------
    quick : smaller sizes only
    profile : profile the 3D 32^3 Stokes multigrid solve
    """
    RESULTS.mkdir(exist_ok=True)
    cavity_system(4, 2, True, MultigridSolver())  # JIT warm-up of assembly + Vanka kernels
    for dim in (2, 3):
        for oseen in (False, True):
            mg = MultigridSolver(MultigridSettings(
                smoother="vanka-diagonal" if dim == 3 and not oseen else "vanka-full"))
            _, system, f, g = cavity_system(4, dim, oseen, mg)
            mg.solve(system, f, g)
    plan = {  # (dim, oseen): [(n, methods)]
        (2, False): [(32, "direct pyamg"), (64, "direct pyamg"), (128, "direct pyamg"), (256, "pyamg")],
        (2, True): [(32, "direct pyamg"), (64, "direct pyamg"), (128, "direct pyamg"), (256, "")],
        (3, False): [(8, "direct pyamg"), (16, "pyamg"), (32, "")],
        (3, True): [(8, "direct pyamg"), (16, "pyamg")],
    }
    if quick:
        plan = {k: v[:2] for k, v in plan.items()}
    results = []
    for (dim, oseen), sizes in plan.items():
        for n, methods in sizes:
            run_case(dim, oseen, n, methods.split(), results, profile=profile and dim == 3 and n == 32)
    (RESULTS / "solvers.json").write_text(json.dumps(results, indent=1))
    lines = ["# Saddle-point solvers to 1e-8 relative residual (python -m fbmbench solvers)", "",
             "Times in seconds and in units of one matvec with the same system matrix; memory is the "
             "growth of the resident set during the solve.", "",
             "| case | cells | unknowns | levels | matvec s | multigrid s (its, matvecs, GB) | direct s (GB) "
             "| pyamg s (its, matvecs, GB) |",
             "|---|---|---|---|---|---|---|---|"]
    for r in results:
        def cell(name, full=True):
            if name not in r:
                return "–"
            m = r[name]
            if not full:
                return f"{m['time_s']:.2f} ({m['memory_gb']:.2f})"
            return f"{m['time_s']:.2f} ({m['iterations']}, {m['matvecs']:.0f}, {m['memory_gb']:.2f})"
        lines.append(f"| {r['case']} | {r['cells']} | {r['n_dofs']} | {r['levels']} | {r['matvec_s']:.4f} | "
                     f"{cell('multigrid')} | {cell('direct', False)} | {cell('pyamg')} |")
    (RESULTS / "solvers.md").write_text("\n".join(lines) + "\n")
