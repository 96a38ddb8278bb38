"""Stokes flow through a simple cubic array of fixed spheres: the drag estimators of the sharp
fictitious boundary against the exact drag, per mesh (the pytest benchmark
``test_sphere_array.py`` runs the same meshes one by one; the set-up is in fbmbench.sphere_array).

Question: how far is each force estimator of the sharp boundary (volume, test-function, surface)
from the exact drag of a sphere in a simple cubic array, per mesh?
Answer: the surface traction is within 0.6 % from 6 cells/d (+2.47 / -0.56 / +0.53 / +0.30 /
-0.18 % at 4 / 6 / 8 / 12 / 16 cells/d), the cut-cell volume force +6.09 / +3.22 / +2.99 /
+1.86 / +1.18 % (first order), the test-function force -21.5 to -3.9 %; the flow's K is within
1.6 % of Sangani & Acrivos from 6 cells/d (benchmarks/results/sphere_array.md).
Measured: 2026-11-26, commit e1b8e83; quoted in docs/validation/sphere-array.md
Run: python -m fbmbench sphere_array --cells 4 6 8 12 16

Each mesh's row goes into ``benchmarks/results/sphere_array.json``; ``sphere_array.md`` and
``sphere_array-tradeoff.png`` are redrawn from all rows there.
"""

from __future__ import annotations

from fbmbench import sphere_array


def run(*, cells: list[int] = (4, 6, 8, 12, 16)) -> None:
    """Run each mesh and record its row.

    Parameters
    ----------
    cells : cells per diameter (even)
    """
    for n in cells:
        sphere_array.record(sphere_array.run(n))
