"""Newton's method: iteration bounds, line search, failure reporting; the direct solver."""
import numpy as np
import pytest

from fbmflow.flow import Dirichlet, NavierStokesProblem, NoSlip
from fbmflow.mesh import StructuredMesh
from fbmflow.solvers import ConvergenceError, LinearReport, NewtonSettings, solve_newton


def _scalar_problem(f, df):
    def step(x, F, fresh=True, rtol=None):
        return -F / df(x), LinearReport("scalar", 0.0, 1)
    return (lambda x: f(x)), step


def test_reused_jacobian_converges_to_the_same_root_and_refreshes_when_slow():
    """Chord steps with the first derivative contract linearly; when they contract less than
    10x per step a fresh derivative is asked for, so the iteration count stays bounded."""
    calls = {"fresh": 0}
    slope = {}

    def step(x, F, fresh=True, rtol=None):
        if fresh or "d" not in slope:
            slope["d"] = 3 * x**2
            calls["fresh"] += 1
        return -F / slope["d"], LinearReport("scalar", 0.0, 1)
    res = lambda x: x**3 - 2.0  # noqa: E731
    x, report = solve_newton(res, step, np.array([1.2]), NewtonSettings(reuse_jacobian=True))
    assert abs(x[0] - 2 ** (1 / 3)) < 1e-10
    assert calls["fresh"] < report.iterations  # some steps reused the derivative
    assert report.iterations <= 12


def test_adaptive_forcing_terms_tighten_near_the_root():
    """Eisenstat-Walker: the linear steps are asked for ``linear_rtol`` at first and for far less
    near the root, where an inexact step would make Newton merely linear (each step here leaves
    exactly the relative residual asked of it)."""
    counts = {}
    for adaptive in (False, True):
        asked = []

        def step(x, F, fresh=True, rtol=None):
            asked.append(rtol)
            return -F / (3 * x**2) * (1 - (1e-2 if rtol is None else rtol)), LinearReport("scalar", 0.0, 1)
        settings = NewtonSettings(rtol=1e-12, linear_rtol=1e-2, adaptive_linear_rtol=adaptive)
        x, report = solve_newton(lambda x: x**3 - 2.0, step, np.array([1.0]), settings)
        assert abs(x[0] - 2 ** (1 / 3)) < 1e-10
        counts[adaptive] = report.iterations
    assert asked[0] == 1e-2 and min(asked) == 1e-4  # MIN_FORCING
    assert counts[True] < counts[False], counts


def test_a_step_near_the_target_is_asked_no_more_than_it_needs():
    """With a fixed ``linear_rtol`` the last step is asked only for half the target over the
    residual it starts from (at most LAST_STEP_FORCING): the same root in as many iterations,
    with looser linear solves (each step here leaves exactly the relative residual asked)."""
    from fbmflow.solvers.newton import LAST_STEP_FORCING
    asked = []

    def step(x, F, fresh=True, rtol=None):
        asked.append((rtol, float(abs(F[0]))))
        return -F / slope * (1 - rtol), LinearReport("linear", 0.0, 1)
    slope = 2.0
    settings = NewtonSettings(rtol=1e-6, atol=1e-30, linear_rtol=1e-4)
    x, report = solve_newton(lambda x: slope * (x - 1.0), step, np.array([2.0]), settings)
    target = 1e-6 * 2.0
    assert report.iterations == 2 and abs(report.residuals[-1]) <= target
    assert asked[0][0] == 1e-4  # far from the target: linear_rtol
    rtol, norm = asked[1]  # residual 2e-4: half the target over it is 5e-3
    assert rtol == pytest.approx(0.5 * target / norm) and 1e-4 < rtol < LAST_STEP_FORCING


def test_quadratic_convergence_on_a_scalar_equation():
    res, step = _scalar_problem(lambda x: x**3 - 2.0, lambda x: 3 * x**2)
    x, report = solve_newton(res, step, np.array([1.0]))
    assert abs(x[0] - 2 ** (1 / 3)) < 1e-12
    assert report.iterations <= 6
    r = report.residuals
    assert r[-2] < 1e-3 * r[-3]  # superlinear tail


def test_line_search_globalises_arctan():
    """Plain Newton diverges for arctan from x0 = 3; the backtracking line search converges."""
    res, step = _scalar_problem(np.arctan, lambda x: 1.0 / (1.0 + x**2))
    x, report = solve_newton(res, step, np.array([3.0]))
    assert abs(x[0]) < 1e-10
    assert report.line_search_steps > 0


def test_failure_is_reported_not_hidden():
    res, step = _scalar_problem(lambda x: x**2 + 1.0, lambda x: 2 * x + 1e-3)
    with pytest.raises(ConvergenceError, match="Newton"):
        solve_newton(res, step, np.array([0.5]), NewtonSettings(max_iterations=5))


@pytest.mark.parametrize("re, max_its", [(100, 6), (400, 10)])
def test_cavity_newton_iterations_are_bounded(re, max_its):
    mesh = StructuredMesh.box((16, 16))
    bcs = {"xmin": NoSlip(), "xmax": NoSlip(), "ymin": NoSlip(), "ymax": Dirichlet((1.0, 0.0))}
    prob = NavierStokesProblem(mesh, 1.0 / re, bcs)
    x, report = prob.solve_steady()
    assert report.converged and report.iterations <= max_its
    assert report.residuals[-1] <= 1e-10 * report.residuals[0]
    # the discrete solution is divergence free and the pressure has zero mean
    u, p = prob.split(x)
    assert np.linalg.norm(prob.BT @ x[:prob.space.n_u]) < 1e-12
    assert abs(prob.mean_weights @ p) < 1e-12


def test_direct_solver_matches_dense_solve():
    mesh = StructuredMesh.box((2, 2))
    bcs = {"xmin": NoSlip(), "xmax": NoSlip(), "ymin": NoSlip(), "ymax": Dirichlet((1.0, 0.0))}
    prob = NavierStokesProblem(mesh, 0.1, bcs)
    x = prob.zero_state()
    system = prob.linear_system(x, 0.0, 1.0, prob.constraints())
    rng = np.random.default_rng(0)
    f, g = rng.standard_normal(system.n_u), rng.standard_normal(system.n_p)
    f[system.fixed] = 0.0
    g -= system.mean_weights * (system.mean_weights @ g) / (system.mean_weights @ system.mean_weights)
    du, dp, _ = prob.linear_solver.solve(system, f, g)
    K = system.matrix().toarray()
    rhs = np.concatenate([f, g, [0.0]])
    sol = np.linalg.lstsq(K, rhs, rcond=None)[0]
    assert np.allclose(du, sol[:system.n_u], atol=1e-10)
    assert np.allclose(dp, sol[system.n_u:-1], atol=1e-10)


def test_a_better_guess_keeps_the_stopping_rule_of_the_usual_start():
    """With ``reference`` the target stays ``rtol`` times the residual at the usual start: a
    start near the root takes fewer iterations and ends within the same target."""
    res, step = _scalar_problem(lambda x: x**3 - 2.0, lambda x: 3 * x**2)
    settings = NewtonSettings(rtol=1e-6)
    _, usual = solve_newton(res, step, np.array([1.0]), settings)
    x, near = solve_newton(res, step, np.array([1.26]), settings, reference=usual.residuals[0])
    assert near.iterations < usual.iterations
    assert near.residuals[-1] <= 1e-6 * usual.residuals[0]
    assert near.residuals[-2] > 1e-6 * usual.residuals[0]  # not the (tighter) rule of its own start
    assert abs(x[0] - 2 ** (1 / 3)) < 1e-6
