"""DFG 2D-1 and 3D-1Z with the cylinder as a fixed fictitious boundary: accuracy against cost
per level.

Question: how close do the drag and the pressure difference of the DFG cylinder come to the
reference values at each level, and at what cost?
Answer: C_D within 0.07-4.8 % (2D, levels 5-1) and 2.3-5.1 % (3D, levels 3-1); the tables and
plots are benchmarks/results/dfg-2d-1.md and dfg-3d-1z.md.
Measured: 2026-11-26, commit 0e3bddf; quoted in docs/validation/dfg-2d-1-and-3d-1z.md.
Run: python -m fbmbench dfg --scene dfg-3d-1z --levels 1 2 3

Each level's row goes into ``benchmarks/results/<scene>.json`` (see :mod:`fbmbench.dfg`); the
table, ``<scene>.png`` and ``<scene>-tradeoff.png`` are redrawn from all rows there. The pytest
benchmark ``test_dfg.py`` runs the same configurations one by one.
"""
from __future__ import annotations

from typing import Literal

from fbmbench import dfg


def run(*, scene: Literal["dfg-2d-1", "dfg-3d-1z"] = "dfg-2d-1", levels: list[int] = (1, 2, 3, 4),
        solver: Literal["direct", "multigrid", "auto"] = "direct",
        boundary: Literal["default", "nodes", "sharp"] = "default") -> None:
    """Run ``scene`` at each level and record the rows.

    Parameters
    ----------
    scene : the DFG scene
    levels : mesh levels, each halving the cells
    solver : the linear solver
    boundary : fbm.boundary (default: the scene's)
    """
    for level in levels:
        dfg.record(scene, dfg.run(scene, level, solver, None if boundary == "default" else boundary))
