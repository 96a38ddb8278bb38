"""Reference elements Q1/Q2/P1disc and the Gauss rules."""
import itertools

import numpy as np
import pytest

from fbmflow.fem import ElementP1Disc, ElementQ1, ElementQ2, gauss_tensor

ELEMENTS = [(cls, dim) for cls in (ElementQ1, ElementQ2) for dim in (2, 3)]
IDS = [f"{cls.__name__}-{dim}d" for cls, dim in ELEMENTS]


def _random_points(dim, n=11, seed=0):
    return np.random.default_rng(seed).uniform(-1, 1, size=(n, dim))


@pytest.mark.parametrize("cls,dim", ELEMENTS, ids=IDS)
def test_sizes_and_node_order(cls, dim):
    el = cls(dim)
    k = el.degree
    assert el.n_local == (k + 1) ** dim
    assert el.nodes.shape == (el.n_local, dim)
    # lexicographic, x fastest: node (i, j[, k]) has local index i + (k+1) j + (k+1)^2 k
    for idx in itertools.product(*[range(k + 1)] * dim):
        number = sum(idx[d] * (k + 1) ** d for d in range(dim))
        np.testing.assert_array_equal(el.local_index[number], idx)
        np.testing.assert_allclose(el.nodes[number], np.array(idx) * (2.0 / k) - 1.0)
    phi, dphi = el.tabulate(_random_points(dim, 4))
    assert phi.shape == (4, el.n_local)
    assert dphi.shape == (4, el.n_local, dim)


@pytest.mark.parametrize("cls,dim", ELEMENTS, ids=IDS)
def test_nodality(cls, dim):
    el = cls(dim)
    phi, _ = el.tabulate(el.nodes)
    np.testing.assert_allclose(phi, np.eye(el.n_local), atol=1e-14)


@pytest.mark.parametrize("cls,dim", ELEMENTS, ids=IDS)
def test_partition_of_unity(cls, dim):
    el = cls(dim)
    phi, dphi = el.tabulate(_random_points(dim))
    np.testing.assert_allclose(phi.sum(axis=1), 1.0, atol=1e-14)
    np.testing.assert_allclose(dphi.sum(axis=1), 0.0, atol=1e-13)


@pytest.mark.parametrize("cls,dim", ELEMENTS, ids=IDS)
def test_gradients_vs_finite_differences(cls, dim):
    el = cls(dim)
    xi = _random_points(dim, 9, seed=1) * 0.999
    _, dphi = el.tabulate(xi)
    eps = 1e-6
    for d in range(dim):
        e = np.zeros(dim)
        e[d] = eps
        fd = (el.tabulate(xi + e)[0] - el.tabulate(xi - e)[0]) / (2 * eps)
        np.testing.assert_allclose(dphi[:, :, d], fd, rtol=0, atol=1e-6)


def test_single_point_input():
    el = ElementQ2(2)
    phi, dphi = el.tabulate(np.array([0.0, 0.0]))
    assert phi.shape == (1, 9) and dphi.shape == (1, 9, 2)
    np.testing.assert_allclose(phi[0], np.eye(9)[4], atol=1e-15)


def _q2_poly(x):
    """A full tensor-product-quadratic polynomial and its gradient, x (n, dim)."""
    dim = x.shape[1]
    rng = np.random.default_rng(7)
    exps = list(itertools.product(*[range(3)] * dim))
    coef = rng.normal(size=len(exps))
    val = np.zeros(x.shape[0])
    grad = np.zeros_like(x)
    for c, e in zip(coef, exps):
        mono = np.prod(x ** np.array(e), axis=1)
        val += c * mono
        for d in range(dim):
            if e[d] > 0:
                ed = np.array(e)
                ed[d] -= 1
                grad[:, d] += c * e[d] * np.prod(x ** ed, axis=1)
    return val, grad


def _q1_poly(x):
    dim = x.shape[1]
    rng = np.random.default_rng(8)
    exps = list(itertools.product(*[range(2)] * dim))
    coef = rng.normal(size=len(exps))
    val = sum(c * np.prod(x ** np.array(e), axis=1) for c, e in zip(coef, exps))
    grad = np.stack([
        sum(c * e[d] * np.prod(x ** (np.array(e) - np.eye(dim, dtype=int)[d]), axis=1)
            for c, e in zip(coef, exps) if e[d] > 0) for d in range(dim)], axis=1)
    return val, grad


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("cls,poly", [(ElementQ2, _q2_poly), (ElementQ1, _q1_poly)])
def test_reproduces_own_polynomial_space(cls, poly, dim):
    el = cls(dim)
    nodal, _ = poly(el.nodes)
    xi = _random_points(dim, 13, seed=2)
    phi, dphi = el.tabulate(xi)
    val, grad = poly(xi)
    np.testing.assert_allclose(phi @ nodal, val, rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.einsum("pad,a->pd", dphi, nodal), grad, rtol=0, atol=1e-12)


