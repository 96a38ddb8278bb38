"""Time order of the registered schemes on the Taylor–Green vortex (issue 2: CN, FS-theta >= 1.9).

Orders come from successive differences of solutions with dt, dt/2, dt/4, dt/8 on one mesh, so the
spatial error cancels: ``log2(|u_dt - u_dt/2| / |u_dt/2 - u_dt/4|)``.
"""
import numpy as np
import pytest

from fbmflow.flow import NavierStokesProblem
from fbmflow.flow.time_schemes import TIME_SCHEMES, advance, get_scheme
from fbmflow.scenes.taylor_green import TaylorGreen2D

EXPECTED = {"backward-euler": 1.0, "crank-nicolson": 2.0, "fractional-step-theta": 2.0}


@pytest.fixture(scope="module")
def problem():
    nu = 0.05
    return NavierStokesProblem(TaylorGreen2D.mesh(1), nu, {}), nu


def test_registry_is_covered():
    assert set(TIME_SCHEMES) == set(EXPECTED)
    for subs in TIME_SCHEMES.values():
        assert np.isclose(sum(s.fraction for s in subs), 1.0)
        # consistency: each substep's weights sum to one
        assert all(np.isclose(s.implicit + s.explicit, 1.0) for s in subs)
    with pytest.raises(ValueError, match="unknown time scheme"):
        get_scheme("rk4")


@pytest.mark.parametrize("scheme", sorted(TIME_SCHEMES))
def test_time_order(problem, scheme):
    prob, nu = problem
    T = 0.4
    finals = []
    for n in (4, 8, 16, 32):
        x = TaylorGreen2D.initial_state(prob, nu)
        t = 0.0
        for _ in range(n):
            x, _ = advance(prob, x, t, T / n, scheme)
            t += T / n
        finals.append(x[:prob.space.n_u])
    d = [np.linalg.norm(finals[i] - finals[i + 1]) for i in range(3)]
    orders = np.log2(np.array(d[:-1]) / np.array(d[1:]))
    expected = EXPECTED[scheme]
    assert orders[-1] >= expected - 0.1, orders
    assert orders[-1] <= expected + 0.5, orders


def test_nonpositive_dt_rejected(problem):
    prob, nu = problem
    with pytest.raises(ValueError, match="time step must be positive"):
        advance(prob, TaylorGreen2D.initial_state(prob, nu), 0.0, 0.0, "crank-nicolson")


def test_energy_decays_at_the_exact_rate():
    from fbmflow.config import from_dict
    scene = TaylorGreen2D()
    params = from_dict(scene.Params, {"time": {"dt": 0.05, "t_end": 0.25}})
    q = scene.run(params, 2).quantities
    E, Eex = np.array(q["kinetic_energy"]), np.array(q["kinetic_energy_exact"])
    assert np.all(np.diff(E) < 0)
    assert np.max(np.abs(E - Eex) / Eex) < 2e-3
    assert q["velocity_l2_error"] < 1e-3


def test_a_guess_changes_the_work_not_the_step(problem):
    """Newton started from a prediction of the new state (here the step's own solution, slightly
    perturbed) ends at the same state to its tolerance, in fewer iterations."""
    prob, nu = problem
    x0 = TaylorGreen2D.initial_state(prob, nu)
    x1, plain = advance(prob, x0, 0.0, 0.05, "crank-nicolson")
    guess = x1 + 1e-6 * np.abs(x1).max() * np.sin(np.arange(x1.size))
    x2, guessed = advance(prob, x0, 0.0, 0.05, "crank-nicolson", guess=guess)
    assert guessed[0].iterations < plain[0].iterations
    assert np.abs(x2 - x1)[:prob.space.n_u].max() <= 1e-6 * np.abs(x1[:prob.space.n_u]).max()
