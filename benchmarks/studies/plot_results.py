"""Redraw every benchmark's tables and plots from its results JSON, without running anything:
the speed-against-accuracy plots (error against wall time over the mesh levels,
``benchmarks/results/*-tradeoff.png``) and the tables and curve plots next to them.

Question: what does each benchmark's accuracy cost in wall time over its mesh levels (a utility:
it redraws the tables and plots from the recorded rows, running nothing)?
Answer: the tables and plots of the glowinski, tencate, dfg (2D-1 and 3D-1Z), dkt and
sphere_array benchmarks, and six speed-against-accuracy plots (dfg-2d-1, dfg-3d-1z, dkt,
glowinski, sphere_array and tencate ``-tradeoff.png``), which docs/validation/ shows in each
benchmark's section.
Measured: 2026-11-26, commit 4cbbac0; quoted in docs/validation/the-benchmark-suite.md
Run: python -m fbmbench plot_results

Prints the tradeoff plots it wrote. docs/validation/ quotes the command in its introduction.
"""
from __future__ import annotations

from fbmbench import dfg, dkt, glowinski, sphere_array, tencate
from fbmbench.common import RESULTS, load_rows


def run() -> None:
    """Redraw the tables and plots from the results JSON (no options)."""
    for name in glowinski.STEMS:
        if load_rows(name):
            glowinski.write(name, load_rows(name))
    glowinski.plot_tradeoff()
    tencate.write(load_rows("tencate"))
    for scene in dfg.SCENES:
        dfg.write(scene, load_rows(scene))
    dkt.write(load_rows("dkt"))
    sphere_array.write(load_rows("sphere_array"))
    print(
        "\n".join(sorted(str(p.relative_to(RESULTS.parent.parent)) for p in RESULTS.glob("*-tradeoff.png")))
    )
