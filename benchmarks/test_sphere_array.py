"""Stokes flow through a cubic array of spheres: the sharp boundary's drag estimators against the
exact drag, and the flow's dimensionless drag K against Sangani & Acrivos' series.

Measured values from ``benchmarks/results/sphere_array.md``; each error is asserted within
``bound(measured)`` (fbmbench.common.bound). Times on the 2-core machine: 4-8 cells/d 0.4-3 s,
12 cells/d 22 s, 16 cells/d 90 s.
"""

import pytest
from fbmbench import sphere_array
from fbmbench.common import bound

quick = pytest.mark.quick

# cells per diameter: measured (volume force, test-function force, surface traction, K) errors
CASES = [
    pytest.param(4, (0.0609, -0.2149, 0.0247, -0.0584), marks=quick, id="4"),
    pytest.param(6, (0.0322, -0.1297, -0.0056, -0.0160), marks=quick, id="6"),
    pytest.param(8, (0.0299, -0.0828, 0.0053, -0.0124), marks=quick, id="8"),
    pytest.param(12, (0.0186, -0.0613, 0.0030, -0.0061), id="12"),
    pytest.param(16, (0.0118, -0.0388, -0.0018, -0.0026), id="16"),
]
KEYS = ("volume_error", "test_function_error", "surface_error", "K_error")


@pytest.mark.parametrize("cells, measured", CASES)
def test_sphere_array(cells, measured, bench):
    row = sphere_array.run(cells)
    sphere_array.record(row)
    bench(
        wall_s=round(row["wall_s"], 1),
        cpu_s=round(row["cpu_s"], 1),
        n_dofs=row["n_dofs"],
        **{k: row[k] for k in KEYS},
    )
    for key, m in zip(KEYS, measured):
        assert abs(row[key]) <= bound(m), key
