"""The lubrication correction and the exact solution it is checked against (Brenner 1961)."""
import numpy as np
import pytest

from fbmflow.config import ParamError
from fbmflow.contact import Lubrication
from fbmflow.contact.settings import ContactParams
from fbmflow.scenes.data.brenner1961 import drag_factor


def test_brenner_series_matches_his_table():
    """Brenner's Table 1 (rigid wall) at alpha = 3, 2, 1.5, 1, 0.5 (h / a = cosh(alpha) - 1)."""
    alpha = np.array([3.0, 2.0, 1.5, 1.0, 0.5])
    table = np.array([1.1252, 1.4129, 1.8375, 3.0361, 9.2518])
    assert np.allclose(drag_factor(np.cosh(alpha) - 1.0), table, atol=1e-4)


@pytest.mark.parametrize("wall, near, far", [("rigid", 1.0, 9 / 8), ("free", 0.25, 3 / 4)])
def test_brenner_series_has_the_known_limits(wall, near, far):
    """Near contact lambda h / a -> 1 (wall) and 1/4 (free surface: two spheres); far away
    lambda - 1 -> 9/8 and 3/4 times a / (a + h) (Lorentz's reflection)."""
    h = np.array([1e-4, 1e-3])
    lam = drag_factor(h, wall)
    assert np.all(np.abs(lam * h / near - 1) < 30 * h * np.log(1 / h))  # log corrections
    assert abs(lam[0] * h[0] - near) < abs(lam[1] * h[1] - near)
    if wall == "rigid":  # Cox & Brenner (1967): a/h + 1/5 ln(a/h) + 0.971
        assert np.allclose(lam, 1 / h + 0.2 * np.log(1 / h) + 0.971, atol=2e-3)
    d = 200.0
    assert (drag_factor(d - 1.0, wall) - 1.0) * d == pytest.approx(far, rel=0.01)


def test_brenner_series_rejects_bad_input():
    with pytest.raises(ValueError, match="positive"):
        drag_factor([0.1, 0.0])
    with pytest.raises(ValueError, match="rigid"):
        drag_factor(0.1, "slip")


def test_correction_without_a_resolved_gap_is_the_near_contact_law_less_its_value_at_the_range():
    """resolved_gap = 0: c(g) = 6 pi mu [a^2 (1/g - 1/delta) + a/5 ln(delta/g)] for a sphere and a
    wall (Cox & Brenner), zero beyond the range, constant below the cut-off; two equal spheres
    have R* = a/2 and Jeffrey & Onishi's log term 9a/40."""
    mu, a, delta, cut = 0.3, 0.5, 0.2, 0.004
    lub = Lubrication(mu, delta, cut)
    g = np.array([0.001, 0.01, 0.1, 0.2, 0.3])
    c = lub.coefficient(g, np.full(5, a), np.full(5, np.inf), 3)
    gc = np.maximum(g, cut)
    expected = 6 * np.pi * mu * (a**2 * (1 / gc - 1 / delta) + a / 5 * np.log(delta / gc))
    assert np.allclose(c[:3], expected[:3])
    assert np.all(c[3:] == 0.0)
    pair = lub.coefficient(g[:3], np.full(3, a), np.full(3, a), 3)
    assert np.allclose(pair, 6 * np.pi * mu * (a**2 / 4 * (1 / gc[:3] - 1 / delta)
                                               + 9 * a / 40 * np.log(delta / gc[:3])))


@pytest.mark.parametrize("dim", [2, 3])
def test_correction_with_a_resolved_gap_adds_what_the_mesh_misses(dim):
    """With resolved_gap s the correction is C(g) - C(g_e), g_e = (g^p + s^p)^(1/p), less its
    value at the range: continuous (zero) at the range, positive and decreasing below it, and
    near contact the whole near-contact law less a bounded part."""
    from fbmflow.contact.lubrication import BLEND_EXPONENT as p
    mu, a, delta, s = 1.0, 1.0, 0.6, 0.15
    lub = Lubrication(mu, delta, 1e-5, s)
    g = np.array([1e-3, 1e-2, 0.1, 0.3, delta * (1 - 1e-9), delta, 1.0])
    c = lub.coefficient(g, np.full(g.size, a), np.full(g.size, np.inf), dim)
    assert np.all(np.diff(c[:5]) < 0) and np.all(c[:5] > 0) and c[4] < 1e-6 and np.all(c[5:] == 0)

    def C(x):  # the near-contact law of a sphere at a wall (R* = a, l = a / 5), of a disk
        return 6 * np.pi * mu * (a**2 / x + a / 5 * np.log(1 / x)) if dim == 3 else \
            3 * np.pi / (2 * np.sqrt(2)) * mu * (a / x)**1.5

    def unresolved(x):
        return C(x) - C((x**p + s**p)**(1 / p))

    assert c[2] == pytest.approx(unresolved(0.1) - unresolved(delta), rel=1e-12)
    near = 6 * np.pi * mu * a**2 / g[0] if dim == 3 else 3 * np.pi / (2 * np.sqrt(2)) * mu * (a / g[0])**1.5
    assert c[0] == pytest.approx(near, rel=0.02)


def test_cut_off_must_lie_below_the_range():
    with pytest.raises(ParamError, match="lubrication_min_gap_cells"):
        ContactParams(lubrication_range_cells=0.5, lubrication_min_gap_cells=0.5)
