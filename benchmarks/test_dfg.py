"""DFG 2D-1 and 3D-1Z: drag (and pressure difference in 2D) against the reference values.

Measured values from ``benchmarks/results/dfg-2d-1.md`` and ``dfg-3d-1z.md`` at the scenes'
default boundaries (2D the sharp one, 3D the nodal one) and meshes; each test asserts ``|error|
<= bound(measured)`` (fbmbench.common.bound), from 16 cells per diameter the 2D lift's sign and at
32 (dfg-2d-1's default level) its error.
Times on the 2-core machine: 2D levels 1-4 0.4-41 s (SuperLU), level 5 30 s on multigrid (2.1 GB;
``auto`` picks it); 3D levels 1-2 3-13 s, level 3 72 s on multigrid (2.4 GB; the
direct solver: 135 s with ``pardiso``).
"""

import json

import pytest
from fbmbench import dfg
from fbmbench.common import bound

from fbmflow.cli import main
from fbmflow.scenes.dfg import REFERENCE

quick = pytest.mark.quick

# scene, level, measured |C_D error|, measured |dp error| (None: not asserted), linear solver;
# dfg-2d-1 level 5 also its measured |C_L error|
CASES = [
    pytest.param("dfg-2d-1", 1, 0.4813, 0.2236, "direct", marks=quick, id="dfg_2d_1-level1"),
    pytest.param("dfg-2d-1", 2, 0.0596, 0.1265, "direct", marks=quick, id="dfg_2d_1-level2"),
    pytest.param("dfg-2d-1", 3, 0.0113, 0.0288, "direct", marks=quick, id="dfg_2d_1-level3"),
    pytest.param("dfg-2d-1", 4, 0.0032, 0.0102, "direct", marks=quick, id="dfg_2d_1-level4"),
    pytest.param("dfg-2d-1", 5, 0.0009, 0.0035, "auto", id="dfg_2d_1-level5"),
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
        C_L=row["lift_coefficient"],
        dp_error=row["pressure_difference_error"] if dp is not None else None,
    )
    assert abs(row["drag_coefficient_error"]) <= bound(drag)
    if dp is not None:
        assert abs(row["pressure_difference_error"]) <= bound(dp)
    if scene == "dfg-2d-1" and level >= 4:  # from 16 cells per diameter the lift has its sign
        assert row["lift_coefficient"] > 0
    if scene == "dfg-2d-1" and level == 5:
        assert abs(row["lift_coefficient"] / REFERENCE["lift_coefficient"] - 1) <= bound(0.0349)


def test_dfg_2d1_default_level_meets_its_targets_and_estimates_its_error(tmp_path, bench):
    """dfg-2d-1 at its default level 5 (32 cells per diameter, the sharp boundary on the mesh that
    centres the cylinder) with ``--estimate-error`` (levels 3-5, about a minute): C_D -0.09 % and C_L
    -3.5 % measured, within the targets of 0.3 % and 5 %; the estimates of C_D's and Δp's errors
    1.00x and 1.10x the actual errors, within the factor 2 asserted. The lift's estimate is 0.43x
    its error (docs/validation/converged-answers.md, "Error estimates"): not asserted. On the
    uniform mesh before, C_D's levels changed direction and no estimate came out."""
    assert main(["run", "dfg-2d-1", "--estimate-error", "--out", str(tmp_path), "--quiet"]) == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    q = summary["quantities"]
    assert summary["level"] == 5 and q["cells_per_diameter"] == pytest.approx(32.0)
    assert q["drag_coefficient_error"] < 0.003, q
    assert q["lift_coefficient"] > 0.0, q
    assert abs(q["lift_coefficient"] / REFERENCE["lift_coefficient"] - 1) < 0.05, q
    estimates = summary["error_estimate"]["quantities"]
    ratios = {name: estimates[name]["error"] / (REFERENCE[name] - q[name])
              for name in ("drag_coefficient", "pressure_difference")}
    bench(wall_s=round(summary["wall_time_s"], 1), C_D_error=q["drag_coefficient_error"],
          C_L=q["lift_coefficient"], estimate_over_error=ratios)
    for name, ratio in ratios.items():
        assert estimates[name]["asymptotic"] is True and 0.5 < ratio < 2.0, (name, estimates[name], ratio)
