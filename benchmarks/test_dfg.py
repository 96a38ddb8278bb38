"""DFG 2D-1 and 3D-1Z: drag (and pressure difference in 2D) against the reference values.

Measured values from ``benchmarks/results/dfg-2d-1.md`` and ``dfg-3d-1z.md`` (direct solver);
each test asserts ``|error| <= bound(measured)`` (fbmbench.common.bound). Times on the 2-core
machine: 2D levels 1-4 0.1-18 s, level 5 95 s (7.1 GB, needs the ``pardiso`` extra); 3D levels
1-2 3-13 s, level 3 72 s on multigrid (2.4 GB; the direct solver: 135 s with ``pardiso``).
"""

import pytest
from fbmbench import dfg
from fbmbench.common import bound

from fbmflow.solvers.direct import pardiso_available

quick = pytest.mark.quick
needs_pardiso = pytest.mark.skipif(
    not pardiso_available(),
    reason="measured with the pardiso extra only (7-13 GB with it); install fbmflow[pardiso]",
)

# scene, level, measured |C_D error|, measured |dp error| (None: not asserted), linear solver
CASES = [
    pytest.param("dfg-2d-1", 1, 0.0482, 0.2238, "direct", marks=quick, id="dfg_2d_1-level1"),
    pytest.param("dfg-2d-1", 2, 0.0335, 0.0190, "direct", marks=quick, id="dfg_2d_1-level2"),
    pytest.param("dfg-2d-1", 3, 0.0179, 0.0161, "direct", marks=quick, id="dfg_2d_1-level3"),
    pytest.param("dfg-2d-1", 4, 0.0069, 0.0110, "direct", marks=quick, id="dfg_2d_1-level4"),
    pytest.param("dfg-2d-1", 5, 0.0007, 0.0061, "direct", marks=needs_pardiso, id="dfg_2d_1-level5"),
    pytest.param("dfg-3d-1z", 1, 0.0512, None, "direct", marks=quick, id="dfg_3d_1z-level1"),
    pytest.param("dfg-3d-1z", 2, 0.0302, None, "direct", marks=quick, id="dfg_3d_1z-level2"),
    pytest.param("dfg-3d-1z", 3, 0.0230, None, "multigrid", id="dfg_3d_1z-level3"),
]


@pytest.mark.parametrize("scene, level, drag, dp, solver", CASES)
def test_dfg(scene, level, drag, dp, solver, bench):
    row = dfg.run(scene, level, solver)
    dfg.record(scene, row)
    bench(
        wall_s=round(row["wall_s"], 1),
        cpu_s=round(row["cpu_s"], 1),
        n_dofs=row["n_dofs"],
        C_D_error=row["drag_coefficient_error"],
        C_D_bound=bound(drag),
        dp_error=row["pressure_difference_error"] if dp is not None else None,
    )
    assert abs(row["drag_coefficient_error"]) <= bound(drag)
    if dp is not None:
        assert abs(row["pressure_difference_error"]) <= bound(dp)
