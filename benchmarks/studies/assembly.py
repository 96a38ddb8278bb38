"""Assembly speed: the full 3D Navier–Stokes Jacobian on n^3 Q2/P1disc cells, beside scikit-fem.

Question: how fast does fbmflow assemble the 3D Navier–Stokes Jacobian on Q2/P1disc cells, and
how does that compare with scikit-fem assembling the same matrix?
Answer: 38 057 cells/s per Newton Jacobian on 32^3 cells (10 377 cells/s for everything from
scratch, 3.6 s set-up, 2.1 GB peak), 140-144x scikit-fem on 8^3 and 12^3 with the same matrix
(Frobenius norms equal to 2e-14) (benchmarks/results/assembly.md).
Measured: 2026-11-21, commit 33107c3; quoted in docs/validation/discretisation-and-solvers.md
Run: python -m fbmbench assembly --cells 32 --skfem-cells 8 12

Reports, in one process (the machine is noisy, so compare within a run):

* JIT time (first call of every kernel on a 2^3 mesh; with a warm Numba cache this is the load
  time), kept out of the measured figures;
* set-up of the mesh data (geometry at quadrature points, CSR patterns, slot maps);
* assembly throughput in cells/s for (a) one Newton Jacobian (convection + Newton blocks into the
  coupled 3x3 velocity block, the mass and viscous parts on its diagonal blocks from the same
  products; before 2026-12-02 they were assembled apart and expanded onto them)
  and (b) everything from scratch: mass, viscous, divergence B and the Jacobian;
* peak resident memory;
* scikit-fem assembling the same velocity matrix (vector Q2, viscous + convection + Newton + mass)
  on smaller meshes, and fbmflow on the same meshes, as the ratio of cells/s.

Writes ``benchmarks/results/assembly.json`` and ``assembly.md``.
"""
from __future__ import annotations

import json
import platform
import resource
import time
from pathlib import Path

import numpy as np

from fbmflow.fem import (
    FlowSpace,
    assemble_convection,
    assemble_divergence,
    assemble_laplace,
    assemble_mass,
)
from fbmflow.mesh import StructuredMesh

RESULTS = Path(__file__).resolve().parents[1] / "results"


def peak_rss_gb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024**2


def velocity_field(space: FlowSpace) -> np.ndarray:
    x = space.V.coordinates
    return np.concatenate([np.sin(np.pi * x[:, 1]), np.cos(np.pi * x[:, 0]), x[:, 0] * x[:, 2]])


def jacobian(space: FlowSpace, u, J=None, mu=0.01, rho=1.0, m=10.0):
    """Data of the coupled Jacobian ``m rho M + mu L + rho (N(u) + R(u))``, into buffer ``J``
    (as :class:`~fbmflow.flow.NavierStokesProblem` does it for every Newton step)."""
    J = np.empty(space.dim**2 * space.nnz) if J is None else J
    J.fill(0.0)
    assemble_convection(space, u, rho, newton_out=J, mass_laplace=(m * rho, mu))
    return J


def time_fbmflow(n: int, repeats: int = 3) -> dict:
    t0 = time.perf_counter()
    space = FlowSpace(StructuredMesh.box((n, n, n)))
    setup = time.perf_counter() - t0
    u = velocity_field(space)
    parts = {}
    t0 = time.perf_counter()
    assemble_mass(space)  # the level keeps its diagonal (row scales)
    parts["mass_s"] = time.perf_counter() - t0
    assemble_laplace(space)
    parts["laplace_s"] = time.perf_counter() - t0 - parts["mass_s"]
    BT = assemble_divergence(space)
    parts["divergence_s"] = time.perf_counter() - t0 - parts["mass_s"] - parts["laplace_s"]
    J = jacobian(space, u)  # includes the first touch of the new J buffer
    full = time.perf_counter() - t0
    parts["first_jacobian_s"] = full - parts["mass_s"] - parts["laplace_s"] - parts["divergence_s"]
    newton = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        J = jacobian(space, u, J)
        newton.append(time.perf_counter() - t0)
    cells = space.mesh.n_cells
    return {"cells_per_axis": n, "n_cells": cells, "n_velocity_dofs": space.n_u, "n_pressure_dofs": space.n_p,
            "nnz_velocity_block": int(J.size), "nnz_B": int(BT.nnz), "setup_s": setup,
            "full_assembly_s": full, "jacobian_s_best": min(newton),
            "cells_per_s_full": cells / full, "cells_per_s_jacobian": cells / min(newton), **parts,
            "peak_rss_gb": peak_rss_gb(), "_J": J, "_space": space, "_u": u}