@pytest.mark.parametrize("dim", [2, 3])
def test_q2_quadratic_in_each_variable(dim):
    """Simple quadratics, e.g. x^2 - 3 x y + y^2 (+ z^2), are reproduced exactly."""
    el = ElementQ2(dim)

    def f(x):
        v = x[:, 0] ** 2 - 3 * x[:, 0] * x[:, 1] + x[:, 1] ** 2 + 0.5
        return v + (x[:, 2] ** 2 - x[:, 0] * x[:, 2] if dim == 3 else 0.0)

    xi = _random_points(dim, 10, seed=3)
    phi, _ = el.tabulate(xi)
    np.testing.assert_allclose(phi @ f(el.nodes), f(xi), atol=1e-13)


# -- quadrature -------------------------------------------------------------------------------
@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("n_1d", [1, 2, 3, 4])
def test_gauss_weights_and_layout(dim, n_1d):
    points, weights = gauss_tensor(dim, n_1d)
    assert points.shape == (n_1d**dim, dim)
    assert weights.shape == (n_1d**dim,)
    np.testing.assert_allclose(weights.sum(), 2.0**dim, rtol=1e-14)
    assert np.all(weights > 0)
    assert np.all(np.abs(points) < 1)
    # x fastest
    if n_1d > 1:
        x1, _ = np.polynomial.legendre.leggauss(n_1d)
        np.testing.assert_allclose(points[:n_1d, 0], x1)
        np.testing.assert_allclose(points[:n_1d, 1:], points[0, 1:][None, :].repeat(n_1d, 0))


def _exact_1d(p):
    return 0.0 if p % 2 else 2.0 / (p + 1)


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("n_1d", [1, 2, 3, 4])
def test_gauss_exact_for_degree_2n_minus_1(dim, n_1d):
    points, weights = gauss_tensor(dim, n_1d)
    top = 2 * n_1d - 1
    for exps in itertools.product(*[range(top + 1)] * dim):
        q = weights @ np.prod(points ** np.array(exps), axis=1)
        exact = np.prod([_exact_1d(p) for p in exps])
        assert abs(q - exact) < 1e-13, (exps, q, exact)
    # ... and not for x^(2n): the rule really has n_1d points per axis
    q = weights @ points[:, 0] ** (2 * n_1d)
    assert abs(q - _exact_1d(2 * n_1d) * 2.0 ** (dim - 1)) > 1e-3


# -- P1disc -----------------------------------------------------------------------------------
@pytest.mark.parametrize("dim", [2, 3])
def test_p1disc_tabulate(dim):
    el = ElementP1Disc(dim)
    assert el.n_local == dim + 1
    rng = np.random.default_rng(4)
    x = rng.normal(size=(3, 5, dim))
    centre = rng.normal(size=(3, 1, dim))
    scale = rng.uniform(0.5, 2.0, size=(3, 1, dim))
    psi = el.tabulate(x, centre, scale)
    assert psi.shape == (3, 5, dim + 1)
    np.testing.assert_array_equal(psi[..., 0], 1.0)
    np.testing.assert_allclose(psi[..., 1:], (x - centre) / scale, rtol=1e-15)


@pytest.mark.parametrize("dim", [2, 3])
def test_p1disc_frame(dim):
    rng = np.random.default_rng(5)
    coords = rng.normal(size=(4, 2**dim, dim))
    centre, scale = ElementP1Disc.frame(coords)
    assert centre.shape == scale.shape == (4, dim)
    for c in range(4):
        np.testing.assert_allclose(centre[c], coords[c].mean(axis=0))
        np.testing.assert_allclose(scale[c], 0.5 * (coords[c].max(axis=0) - coords[c].min(axis=0)))
    # on an axis-aligned box cell the basis is (1, xi) at the reference point xi
    lo, hi = np.array([1.0, 2.0, -1.0][:dim]), np.array([1.5, 3.0, 0.0][:dim])
    box = lo + np.indices((2,) * dim).reshape(dim, -1, order="F").T * (hi - lo)
    centre, scale = ElementP1Disc.frame(box[None])
    xi = rng.uniform(-1, 1, size=(6, dim))
    x = centre + xi * scale
    psi = ElementP1Disc(dim).tabulate(x, centre, scale)
    np.testing.assert_allclose(psi[:, 1:], xi, atol=1e-14)
