"""``solver.linear = "auto"``: the cheaper solver by the measured cost model."""
import pytest

from fbmflow.solvers.choice import cheapest_solver, solve_time


@pytest.mark.parametrize("solver, dim, n, rtol, measured", [
    ("superlu", 2, 45_570, None, 0.43), ("pardiso", 2, 45_570, None, 0.16),
    ("multigrid", 2, 45_570, 1e-2, 0.32), ("multigrid", 2, 17_106, 1e-8, 1.4),
    ("pardiso", 3, 64_547, None, 1.0), ("pardiso", 3, 278_739, None, 11.0),
    ("superlu", 3, 9_043, None, 0.13), ("superlu", 3, 64_547, None, 16.0)])
def test_the_model_reproduces_the_measured_solves(solver, dim, n, rtol, measured):
    """Within 30 % of the per-solve times it was fitted to (SOLVE_COST's docstring)."""
    assert 0.7 * measured <= solve_time(solver, dim, n, rtol) <= 1.3 * measured


@pytest.mark.parametrize("dim, n, rtol, pardiso, expected", [
    (2, 45_570, 1e-2, True, "direct"),      # the cavity: PARDISO 3.1 s against multigrid 4.8 s
    (2, 45_570, 1e-2, False, "multigrid"),  # against SuperLU 7.2 s
    (2, 164_946, 1e-8, False, "direct"),    # a 2D particle flow solved tightly: SuperLU
    (3, 64_547, 1e-3, True, "multigrid"),   # ten-cate level 0
    (3, 278_739, 1e-3, True, "multigrid"),  # ten-cate level 1: 8-9 s per step against 43-49 s
    (3, 8_000, 1e-8, False, "direct"),      # a small 3D system
    (3, 486_979, 1e-2, True, "multigrid"),  # channel-3d level 4
])
def test_auto_picks_what_was_measured_cheaper(dim, n, rtol, pardiso, expected):
    assert cheapest_solver(dim, n, rtol, pardiso) == expected


def test_a_solver_that_does_not_fit_is_passed_over():
    assert cheapest_solver(2, 45_570, 1e-2, True, fits=lambda name: name != "direct") == "multigrid"


def test_the_coupling_s_responses_weigh_against_multigrid():
    """30 disks at sedimentation-2d level 1 (35 682 unknowns, linear steps to 1e-3, no PARDISO):
    multigrid is cheaper per Newton solve, but the implicit coupling's 90 responses per step are
    substitutions with a direct factorisation and whole solves with multigrid (measured: the
    dense-packing test took 1 143 s on multigrid, 37 s on SuperLU, compilation included)."""
    assert cheapest_solver(2, 35_682, 1e-3, False) == "multigrid"
    assert cheapest_solver(2, 35_682, 1e-3, False, responses=90) == "direct"
    # ten-cate level 0 on two mirror planes: one response does not change the choice
    assert cheapest_solver(3, 64_547, 1e-3, True, responses=1) == "multigrid"


def test_substitutions_are_cheap_next_to_the_factorisation():
    """The substitution model against the measured SuperLU runs of its docstring, within 30 %."""
    from fbmflow.solvers.choice import substitution_time

    for dim, n, measured in ((2, 35_682, 0.72 / 90), (2, 17_106, 0.22 / 90), (3, 32_707, 1.46 / 90)):
        assert 0.7 * measured <= substitution_time("superlu", dim, n) <= 1.3 * measured


def test_the_switch_points_are_where_the_choice_changes():
    """The documentation's table (docs/parameters.md) comes from ``switch_point``: just below it
    the direct solver, at it multigrid."""
    from fbmflow.solvers.choice import switch_point

    for dim, rtol, pardiso, responses in ((2, 1e-2, False, 0), (3, 1e-8, True, 6), (3, 1e-2, False, 60)):
        n = switch_point(dim, rtol, pardiso, responses)
        assert cheapest_solver(dim, int(0.99 * n), rtol, pardiso, responses=responses) == "direct"
        assert cheapest_solver(dim, int(1.01 * n), rtol, pardiso, responses=responses) == "multigrid"
    assert switch_point(2, 1e-8, True) is None  # PARDISO stays cheaper for tight 2D solves
