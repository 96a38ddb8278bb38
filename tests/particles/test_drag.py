"""Drag correlations and the terminal velocity they give (fbmflow.particles.drag)."""
import math

import pytest

from fbmflow.particles.drag import drag_coefficient, terminal_velocity

# ten Cate et al. (2002): fluid (density, viscosity) and the terminal velocity in unbounded
# fluid they give, u_inf [m/s]
TEN_CATE = {"E1": (970.0, 0.373, 0.038), "E2": (965.0, 0.212, 0.060), "E3": (962.0, 0.113, 0.091),
            "E4": (960.0, 0.058, 0.128)}


def test_the_sphere_drag_tends_to_stokes_and_the_terminal_velocity_to_stokes_velocity():
    assert drag_coefficient(1e-6, 3) * 1e-6 / 24 == pytest.approx(1.0, rel=1e-4)
    # a heavy speck in honey: Re ~ 1e-7, so Stokes' velocity (rho_s - rho_f) g d^2 / (18 mu)
    u = terminal_velocity(1e-4, 2000.0, 1000.0, 10.0, 9.81, 3)
    assert u == pytest.approx(1000.0 * 9.81 * 1e-8 / 180.0, rel=1e-4)


@pytest.mark.parametrize("case", TEN_CATE)
def test_the_sphere_terminal_velocity_is_ten_cates_within_8_percent(case):
    rho_f, mu, u_inf = TEN_CATE[case]
    u = terminal_velocity(0.015, 1120.0, rho_f, mu, 9.81, 3)
    assert abs(u / u_inf - 1) < 0.08


@pytest.mark.parametrize("dim", [2, 3])
def test_the_terminal_velocity_balances_drag_and_net_weight(dim):
    d, rho_s, rho_f, mu, g = 0.25, 1.25, 1.0, 0.1, 980.0
    u = terminal_velocity(d, rho_s, rho_f, mu, g, dim)
    area, volume = (math.pi * d**2 / 4, math.pi * d**3 / 6) if dim == 3 else (d, math.pi * d**2 / 4)
    drag = 0.5 * drag_coefficient(rho_f * u * d / mu, dim) * rho_f * u**2 * area
    assert drag == pytest.approx((rho_s - rho_f) * g * volume, rel=1e-9)
    # a light particle rises at the speed a heavy one of the same density difference falls
    assert terminal_velocity(d, 2 * rho_f - rho_s, rho_f, mu, g, dim) == pytest.approx(u)
    assert terminal_velocity(d, rho_f, rho_f, mu, g, dim) == 0.0


def test_the_cylinder_correlation_is_whites_at_re_one_and_hundred():
    """The correlation's terms at Re = 1, and at Re = 100 the measured C_D of about 1.4 to its
    stated 10 %."""
    assert drag_coefficient(1.0, 2) == pytest.approx(9.94, rel=1e-3)
    assert drag_coefficient(100.0, 2) == pytest.approx(1.4, rel=0.1)


def test_bad_arguments_name_the_problem():
    with pytest.raises(ValueError, match="Re must be positive"):
        drag_coefficient(0.0, 3)
    with pytest.raises(ValueError, match="dim must be 2 or 3"):
        drag_coefficient(1.0, 1)
