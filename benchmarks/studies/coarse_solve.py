"""The coarsest multigrid level's solve: the sparse LU it takes today against PyAMG.

Question: does PyAMG (smoothed aggregation on the velocity block, the pressure mass matrix on the
pressure, inside FGMRES) solve the coarsest level of fbmflow's hierarchies faster than the sparse
LU the multigrid factorises once per linearisation?
Answer: no. The LU's set-up and solve are cheaper on every coarsest level measured (cavity-2d 210
unknowns 0.002 s against 0.03 s; ten-cate level 1, 5 427 unknowns, 0.08 s against 0.15 s to 1e-2
in 88 iterations; dfg-3d-1z level 3, 34 049 unknowns, 3.1 s against no convergence in 400
iterations); pyamg moved from the dependencies to the ``bench`` extra.
Measured: 2026-11-28, commit 743678e; quoted in
docs/validation/multigrid-with-fictitious-boundaries.md, "The coarsest level"
Run: python -m fbmbench coarse_solve --cases cavity-2d dfg-3d-1z ten-cate

Each case builds a scene's flow problem with multigrid at the scene's default level, linearises it
once (the first time step's, or the steady Stokes start's, system) and takes the last system of
its ``coarser`` chain: that is what ``MultigridSolver`` factorises. Both solvers then solve the
same right-hand side (the coarse restriction of a random residual) to the relative residuals
``1e-8`` (what a stand-alone coarse solve gives) and ``1e-2``; the LU is exact to round-off.
Times are the set-up plus the solve, one after the other in one process.
"""
from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

RESULTS = Path(__file__).resolve().parents[1] / "results"
CASES = ("cavity-2d", "dfg-3d-1z", "ten-cate")


