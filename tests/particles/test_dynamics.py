"""Newton–Euler integration without fluid: exact kinematics, buoyancy, rotation."""
import numpy as np
import pytest

from fbmflow.particles import INTEGRATORS, Ball, Particles, integrate


def test_free_fall_in_vacuum_is_exact_for_semi_implicit_euler():
    p = Particles.at_rest([Ball(0.1, 2)], 2.0, [[0.0, 1.0]])
    g = np.array([0.0, -9.81])
    dt, n = 0.01, 50
    for _ in range(n):
        p = integrate(p, np.zeros((1, 2)), np.zeros((1, 3)), g, 0.0, dt)
    t = n * dt
    assert np.allclose(p.velocity[0], g * t, rtol=1e-13)
    # symplectic Euler: x_n = x0 + g dt^2 n (n + 1) / 2
    assert np.allclose(p.position[0], [0.0, 1.0] + g * dt**2 * n * (n + 1) / 2, rtol=1e-13)


@pytest.mark.parametrize("scheme", INTEGRATORS)
def test_neutral_buoyancy_stays_at_rest(scheme):
    p = Particles.at_rest([Ball(0.1, 3)], 1000.0, [[0.0, 0.0, 0.0]])
    for _ in range(10):
        p = integrate(p, np.zeros((1, 3)), np.zeros((1, 3)), [0.0, 0.0, -9.81], 1000.0, 0.1, scheme)
    assert np.all(p.velocity == 0.0) and np.all(p.position == 0.0)


def test_reduced_gravity_and_force():
    p = Particles.at_rest([Ball(0.5, 2)], 1.25, [[1.0, 4.0]])
    F = np.array([[0.0, 0.3]])
    p1 = integrate(p, F, np.zeros((1, 3)), [0.0, -980.0], 1.0, 1e-3)
    expected = (F[0] / p.mass[0] + (1 - 1 / 1.25) * np.array([0.0, -980.0])) * 1e-3
    assert np.allclose(p1.velocity[0], expected)


def test_torque_spins_a_disk_and_a_sphere():
    disk = Particles.at_rest([Ball(0.2, 2)], 3.0, [[0.0, 0.0]])
    d1 = integrate(disk, np.zeros((1, 2)), np.array([[0.0, 0.0, 0.5]]), [0.0, 0.0], 1.0, 0.1)
    assert np.isclose(d1.angular_velocity[0], 0.1 * 0.5 / (3.0 * np.pi * 0.2**4 / 2))
    sphere = Particles.at_rest([Ball(0.2, 3)], 3.0, [[0.0, 0.0, 0.0]])
    s = integrate(sphere, np.zeros((1, 3)), np.array([[0.0, 0.0, 0.5]]), [0.0, 0.0, 0.0], 1.0, 0.1)
    for _ in range(20):  # torque-free spin: the quaternion stays unit and turns about z
        s = integrate(s, np.zeros((1, 3)), np.zeros((1, 3)), [0.0, 0.0, 0.0], 1.0, 0.1)
    assert np.isclose(np.linalg.norm(s.orientation[0]), 1.0)
    R = s.rotations()[0]
    angle = s.angular_velocity[0, 2] * 2.1  # 21 steps of 0.1 s, each with the new rate
    assert np.allclose(R[:2, :2], [[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])


def test_fixed_particles_do_not_move_and_bad_input_is_rejected():
    p = Particles.at_rest([Ball(0.1, 2)], 2.0, [[0.0, 0.0]])
    p.fixed[:] = True
    p1 = integrate(p, np.ones((1, 2)), np.ones((1, 3)), [0.0, -9.81], 1.0, 0.1)
    assert np.all(p1.position == 0.0)
    with pytest.raises(ValueError, match="unknown integrator"):
        integrate(p, np.zeros((1, 2)), np.zeros((1, 3)), [0.0, -9.81], 1.0, 0.1, "rk4")
    with pytest.raises(ValueError, match="densities must be positive"):
        Particles.at_rest([Ball(0.1, 2)], -1.0, [[0.0, 0.0]])


@pytest.mark.parametrize("scheme, start, order", [("semi-implicit-euler", "exact", 1),
                                                  ("trapezoidal", "exact", 2), ("trapezoidal", "none", 2),
                                                  ("trapezoidal", "zero", 1)])
def test_convergence_order_under_a_time_dependent_force(scheme, start, order):
    """``F(t) = m cos t`` on a sphere from rest (no gravity): ``v = sin t``, ``x = 1 - cos t``.
    The trapezoidal rule (new force at the end of the step, the previous step's at its start)
    is second order, semi-implicit Euler first; fitted slopes of the position error at t = 1.
    Started without a force history (``previous=None``, a backward-Euler first velocity step)
    the trapezoidal rule stays second order; started from a zero force where ``F(0)`` is not
    zero it falls to first order."""
    errors = []
    for n in (40, 80, 160, 320):
        p = Particles.at_rest([Ball(0.1, 3)], 2.0, [[0.0, 0.0, 0.0]])
        m, dt = p.mass[0], 1.0 / n
        previous = {"exact": (np.array([[m, 0.0, 0.0]]), np.zeros((1, 3))), "none": None,
                    "zero": (np.zeros((1, 3)), np.zeros((1, 3)))}[start]
        for k in range(n):
            F = np.array([[m * np.cos((k + 1) * dt), 0.0, 0.0]])
            p = integrate(p, F, np.zeros((1, 3)), [0.0, 0.0, 0.0], 0.0, dt, scheme, previous)
            previous = (F, np.zeros((1, 3)))
        errors.append(abs(p.position[0, 0] - (1.0 - np.cos(1.0))))
    slopes = -np.diff(np.log(errors)) / np.log(2.0)
    assert np.all(np.abs(slopes - order) < 0.1), slopes


def test_trapezoidal_gain_is_half_a_step_with_a_force_history():
    from fbmflow.particles import velocity_gain

    p = Particles.at_rest([Ball(0.1, 2)], 2.0, [[0.0, 0.0]])
    full, half = velocity_gain(p, 0.1), velocity_gain(p, 0.1, "trapezoidal")
    np.testing.assert_allclose(half, 0.5 * full)
    np.testing.assert_allclose(velocity_gain(p, 0.1, "trapezoidal", history=False), full)
    F = np.array([[0.0, 0.3]])
    zero = (np.zeros((1, 2)), np.zeros((1, 3)))
    v1 = integrate(p, F, np.zeros((1, 3)), [0.0, 0.0], 1.0, 0.1, "trapezoidal", zero).velocity[0]
    np.testing.assert_allclose(v1, half[0, :2, :2] @ F[0])  # with a zero force at the start
    v1 = integrate(p, F, np.zeros((1, 3)), [0.0, 0.0], 1.0, 0.1, "trapezoidal").velocity[0]
    np.testing.assert_allclose(v1, full[0, :2, :2] @ F[0])  # without a history: the end's force
