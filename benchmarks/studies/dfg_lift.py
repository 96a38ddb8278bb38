"""The lift of the DFG 2D-1 cylinder on the 3D scene's kind of mesh: is its wrong sign the
graded mesh's or the resolution's?

Question: does the DFG 2D-1 lift take the wrong sign on a mesh graded like dfg-3d-1z's (fine
zone [0.1, 0.3] about the cylinder, cells growing by 1.3 towards the walls), and does it with the
fine zone placed symmetric about the channel's middle, at 8 and 16 cells per diameter?
Answer: graded like 3D: C_L -0.141 / -0.081 (nodal) and -0.0059 / +0.0088 (sharp) at 8 / 16
cells per diameter; the zone symmetric about the middle: -0.112 / -0.035 and -0.065 / +0.014
(reference +0.0106). The sign comes right at 16 cells per diameter with the sharp boundary on
either mesh, not at 8: a matter of resolution, not of the mesh's asymmetry.
Measured: 2026-11-28, commit d105cef; quoted in docs/validation/converged-answers.md.
Run: python -m fbmbench dfg_lift --levels 3 4

Prints one line per mesh, boundary and level: C_D and C_L.
"""
from __future__ import annotations

import numpy as np

from fbmflow.config import from_dict
from fbmflow.mesh import StructuredMesh, graded_axis
from fbmflow.scenes import get_scene
from fbmflow.scenes.dfg import DFG2D1, REFERENCE, D, H


def mesh(kind: str, level: int) -> StructuredMesh:
    """The 2D channel graded along x about the cylinder and, along y, like dfg-3d-1z
    (``graded``: zone [0.1, 0.3]), with the zone symmetric about the middle (``symmetric``:
    [0.105, 0.305]) or uniform (``uniform``); or uniform along x and, along y, the scene's
    (``centred``: the cylinder's centre on a node at every level) or the scene's before it
    (``box``: uniform, the centre at a quarter, five eighths, ... of a cell)."""
    h = D / 2**level
    x = graded_axis(0.0, 2.2, (0.1, 0.3), h)
    if kind == "graded":
        return StructuredMesh.rectilinear([x, graded_axis(0.0, H, (0.1, 0.3), h)])
    if kind == "symmetric":
        return StructuredMesh.rectilinear([x, graded_axis(0.0, H, (0.105, 0.305), h)])
    if kind == "centred":
        return DFG2D1().mesh(level)  # a fresh instance: run() replaces only its own scene's mesh
    if kind == "box":
        return StructuredMesh.box((22 * 2**level, 4 * 2**level), upper=(2.2, H))
    return StructuredMesh.rectilinear([x, np.linspace(0.0, H, int(round(H / h)) + 1)])


def run(*, levels: list[int] = (3, 4), meshes: list[str] = ("graded", "symmetric"),
        boundaries: list[str] = ("nodes", "sharp")) -> None:
    """Each mesh, boundary and level; one line each.

    Parameters
    ----------
    levels : cells per diameter 2^level
    meshes : of graded, symmetric, uniform, centred (the scene's), box (the scene's before)
    boundaries : of nodes, sharp
    """
    scene = get_scene("dfg-2d-1")
    for kind in meshes:
        scene.mesh = lambda level, kind=kind: mesh(kind, level)  # this process's scene only
        for boundary in boundaries:
            for level in levels:
                q = scene.run(from_dict(scene.Params, {"fbm": {"boundary": boundary}}), level).quantities
                print(f"{kind} {boundary} level {level} ({2**level} cells/D): "
                      f"C_D {q['drag_coefficient']:.5f} "
                      f"C_L {q['lift_coefficient']:+.5f} (reference {REFERENCE['lift_coefficient']:+.5f})",
                      flush=True)
