"""ten Cate et al. (2002), a sphere settling onto the bottom of a box, cases E1-E4: the peak
settling velocity against Table II and the gap curve against the measured one; the quick run
checks the acceleration against the measured velocity curve.

Measured values from ``benchmarks/results/tencate.md`` and docs/validation/ten-cate-e1-e4.md; each
error is asserted within ``bound(measured)`` (fbmbench.common.bound). The 3 % target on u_max is
met by E2-E4 at level 1; the 5 % target on the gap curve is not met by any case (the bounds below
are the measured deviations). A run checkpoints every 5 steps into ``out/bench/`` and the same
test continues it after an interruption.

Times on the 2-core machine (the level-1 runs are hours; run one with ``-k``):

| test | measured |
|---|---|
| E4 level 0, dt 0.02, to t = 0.2 s (quick) | about 1-2 min |
| E4 level 0, dt 0.02, to the bottom | 693 s (PARDISO, Newton 1e-10) |
| E1 level 0, dt 0.02, to the bottom | 813 s |
| E4 level 1, today's defaults (surface force, dt 4.8 ms) | 4938 s on multigrid beside other jobs |
| E4 level 1, dt 0.01 | 1310 s on multigrid (the default at level 1), 9951 s on PARDISO |
| E3 level 1, dt 0.02 | 6739 s on PARDISO (multigrid not yet measured) |
| E2 level 1, dt 0.02 | 10021 s on PARDISO (multigrid not yet measured) |
| E1 level 1, dt 0.02, to t = 2.3 s | 5747 s on PARDISO (multigrid not yet measured) |
"""

import pytest
from fbmbench import tencate
from fbmbench.common import bound

#: the force the runs measured before the surface force became the 3D default (fbm.force = auto)
VOLUME = {"fbm.force": "volume"}
# case, level, dt (0: the scene's, following the mesh), settings, measured u_max error, measured
# gap-curve deviation (None: not asserted)
CASES = [
    pytest.param("E4", 1, 0, {}, 0.0028, 0.238, id="E4-level1-defaults"),
    pytest.param("E4", 1, 0.01, VOLUME, -0.0150, 0.148, id="E4-level1"),
    pytest.param("E3", 1, 0.02, VOLUME, 0.0052, 0.123, id="E3-level1"),
    pytest.param("E2", 1, 0.02, VOLUME, -0.0058, 0.153, id="E2-level1"),
    pytest.param("E1", 1, 0.02, {**VOLUME, "time.t_end": 2.3}, -0.0605, 0.039, id="E1-level1-t2.3"),
    pytest.param("E4", 0, 0.02, VOLUME, 0.0534, 0.453, id="E4-level0"),
    pytest.param("E1", 0, 0.02, VOLUME, -0.0146, 0.229, id="E1-level0"),
]


@pytest.mark.parametrize("case, level, dt, settings, u_max, gap", CASES)
def test_tencate(case, level, dt, settings, u_max, gap, bench):
    row = tencate.run(case, level, dt, settings)
    tencate.record(row)
    bench(
        wall_s=round(row["wall_s"]),
        cpu_s=round(row["cpu_s"], 1),
        steps=row["steps"],
        n_dofs=row["n_dofs"],
        u_max=row["u_max"],
        u_max_error=row["u_max_error"],
        gap_deviation=row["gap_deviation"],
    )
    assert abs(row["u_max_error"]) <= bound(u_max)
    assert row["gap_deviation"] <= bound(gap)


@pytest.mark.quick
def test_tencate_quick(bench):
    """E4 at level 0 (3 cells/d) to t = 0.2 s: the acceleration against the measured velocity
    curve (largest deviation over Table II's u_max)."""
    row = tencate.run("E4", 0, 0.02, {**VOLUME, "time.t_end": 0.2})
    tencate.record(row)
    deviation = tencate.curve_deviation(row)
    bench(
        wall_s=round(row["wall_s"]),
        cpu_s=round(row["cpu_s"], 1),
        steps=row["steps"],
        u_at_end=row["settling_velocity"][-1],
        curve_deviation=deviation,
    )
    assert deviation <= bound(0.094)
