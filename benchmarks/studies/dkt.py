"""Drafting, kissing and tumbling (Uhlmann's set-up): convergence in the mesh level against
Koblitz et al. (2017) (the pytest benchmark ``test_dkt.py`` runs the same levels one by one).

Question: how close do the kissing and tumbling times of two settling disks come to Koblitz et
al.'s (2017), and do they converge in the mesh level?
Answer: at 4 cells/d (level 2) the disks kiss 6.2 % early (0.164 s against about 0.175 s) and
tumble 10.3 % early (0.233 s against about 0.26 s), in 389 s; level 1 is -22.8 / -21.7 % and the
tumbling time still moves 12.8 % between levels 1 and 2 (benchmarks/results/dkt.md).
Measured: 2026-11-26, commit e1b8e83; quoted in docs/validation/drafting-kissing-and-tumbling.md
Run: python -m fbmbench dkt --levels 1 2

Each level's row goes into ``benchmarks/results/dkt.json`` (see fbmbench.dkt); ``dkt.md``,
``dkt.png`` (positions over the digitised curves of the shared reference folder, when present)
and ``dkt-tradeoff.png`` are redrawn from all rows there.
"""

from __future__ import annotations

from fbmbench import dkt


def run(*, levels: list[int] = (1, 2)) -> None:
    """Run the scene at each level and record the rows.

    Parameters
    ----------
    levels : mesh levels, each halving the cells
    """
    for level in levels:
        dkt.record(dkt.run(level))
