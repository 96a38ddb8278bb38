"""Redraw every benchmark's tables and plots from its results JSON, without running anything:
the speed-against-accuracy plots (error against wall time over the mesh levels,
``benchmarks/results/*-tradeoff.png``) and the tables and curve plots next to them.

Run:  python benchmarks/plot_results.py
"""

from __future__ import annotations

from fbmbench import dfg, dkt, glowinski, sphere_array, tencate
from fbmbench.common import RESULTS, load_rows


def main():
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


if __name__ == "__main__":
    main()