def time_skfem(n: int) -> dict | None:
    try:
        import skfem
        from skfem.helpers import ddot, dot, grad, mul
    except ImportError:
        return None
    mesh = skfem.MeshHex.init_tensor(*(np.linspace(0, 1, n + 1),) * 3)
    t0 = time.perf_counter()
    basis = skfem.Basis(mesh, skfem.ElementVector(skfem.ElementHex2()), intorder=5)
    setup = time.perf_counter() - t0
    x = basis.doflocs
    w_dofs = np.zeros(basis.N)
    comp = [np.sin(np.pi * x[1]), np.cos(np.pi * x[0]), x[0] * x[2]]
    for i in range(3):  # ElementVector interleaves the components per node
        w_dofs[i::3] = comp[i][i::3]

    @skfem.BilinearForm
    def form(u, v, w):
        W = w["w"]
        return (0.01 * ddot(grad(u), grad(v)) + dot(mul(grad(u), W), v) + dot(mul(grad(W), u), v)
                + 10.0 * dot(u, v))

    t0 = time.perf_counter()
    A = form.assemble(basis, w=basis.interpolate(w_dofs))
    elapsed = time.perf_counter() - t0
    return {"cells_per_axis": n, "n_cells": mesh.nelements, "basis_setup_s": setup, "assembly_s": elapsed,
            "cells_per_s": mesh.nelements / elapsed, "frobenius": float(np.sqrt((A.data**2).sum())),
            "version": skfem.__version__}


def run(*, cells: int = 32, skfem_cells: list[int] = (8, 12)) -> None:
    """Time fbmflow's assembly on ``cells``^3 and beside scikit-fem on each of ``skfem_cells``;
    writes the tables.

    Parameters
    ----------
    cells : cells per axis of the large mesh
    skfem_cells : cells per axis of the meshes compared with scikit-fem (skipped without it)
    """
    t0 = time.perf_counter()
    time_fbmflow(2, repeats=1)
    jit_s = time.perf_counter() - t0
    print(f"JIT / cache load (2^3 mesh, all kernels): {jit_s:.2f} s")

    comparisons = []
    for n in skfem_cells:
        ours = time_fbmflow(n)
        sk = time_skfem(n)
        row = {"cells_per_axis": n, "fbmflow_cells_per_s_jacobian": ours["cells_per_s_jacobian"]}
        if sk is not None:
            row.update(skfem_cells_per_s=sk["cells_per_s"], skfem_assembly_s=sk["assembly_s"],
                       ratio=ours["cells_per_s_jacobian"] / sk["cells_per_s"], skfem_version=sk["version"])
            # the same matrix up to DOF ordering: equal Frobenius norms
            row["frobenius_rel_diff"] = abs(np.linalg.norm(ours["_J"]) - sk["frobenius"]) / sk["frobenius"]
        comparisons.append(row)
        print(f"{n}^3: fbmflow {row['fbmflow_cells_per_s_jacobian']:.0f} cells/s"
              + (f", scikit-fem {row['skfem_cells_per_s']:.0f} cells/s, ratio {row['ratio']:.1f}x, "
                 f"same matrix: |J|_F rel. diff {row['frobenius_rel_diff']:.1e}" if sk else ""))

    big = time_fbmflow(cells)
    for k in ("_J", "_space", "_u"):
        big.pop(k)
    print(f"{cells}^3 = {big['n_cells']} cells, {big['n_velocity_dofs']} velocity dofs, "
          f"{big['nnz_velocity_block'] / 1e6:.1f} M non-zeros in the velocity block")
    print(f"  set-up (geometry, patterns, slots): {big['setup_s']:.2f} s")
    print(f"  full assembly (M, L, B, Jacobian):  {big['full_assembly_s']:.2f} s = "
          f"{big['cells_per_s_full']:.0f} cells/s"
          f"  [M {big['mass_s']:.2f}, L {big['laplace_s']:.2f}, B {big['divergence_s']:.2f}, "
          "first Jacobian incl. page faults of the new "
          f"{big['nnz_velocity_block'] * 8 / 1e9:.1f} GB buffer "
          f"{big['first_jacobian_s']:.2f} s]")
    print(f"  Newton Jacobian (best of 3):        {big['jacobian_s_best']:.2f} s = "
          f"{big['cells_per_s_jacobian']:.0f} cells/s")
    print(f"  peak RSS: {big['peak_rss_gb']:.2f} GB")
    result = {"machine": platform.processor() or platform.machine(), "jit_s": jit_s, "large": big,
              "skfem_comparison": comparisons}
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "assembly.json").write_text(json.dumps(result, indent=1))
    lines = ["# 3D Navier–Stokes Jacobian assembly (Q2/P1disc)", "",
             f"JIT/cache load: {jit_s:.2f} s (excluded below)", "",
             "| mesh | cells | velocity nnz | set-up s | full (M,L,B,J) cells/s | Jacobian cells/s "
             "| peak RSS GB |",
             "|---|---|---|---|---|---|---|",
             f"| {cells}^3 | {big['n_cells']} | {big['nnz_velocity_block'] / 1e6:.1f} M | "
             f"{big['setup_s']:.2f} | "
             f"{big['cells_per_s_full']:.0f} | {big['cells_per_s_jacobian']:.0f} | "
             f"{big['peak_rss_gb']:.2f} |", "",
             "| mesh | fbmflow Jacobian cells/s | scikit-fem cells/s | ratio | Frobenius rel. diff |",
             "|---|---|---|---|---|"]
    for row in comparisons:
        if "ratio" in row:
            lines.append(f"| {row['cells_per_axis']}^3 | {row['fbmflow_cells_per_s_jacobian']:.0f} | "
                         f"{row['skfem_cells_per_s']:.0f} | {row['ratio']:.1f}x | "
                         f"{row['frobenius_rel_diff']:.1e} |")
    (RESULTS / "assembly.md").write_text("\n".join(lines) + "\n")
