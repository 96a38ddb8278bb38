"""The lubrication correction against Brenner's exact Stokes drag: a sphere approaching a plane
wall and two equal spheres approaching each other, at several meshes and gaps (the set-up is in
fbmbench.lubrication).

Question: how close does the resolved flow, and the flow with the lubrication correction, come
to Brenner's exact drag of a sphere approaching a wall and of two spheres approaching each other,
at 4, 6 and 8 cells per diameter and gaps h/a from 10 to 0.01?
Answer: the resolved flow is within 1-4.5 % down to h/a = 0.5 and then saturates (9 % of the
wall's drag at h/a = 0.01, 6 cells/d); with the correction the largest error over all gaps is
3.4 % for the wall and 4.6 % for two fictitious spheres at 6 cells/d (6.5 % and 5.3 % for the
wall at 4 and 8 cells/d; the mirror set-up 12-14 %) (benchmarks/results/lubrication.md).
Measured: 2026-11-27, commit ef072bf; quoted in docs/validation/lubrication.md
Run: python -m fbmbench lubrication

The pairs: ``python -m fbmbench lubrication --pairs-only --pair-offsets 0 0.25 0.5 --pair-gaps 3
1 0.5 0.2 0.1 0.05 0.02 0.01``.

Each flow's row goes into ``benchmarks/results/lubrication.json``; ``lubrication.md`` and
``lubrication.png`` are redrawn from all rows there with the correction of the given range,
cut-off and resolved gap (by default the package's: ``contact.lubrication_range_cells``,
``lubrication_min_gap_cells`` and ``lubrication_resolved_cells``). ``--pair-offsets`` adds
flows of two fictitious spheres at 6 cells/d whose midplane lies that many cells above a mesh
plane (``--pairs-only`` runs only these; it stands for the old ``--walls`` with no value).
"""

from __future__ import annotations

from fbmbench import lubrication

from fbmflow.contact.settings import ContactParams

#: the package's lubrication defaults
CONTACT = ContactParams()
WALLS = ("rigid", "free")


def run(*, cells: list[int] = (4, 6, 8), walls: list[str] = WALLS, pairs_only: bool = False,
        gaps: list[float] = lubrication.GAPS, range_cells: float = CONTACT.lubrication_range_cells,
        min_gap_cells: float = CONTACT.lubrication_min_gap_cells,
        resolved_cells: float = CONTACT.lubrication_resolved_cells, solver: str = "auto",
        pair_offsets: list[float] = (), pair_gaps: list[float] = (0.1, 0.02),
        table_only: bool = False) -> None:
    """Run the flows, record their rows and redraw the table and plot.

    Parameters
    ----------
    cells : cells per diameter
    walls : rigid: sphere towards a wall; free: two spheres towards each other
    pairs_only : run no wall, only the pairs of --pair-offsets
    gaps : gaps h / a
    range_cells : range of the correction [cells]
    min_gap_cells : cut-off gap of the correction [cells]
    resolved_cells : gap down to which the flow carries the film force [cells]
    solver : linear solver (auto, multigrid, direct, pardiso)
    pair_offsets : also two fictitious spheres at 6 cells/d, midplane this many cells off a mesh plane
    pair_gaps : gaps h / a of the pairs
    table_only : redraw the table and plot from the rows
    """
    unknown = [w for w in walls if w not in WALLS]
    if unknown:
        raise SystemExit(f"lubrication: no wall {', '.join(unknown)}; walls: {', '.join(WALLS)}")
    rows = []
    if not table_only:
        for wall in () if pairs_only else walls:
            for n in cells:
                rows += lubrication.run(n, wall, list(gaps), solver)
        if pair_offsets:
            rows += lubrication.run_pairs(6, list(pair_gaps), list(pair_offsets))
    lubrication.record(rows, {"range": range_cells, "min_gap": min_gap_cells, "resolved": resolved_cells})
