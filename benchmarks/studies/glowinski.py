"""Glowinski's free fall of a disk: convergence in the mesh level and in the time step (a study of
several runs; the pytest benchmark ``test_glowinski.py`` runs single configurations).

Question: how close does the peak settling velocity of Glowinski's falling disk come to Koblitz
et al.'s (2017) 5.591 cm/s, and does it converge in the mesh level and the time step?
Answer: with the sharp boundary and Crank–Nicolson, v_max is 5.8030 / 5.6523 cm/s (+3.79 / +1.10 %)
at 2 / 4 cells/D and dt 4 ms, and 5.6120 cm/s (+0.38 %, curve within 0.86 %) at 4 cells/D and
dt 2 ms (benchmarks/results/glowinski.md); the mesh target is met (0.07 % between 4 and 8 cells/D,
earlier rows); the nodal boundary needs 32 cells/D (0.61 % between levels 4 and 5,
glowinski-nodes.md).
Measured: 2026-11-26, commit e1b8e83; quoted in docs/validation/glowinski-free-fall.md
Run: python -m fbmbench glowinski --levels 1 2 --dt 0.004 --dts 0.004 0.002 0.001 --dt-level 2

Other studies: ``--boundary nodes`` (backward Euler, ``glowinski-nodes.md``), ``--scheme
backward-euler`` (``glowinski-be.md``), ``--mesh uniform`` (``glowinski-uniform.md``).

Each run's row goes into ``benchmarks/results/glowinski*.json`` (see fbmbench.glowinski) and the
tables and plots are redrawn from all rows there. With ``--reuse`` a configuration already in the
results file is not run again.
"""

from __future__ import annotations

from typing import Literal

from fbmbench import glowinski
from fbmbench.common import load_rows


def run(
    *,
    levels: list[int] = (1, 2, 3),
    dts: list[float] = (0.004, 0.002, 0.001),
    dt: float = 0.002,
    dt_level: int = 2,
    t_end: float = 0.65,
    mesh: Literal["graded", "uniform"] = "graded",
    boundary: Literal["sharp", "nodes"] = "sharp",
    scheme: Literal["crank-nicolson", "backward-euler"] = None,
    reuse: bool = False,
) -> None:
    """Run the mesh study (``levels`` at ``dt``) and the time-step study (``dts`` at ``dt_level``).

    Parameters
    ----------
    levels : mesh levels of the mesh study
    dts : time steps of the time-step study
    dt : time step of the mesh study
    dt_level : level of the time-step study
    t_end : past the peak, before the landing
    mesh : domain.mesh
    boundary : fbm.boundary
    scheme : time.scheme (with the trapezoidal / semi-implicit Euler particle integrator); default:
        crank-nicolson for the sharp boundary, backward-euler for the nodal one
    reuse : skip configurations already in the results file
    """
    scheme = scheme or ("crank-nicolson" if boundary == "sharp" else "backward-euler")
    runs = [(lv, dt) for lv in levels] + [(dt_level, step) for step in dts]
    runs = sorted(dict.fromkeys(runs), key=lambda r: (r[0], -r[1]))  # cheapest first, no repeats
    name = glowinski.stem(mesh, boundary, scheme)
    for level, step in runs:
        want = dict(
            level=level,
            dt=step,
            t_end=t_end,
            mesh=mesh,
            boundary=boundary,
            scheme=scheme,
            pressure_lag=glowinski.pressure_lag(scheme),
        )
        if reuse and any(glowinski.key(r) == glowinski.key(want) for r in load_rows(name)):
            print(f"level {level} dt {step}: in results/{name}.json already")
            continue
        glowinski.record(glowinski.run(level, step, t_end, mesh, boundary, scheme))
    glowinski.write(name, load_rows(name))