def coarsest_system(case: str):
    """The flow problem of ``case`` at its default level (multigrid) and the coarsest system of
    its first linearisation's hierarchy."""
    from fbmflow.config import from_dict
    from fbmflow.coupling import FixedObstacles
    from fbmflow.flow import Dirichlet, DoNothing, NoSlip
    from fbmflow.scenes import get_scene
    from fbmflow.scenes.builder import flow_problem

    scene = get_scene(case)
    params = from_dict(scene.Params, {"solver": {"linear": "multigrid"}})
    level = scene.default_level
    if case == "ten-cate":
        sim = scene.build(params, level).sim
        flow, x, m = sim.flow, sim.x, 1.0 / params.time.dt
    elif case == "cavity-2d":
        mesh = scene.mesh(level)
        bcs = {t: NoSlip() for t in mesh.tags}
        bcs["ymax"] = Dirichlet((1.0, 0.0))
        flow = flow_problem(mesh, 1.0 / params.fluid.re, bcs, params.solver)
        x, m = flow.zero_state(), 0.0
    else:  # dfg-3d-1z as the scene sets it up (scenes/dfg.py)
        f, mesh = params.fluid, scene.mesh(level)
        obstacle = FixedObstacles([scene.cylinder()], scene.centre[None, :], params.fbm.boundary)
        bcs = {"xmin": Dirichlet(scene.inflow(f.max_inflow)), "xmax": DoNothing(),
               **{tag: NoSlip() for tag in mesh.tags if tag not in ("xmin", "xmax")}}
        flow = flow_problem(mesh, f.viscosity, bcs, params.solver, density=f.density,
                            extra_constraints=obstacle,
                            coarse_cells=mesh.n_cells // 2**(scene.dim * max(level - 2, 0)))
        x, m = flow.zero_state(), 0.0
    con = flow.constraints(0.0)
    system = flow.linear_system(x, m, 1.0, con)
    system = system.preconditioner or system
    while system.coarser is not None:
        system = system.coarser
    return flow, system


def lu(system, b):
    """Set-up and solve time of the sparse LU the multigrid uses (``factorize``), and its residual."""
    from fbmflow.solvers.direct import factorize

    t0 = time.perf_counter()
    solve = factorize(system)
    t1 = time.perf_counter()
    u, p = solve(b[:system.n_u], b[system.n_u:])
    t2 = time.perf_counter()
    x = np.concatenate([u, p])
    rhs = np.concatenate([b[:system.n_u], system.balance(b[system.n_u:])])
    return t1 - t0, t2 - t1, float(np.linalg.norm(rhs - system.apply(x)) / np.linalg.norm(rhs))


def amg(system, b, rtol: float, mu: float):
    """PyAMG smoothed aggregation on the velocity block, the inverse pressure mass (exact per
    cell: the P1disc mass is block diagonal) on the pressure, inside FGMRES: set-up and
    solve time, iterations (None: not converged in 400). ``mu``: the viscosity (the Schur
    complement of a Stokes system is about the pressure mass over it)."""
    import pyamg
    import scipy.sparse as sp

    from fbmflow.solvers import fgmres

    t0 = time.perf_counter()
    A = sp.csr_matrix(system.A)
    ml = pyamg.smoothed_aggregation_solver(A, symmetry="nonsymmetric", max_coarse=500)
    s = system.space  # the P1disc pressure mass, cell by cell (its inverse: block diagonal)
    local = np.einsum("cq,cqm,cqn->cmn", s.detJw, s.psi, s.psi)
    Mp_inv = sp.block_diag(list(np.linalg.inv(local)), format="csr") * mu
    n_u = system.n_u
    t1 = time.perf_counter()

    def precondition(r):
        return np.concatenate([ml.solve(r[:n_u], tol=1e-30, maxiter=1, cycle="V"), Mp_inv @ r[n_u:]])

    rhs = np.concatenate([b[:n_u], system.balance(b[n_u:])])
    x0 = np.zeros_like(rhs)
    if system.fixed is not None:
        x0[system.fixed] = rhs[system.fixed]
    project = system.remove_pressure_mean if system.mean_weights is not None else None
    x, res, its = fgmres(system.apply, precondition, rhs, x0, rtol, 400, 40, project)
    converged = res[-1] <= rtol * res[0]
    return t1 - t0, time.perf_counter() - t1, its if converged else None


def run(*, cases: list[str] = CASES) -> None:
    """Measure each case's coarsest level and write ``benchmarks/results/coarse_solve.md`` / ``.json``.

    Parameters
    ----------
    cases : scenes whose default-level hierarchy is measured (cavity-2d, dfg-3d-1z, ten-cate)
    """
    unknown = sorted(set(cases) - set(CASES))
    if unknown:
        raise SystemExit(f"coarse_solve: unknown cases {unknown}; choose from {CASES}")
    rows = []
    for case in cases:
        flow, system = coarsest_system(case)
        rng = np.random.default_rng(0)
        b = rng.standard_normal(system.n_u + system.n_p)
        if system.fixed is not None:
            b[system.fixed] = 0.0
        lu_setup, lu_solve, lu_res = lu(system, b)
        row = dict(case=case, unknowns=system.n_u + system.n_p, lu_setup_s=lu_setup, lu_solve_s=lu_solve,
                   lu_residual=lu_res)
        for rtol in (1e-2, 1e-8):
            setup, solve, its = amg(system, b, rtol, flow.mu)
            row["amg_setup_s"] = setup
            row[f"amg_solve_{rtol:g}_s"] = solve
            row[f"amg_iterations_{rtol:g}"] = its
        rows.append(row)
        print(row, flush=True)
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "coarse_solve.json").write_text(json.dumps(rows, indent=1))
    lines = ["# The coarsest multigrid level: sparse LU against PyAMG", "",
             "Command: `python -m fbmbench coarse_solve`; 2-core machine, one process, the two solvers one "
             "after the other on the same system and right-hand side. LU: `factorize` (SuperLU, as the "
             "multigrid uses it), exact to round-off. PyAMG: smoothed aggregation on the velocity block "
             "(nonsymmetric, V-cycle), the diagonal of the pressure mass on the pressure, FGMRES(40); "
             "iterations to 1e-2 and 1e-8 (- : not converged in 400).", "",
             "| case | coarsest unknowns | LU set-up [s] | LU solve [s] | AMG set-up [s] | "
             "AMG to 1e-2 [s] (its) | AMG to 1e-8 [s] (its) |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        def cell(rtol):
            its = r[f"amg_iterations_{rtol:g}"]
            return f"{r[f'amg_solve_{rtol:g}_s']:.3f} ({its if its is not None else '-'})"
        lines.append(f"| {r['case']} | {r['unknowns']} | {r['lu_setup_s']:.3f} | {r['lu_solve_s']:.4f} | "
                     f"{r['amg_setup_s']:.3f} | {cell(1e-2)} | {cell(1e-8)} |")
    (RESULTS / "coarse_solve.md").write_text("\n".join(lines) + "\n")
