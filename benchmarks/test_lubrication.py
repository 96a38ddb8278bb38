"""The lubrication correction against Brenner's exact Stokes drag at 6 cells per diameter: a
sphere approaching a wall, and two fictitious spheres approaching each other
(fbmflow.scenes.data.brenner1961, fbmbench.lubrication).

Measured values from ``benchmarks/results/lubrication.md``; each error of the corrected drag is
asserted within ``bound(measured)``. The issue's target is 5 % at every gap: met by the wall
(at most 3.4 %) and by two spheres at every midplane offset measured (at most 4.6 %, on a mesh
plane at h / a = 0.02). About 30-80 s per case on the 2-core machine.
"""

import pytest
from fbmbench import lubrication
from fbmbench.common import bound

from fbmflow.contact.settings import ContactParams

DEFAULTS = ContactParams()
MODEL = {"range": DEFAULTS.lubrication_range_cells, "min_gap": DEFAULTS.lubrication_min_gap_cells,
         "resolved": DEFAULTS.lubrication_resolved_cells}

# (set-up, h / a, midplane offset in cells for two spheres): the measured error of the corrected drag
CASES = [
    pytest.param("rigid", 1.0, None, 0.0253, marks=pytest.mark.quick, id="wall-1"),
    pytest.param("rigid", 0.1, None, -0.0175, id="wall-0.1"),
    pytest.param("rigid", 0.01, None, -0.0032, id="wall-0.01"),
    pytest.param("pair", 0.1, 0.25, -0.0030, id="spheres-0.1"),
    pytest.param("pair", 0.02, 0.25, -0.0298, id="spheres-0.02"),
    pytest.param("pair", 0.02, 0.0, 0.0456, id="spheres-0.02-on-a-mesh-plane"),
    pytest.param("pair", 0.1, 0.0, -0.0419, id="spheres-0.1-on-a-mesh-plane"),
]


@pytest.mark.parametrize("wall, gap, offset, measured", CASES)
def test_lubrication(wall, gap, offset, measured, bench):
    if wall == "pair":
        row = lubrication.run_pairs(6, [gap], [offset])[0]
    else:
        row = lubrication.run(6, wall, [gap])[0]
    lubrication.record([row], MODEL)
    total = row["lambda_flow"] + float(lubrication.correction(gap, 6, wall, MODEL))
    error = total / row["lambda_exact"] - 1
    bench(wall_s=round(row["wall_s"], 1), lambda_flow=row["lambda_flow"], lambda_exact=row["lambda_exact"],
          error=error)
    assert abs(error) <= bound(measured)
