"""Shapes: inside tests, volumes, centres of mass and inertia against closed forms; the winding-number
kernel against a NumPy reference; meshio file round trip; clear errors for bad surfaces."""
import numpy as np
import pytest

from fbmflow.particles import Ball, Box, Cylinder, Ellipsoid, ImplicitShape, TriangulatedSurface, _kernels


def box_surface(h, centre=(0.0, 0.0, 0.0)):
    """12 outward triangles of the box |x_k - c_k| <= h_k."""
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], float)
    v = corners * np.array(h) + np.array(centre)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    t = [(a, b, c) for a, b, c, d in quads] + [(a, c, d) for a, b, c, d in quads]
    return v, np.array(t)


def icosphere(level):
    """Unit icosphere, outward triangles."""
    g = (1 + 5**0.5) / 2
    v = [(-1, g, 0), (1, g, 0), (-1, -g, 0), (1, -g, 0), (0, -1, g), (0, 1, g), (0, -1, -g), (0, 1, -g),
         (g, 0, -1), (g, 0, 1), (-g, 0, -1), (-g, 0, 1)]
    t = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2),
         (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5),
         (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    v = [np.array(p, float) / np.linalg.norm(p) for p in v]
    for _ in range(level):
        cache, new = {}, []

        def mid(i, j):
            key = (min(i, j), max(i, j))
            if key not in cache:
                m = v[i] + v[j]
                v.append(m / np.linalg.norm(m))
                cache[key] = len(v) - 1
            return cache[key]
        for a, b, c in t:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            new += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        t = new
    return np.array(v), np.array(t)


def winding_numpy(x, v, t):
    a = v[t[:, 0]][None] - x[:, None]
    b = v[t[:, 1]][None] - x[:, None]
    c = v[t[:, 2]][None] - x[:, None]
    la, lb, lc = (np.linalg.norm(q, axis=2) for q in (a, b, c))
    det = np.einsum("pti,pti->pt", a, np.cross(b, c))
    den = la * lb * lc + np.einsum("pti,pti->pt", a, b) * lc + np.einsum("pti,pti->pt", b, c) * la \
        + np.einsum("pti,pti->pt", c, a) * lb
    return (2 * np.arctan2(det, den)).sum(axis=1) / (4 * np.pi)


def test_ellipse_and_ellipsoid_closed_forms():
    e2 = Ellipsoid((0.3, 0.1))
    assert e2.dim == 2 and e2.volume == pytest.approx(np.pi * 0.03)
    assert e2.inertia[0, 0] == pytest.approx(np.pi * 0.03 * (0.09 + 0.01) / 4)
    assert e2.inside(np.array([[0.29, 0.0], [0.0, 0.11], [0.2, 0.07]])).tolist() == [True, False, True]
    e3 = Ellipsoid((0.3, 0.2, 0.1))
    V = 4 / 3 * np.pi * 0.006
    assert e3.volume == pytest.approx(V)
    np.testing.assert_allclose(np.diag(e3.inertia), V / 5 * np.array([0.05, 0.1, 0.13]))
    with pytest.raises(ValueError, match="positive"):
        Ellipsoid((0.1, -1.0))


def test_box_closed_forms():
    b = Box((0.5, 0.25))
    assert b.volume == pytest.approx(0.5) and b.inertia[0, 0] == pytest.approx(0.5 * (0.25 + 0.0625) / 3)
    b3 = Box((0.5, 0.25, 0.1))
    np.testing.assert_allclose(np.diag(b3.inertia), 0.1 / 3 * np.array([0.0725, 0.26, 0.3125]))
    assert b3.bounding_radius == pytest.approx(np.sqrt(0.25 + 0.0625 + 0.01))
    assert b3.inside(np.array([[0.49, -0.24, 0.09], [0.0, 0.0, 0.11]])).tolist() == [True, False]


def test_cylinder_closed_forms_and_support():
    """Volume and inertia against the lattice moments of the same inside test (an ImplicitShape);
    support points lie on the surface and maximise d . x over sampled inside points."""
    c = Cylinder(0.1, 0.5)
    lattice = ImplicitShape(c.inside, dim=3, extent=0.26, kind="inside", resolution=200)
    assert c.volume == pytest.approx(np.pi * 0.01 * 0.5) == pytest.approx(lattice.volume, rel=5e-3)
    np.testing.assert_allclose(c.inertia, lattice.inertia, rtol=1e-2, atol=1e-9)
    assert c.bounding_radius == pytest.approx(np.hypot(0.1, 0.25))
    rng = np.random.default_rng(1)
    d = rng.normal(size=(50, 3))
    s = c.support(d)
    np.testing.assert_allclose(np.hypot(s[:, 0], s[:, 1]), 0.1)
    np.testing.assert_allclose(np.abs(s[:, 2]), 0.25)
    x = rng.uniform(-0.3, 0.3, (20000, 3))
    x = x[c.inside(x)]
    assert np.all(np.einsum("kd,kd->k", d, s) >= (d @ x.T).max(axis=1) - 1e-12)
    with pytest.raises(ValueError, match="positive"):
        Cylinder(0.1, 0.0)


def test_implicit_shape_moments_converge_to_exact():
    """A shifted disk given as a signed distance: centre of mass found, area and inertia within
    the midpoint rule's error; the inside test works relative to the centre of mass."""
    r, c = 0.2, np.array([0.05, -0.03])
    disk = ImplicitShape(lambda x: np.linalg.norm(x - c, axis=1) - r, dim=2, extent=0.3)
    np.testing.assert_allclose(disk.centre_of_mass, c, atol=0.1 * 0.6 / 800)  # a tenth of the lattice step
    assert disk.volume == pytest.approx(Ball(r).volume, rel=1e-4)
    assert disk.inertia[0, 0] == pytest.approx(Ball(r).inertia[0, 0], rel=1e-3)
    assert disk.inside(np.array([[0.19, 0.0], [0.21, 0.0]])).tolist() == [True, False]
    assert disk.bounding_radius >= r
    sphere = ImplicitShape(lambda x: (x**2).sum(axis=1) <= r**2, dim=3, extent=0.25, kind="inside")
    assert sphere.volume == pytest.approx(Ball(r, 3).volume, rel=3e-3)
    np.testing.assert_allclose(sphere.inertia, Ball(r, 3).inertia, rtol=1e-2, atol=1e-9)


def test_implicit_shape_errors():
    with pytest.raises(ValueError, match="no point inside"):
        ImplicitShape(lambda x: np.ones(len(x)), dim=2, extent=1.0)
    with pytest.raises(ValueError, match="one value per point"):
        ImplicitShape(lambda x: np.ones((len(x), 2)), dim=2, extent=1.0)


def test_triangulated_box_is_exact():
    v, t = box_surface((0.5, 0.25, 0.1), centre=(1.0, 2.0, 3.0))
    s = TriangulatedSurface(v, t)
    ref = Box((0.5, 0.25, 0.1))
    np.testing.assert_allclose(s.centre_of_mass, [1.0, 2.0, 3.0], atol=1e-14)
    assert s.volume == pytest.approx(ref.volume, rel=1e-13)
    np.testing.assert_allclose(s.inertia, ref.inertia, atol=1e-14)
    rng = np.random.default_rng(0)
    x = rng.uniform(-0.6, 0.6, (500, 3))
    np.testing.assert_array_equal(s.inside(x), ref.inside(x))
    # an inward-oriented copy is flipped, not rejected
    s2 = TriangulatedSurface(v, t[:, ::-1])
    assert s2.volume == pytest.approx(ref.volume)


def test_icosphere_converges_to_sphere():
    v, t = icosphere(3)
    s = TriangulatedSurface(0.5 * v, t)
    ball = Ball(0.5, 3)
    assert s.volume == pytest.approx(ball.volume, rel=1e-2)
    np.testing.assert_allclose(s.inertia, ball.inertia, rtol=2e-2, atol=1e-12)
    rng = np.random.default_rng(1)
    x = rng.uniform(-0.6, 0.6, (400, 3))
    r = np.linalg.norm(x, axis=1)
    clear = (r < 0.48) | (r > 0.5)
    np.testing.assert_array_equal(s.inside(x)[clear], ball.inside(x)[clear])


def test_winding_kernel_matches_numpy():
    v, t = icosphere(1)
    x = np.random.default_rng(2).uniform(-1.5, 1.5, (50, 3))
    np.testing.assert_allclose(_kernels.winding_number(x, v, t), winding_numpy(x, v, t), atol=1e-12)


def test_surface_file_round_trip(tmp_path):
    meshio = pytest.importorskip("meshio")
    v, t = icosphere(2)
    path = tmp_path / "sphere.stl"
    meshio.write(path, meshio.Mesh(v * 10.0, [("triangle", t)]), binary=True)  # millimetres
    s = TriangulatedSurface.from_file(path, scale=1e-3)
    ref = TriangulatedSurface(v * 1e-2, t)
    assert s.volume == pytest.approx(ref.volume, rel=1e-6)
    assert s.bounding_radius == pytest.approx(1e-2, rel=1e-6)


def test_open_or_inconsistent_surface_is_refused():
    v, t = box_surface((1, 1, 1))
    with pytest.raises(ValueError, match="not closed"):
        TriangulatedSurface(v, t[:-1])
    bad = t.copy()
    bad[0] = bad[0, ::-1]
    with pytest.raises(ValueError, match="consistently oriented"):
        TriangulatedSurface(v, bad)
