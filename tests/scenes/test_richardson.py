"""Richardson error estimates (fbmflow.scenes.richardson) and ``--estimate-error``."""
import json

import pytest

from fbmflow.cli import main
from fbmflow.scenes.richardson import estimate, estimated_quantities, richardson


@pytest.mark.parametrize("p", [1.0, 1.5, 2.0])
def test_three_levels_of_a_power_law_give_its_limit_and_order_exactly(p):
    q_star, c = 3.0, -0.7
    values = [q_star + c * (0.5**level)**p for level in (2, 3, 4)]
    e = richardson(values)
    assert e["asymptotic"] is True and e["order"] == pytest.approx(p, rel=1e-12)
    assert e["extrapolated"] == pytest.approx(q_star, rel=1e-12)
    assert e["error"] == pytest.approx(q_star - values[-1], rel=1e-10)


CASES = [([1.0, 1.2, 1.1], "change sign"), ([1.0, 1.1, 1.3], "not smaller"), ([1.0, 1.9, 1.9001], "outside")]


@pytest.mark.parametrize("values, reason", CASES)
def test_levels_outside_the_asymptotic_range_give_no_number_but_the_reason(values, reason):
    e = richardson(values)
    assert e["asymptotic"] is False and e["error"] is None and reason in e["reason"]


def test_two_levels_take_the_given_order_and_say_the_range_was_not_checked():
    e = richardson([1.0, 1.1], order=2.0)
    assert e["asymptotic"] is None and e["error"] == pytest.approx(0.1 / 3) and "not checked" in e["reason"]
    with pytest.raises(ValueError, match="2 or 3 levels"):
        richardson([1.0])


def test_only_physical_scalars_are_estimated():
    q = {"drag": 1.0, "drag_error": 0.1, "time_step": 0.01, "courant_number": 0.2, "steps": 3, "t": [0.0],
         "nan": float("nan"), "gap_max_deviation": 0.2, "ghia_max_deviation_u": 0.01}
    assert estimated_quantities(q) == ["drag"]
    assert set(estimate([{"quantities": {"drag": 0.9}}, {"quantities": q}])) == {"drag"}


def test_estimate_error_runs_the_coarser_levels_and_writes_the_estimates(tmp_path):
    """dfg-2d-1 at level 3 (levels 1-3: 2, 4 and 8 cells per diameter, seconds): summary.json holds
    an estimate or a reason for every quantity, the coarser runs and the plot are written."""
    argv = ["run", "dfg-2d-1", "--level", "3", "--estimate-error", "--out", str(tmp_path), "--quiet"]
    assert main(argv) == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    est = summary["error_estimate"]
    assert est["levels"] == [1, 2, 3]
    assert {"drag_coefficient", "lift_coefficient", "pressure_difference"} == set(est["quantities"])
    for name, e in est["quantities"].items():
        assert e["value"] == summary["quantities"][name] and len(e["levels_values"]) == 3
        if e["error"] is None:
            assert e["reason"] and e["asymptotic"] is False
        else:
            assert e["extrapolated"] == pytest.approx(e["value"] + e["error"])
    for level in (1, 2):
        coarser = json.loads((tmp_path / "coarser" / f"level-{level}" / "summary.json").read_text())
        assert coarser["level"] == level
    assert (tmp_path / "error_estimate.png").stat().st_size > 0


def test_dfg_2d1_lift_has_its_sign_from_16_cells_per_diameter(tmp_path):
    """dfg-2d-1 at level 4 (16 cells per diameter, the sharp boundary on the mesh that centres the
    cylinder): C_L +0.0088 (-17 %) and C_D -0.32 % measured; the lift's wrong sign (-0.0533 at this
    level on the old mesh and boundary) fails here. The default level 5 with ``--estimate-error``
    (about a minute) is checked in benchmarks/test_dfg.py."""
    from fbmflow.scenes.dfg import REFERENCE
    assert main(["run", "dfg-2d-1", "--level", "4", "--out", str(tmp_path), "--quiet"]) == 0
    q = json.loads((tmp_path / "summary.json").read_text())["quantities"]
    lift = REFERENCE["lift_coefficient"]
    assert 0.5 * lift < q["lift_coefficient"] < 1.5 * lift, q
    assert q["drag_coefficient_error"] < 0.005, q


def test_estimate_error_at_level_zero_is_refused_before_any_run(tmp_path, capsys):
    code = main(["run", "dfg-2d-1", "--level", "0", "--estimate-error", "--out", str(tmp_path / "x"),
                 "--quiet"])
    assert code == 2 and "level 1 or more" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()
