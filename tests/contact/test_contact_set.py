"""Contact solver without fluid: collisions, the cradle, sticking, rolling, a stack and a pile."""
import numpy as np
import pytest

from fbmflow.contact import ContactSet, Planes
from fbmflow.contact.broadphase import brute_force_pairs
from fbmflow.particles import Ball, Box, Particles


def _run(cs, p, acc, h, steps):
    ang = np.zeros(p.n) if p.dim == 2 else np.zeros((p.n, 3))
    for _ in range(steps):
        p, report = cs.substep(p, acc, ang, h)
    return p, report


def _momentum_energy(p):
    inertia = p.inertia_world()
    w = np.reshape(p.angular_velocity, (p.n, -1))
    rot = 0.5 * np.einsum("ni,nij,nj->", w, inertia, w)
    momentum = (p.mass[:, None] * p.velocity).sum(axis=0)
    return momentum, 0.5 * (p.mass * (p.velocity**2).sum(axis=1)).sum() + rot


@pytest.mark.parametrize("offset", [0.0, 0.4])
def test_elastic_pair_conserves_momentum_and_energy(offset):
    """Head-on (offset 0) and oblique collision of unequal spheres, restitution 1."""
    p = Particles.at_rest([Ball(1.0, 3), Ball(0.5, 3)], [1.0, 3.0], [[0.0, 0.0, 0.0], [3.0, offset, 0.0]])
    p.velocity[0] = [1.0, 0.0, 0.0]
    p.velocity[1] = [-0.5, 0.0, 0.2 if offset else 0.0]
    P0, E0 = _momentum_energy(p)
    q, _ = _run(ContactSet(restitution=1.0), p, np.zeros((2, 3)), 0.01, 300)
    P1, E1 = _momentum_energy(q)
    assert np.abs(P1 - P0).max() <= 1e-10 and abs(E1 - E0) <= 1e-10 * E0
    assert q.velocity[1, 0] > 0.0  # the light sphere bounced back
    if offset == 0.0:  # 1D elastic formulas
        m1, m2 = p.mass
        assert q.velocity[0, 0] == pytest.approx(((m1 - m2) * 1.0 + 2 * m2 * -0.5) / (m1 + m2), abs=1e-12)


def test_single_contact_gives_the_pair_impulse_formula():
    """lambda = -(1 + e) u_n / k with k = 1/m_1 + 1/m_2 for spheres."""
    e = 0.6
    p = Particles.at_rest([Ball(0.5, 2), Ball(0.5, 2)], [1.0, 2.0], [[0.0, 0.0], [1.02, 0.0]])
    p.velocity[0] = [3.0, 0.0]
    q, _ = _run(ContactSet(restitution=e), p, np.zeros((2, 2)), 0.01, 3)
    m1, m2 = p.mass
    lam = (1 + e) * 3.0 / (1 / m1 + 1 / m2)
    assert q.velocity[0, 0] == pytest.approx(3.0 - lam / m1, abs=1e-12)
    assert q.velocity[1, 0] == pytest.approx(lam / m2, abs=1e-12)


def test_newtons_cradle_passes_the_momentum_ball_by_ball():
    n = 5
    p = Particles.at_rest([Ball(0.5, 2)] * n, 1.0, [[k * 1.01, 0.0] for k in range(n)])
    p.position[0, 0] -= 0.5
    p.velocity[0] = [1.0, 0.0]
    q, _ = _run(ContactSet(restitution=1.0), p, np.zeros((n, 2)), 0.005, 400)
    assert np.allclose(q.velocity[:, 0], [0, 0, 0, 0, 1.0], atol=1e-12)
    assert np.all(np.diff(q.position[:, 0]) > 1.0 - 1e-12)  # nobody overlaps


def test_inelastic_pair_sticks():
    p = Particles.at_rest([Ball(0.5, 3), Ball(0.5, 3)], [1.0, 4.0], [[0.0, 0.0, 0.0], [1.5, 0.0, 0.0]])
    p.velocity[0] = [2.0, 0.0, 0.0]
    P0, _ = _momentum_energy(p)
    q, _ = _run(ContactSet(restitution=0.0), p, np.zeros((2, 3)), 0.01, 200)
    assert q.velocity[0, 0] == pytest.approx(q.velocity[1, 0], abs=1e-12)
    assert np.allclose(_momentum_energy(q)[0], P0, atol=1e-12)
    gap = np.linalg.norm(q.position[1] - q.position[0]) - 1.0
    assert abs(gap) < 1e-12


def test_sliding_sphere_rolls_at_five_sevenths_with_friction():
    cs = ContactSet(Planes.box([-50, -5, 0], [50, 5, 10]), friction=0.3)
    p = Particles.at_rest([Ball(0.5, 3)], 1.0, [[0.0, 0.0, 0.5]])
    p.velocity[0] = [2.0, 0.0, 0.0]
    q, _ = _run(cs, p, np.array([[0.0, 0.0, -10.0]]), 0.005, 300)
    assert q.velocity[0, 0] == pytest.approx(5 / 7 * 2.0, rel=1e-10)
    assert q.angular_velocity[0, 1] * 0.5 == pytest.approx(q.velocity[0, 0], rel=1e-10)
    assert q.position[0, 2] == pytest.approx(0.5, abs=1e-10)  # stays on the floor


def test_box_lands_flat_and_fixed_particles_do_not_move():
    cs = ContactSet(Planes.box([-5, 0], [5, 5], faces=[(1, 0)]), friction=0.5)
    p = Particles.at_rest([Box((0.4, 0.1)), Ball(0.2)], 1.0, [[0.0, 1.0], [0.3, 0.2]])
    p.orientation[0] = 0.05
    p.fixed[1] = True
    q, _ = _run(cs, p, np.tile([0.0, -10.0], (2, 1)), 0.002, 1500)
    assert np.array_equal(q.position[1], p.position[1])
    assert np.abs(q.velocity[0]).max() < 1e-3  # came to rest on the ball and the floor


def test_pgs_residual_decreases_monotonically_on_a_stack():
    n, R = 10, 0.5
    p = Particles.at_rest([Ball(R, 3)] * n, 1.0, [[0.0, 0.0, R + 2 * R * k] for k in range(n)])
    cs = ContactSet(Planes.box([-5, -5, 0], [5, 5, 100]), iterations=300, tol=0.0)
    _, report = _run(cs, p, np.tile([0.0, 0.0, -10.0], (n, 1)), 0.01, 1)
    h = report.history
    assert len(h) == 300 and np.all(np.diff(h) <= 0.0) and h[-1] < 0.01 * h[0]


@pytest.mark.slow
def test_pile_of_1000_spheres_comes_to_rest_without_overlap():
    N, R = 1000, 0.01
    rng = np.random.default_rng(1)
    k = np.arange(N)
    X = np.column_stack([(k % 10 + 0.5) * 2.2 * R, ((k // 10) % 10 + 0.5) * 2.2 * R,
                         (k // 100 + 0.5) * 2.2 * R + R])
    X[:, :2] += rng.uniform(-0.05 * R, 0.05 * R, (N, 2))
    p = Particles.at_rest([Ball(R, 3)] * N, 2500.0, X)
    p.velocity = rng.normal(0.0, 0.05, (N, 3))
    L = 22 * R
    cs = ContactSet(Planes.box([0, 0, 0], [L, L, 1.0]), restitution=0.3, friction=0.5, iterations=30)
    q, _ = _run(cs, p, np.tile([0.0, 0.0, -9.81], (N, 1)), 2e-3, 700)
    pairs = brute_force_pairs(q.position, np.full(N, R))
    d = np.linalg.norm(q.position[pairs[:, 0]] - q.position[pairs[:, 1]], axis=1)
    overlap = max((2 * R - d).max(), (R - q.position[:, 2]).max(), (R - q.position[:, :2]).max(),
                  (q.position[:, :2] + R - L).max())
    assert overlap < 0.01 * R
    assert np.linalg.norm(q.velocity, axis=1).max() < 0.01  # m/s: at rest (free fall gains 0.02 per step)
    assert q.position[:, 2].max() < 0.2  # collapsed from 0.22 m into a pile


def test_warm_start_state_round_trip_and_validation():
    cs = ContactSet(Planes.box([-5, 0], [5, 5]), friction=0.2)
    p = Particles.at_rest([Ball(0.5)] * 2, 1.0, [[0.0, 0.5], [1.0, 0.5]])
    _run(cs, p, np.tile([0.0, -10.0], (2, 1)), 0.01, 3)
    state = cs.state()
    assert len(state["keys"]) == 3 and np.all(state["normal"][[0, 2]] > 0)  # floor contacts
    other = ContactSet(Planes.box([-5, 0], [5, 5]), friction=0.2)
    other.set_state(state)
    a, _ = _run(cs, p, np.tile([0.0, -10.0], (2, 1)), 0.01, 1)
    b, _ = _run(other, p, np.tile([0.0, -10.0], (2, 1)), 0.01, 1)
    assert np.array_equal(a.velocity, b.velocity)
    bad = dict(state, keys=state["keys"][::-1])
    with pytest.raises(ValueError, match="sorted"):
        other.set_state(bad)


@pytest.mark.parametrize("kwargs, match", [({"restitution": 1.5}, "restitution"),
                                           ({"friction": -1.0}, "non-negative"),
                                           ({"iterations": 0}, "iterations"),
                                           ({"broadphase": "kd"}, "broadphase")])
def test_bad_settings_are_refused(kwargs, match):
    with pytest.raises(ValueError, match=match):
        ContactSet(**kwargs)


@pytest.mark.parametrize("dim", [2, 3])
def test_lubrication_slows_an_approach_as_the_film_law_says(dim):
    """Two equal balls approaching head-on with only the film force: the relative velocity as a
    function of the gap follows m* du/dg = -c(g) (m* the reduced mass), integrated in closed form
    (3D) or by quadrature (2D)."""
    from scipy.integrate import quad

    from fbmflow.contact import Lubrication

    R, mu, delta = 0.5, 0.05, 0.5
    lub = Lubrication(mu, delta, 1e-6)
    p = Particles.at_rest([Ball(R, dim)] * 2, 1.0, np.array([[0.0] * dim, [1.0 + 0.4] + [0.0] * (dim - 1)]))
    u0 = 1.0
    p.velocity[0, 0], p.velocity[1, 0] = u0 / 2, -u0 / 2
    cs = ContactSet(lubrication=lub)
    m_red = p.mass[0] / 2
    zero = np.zeros(2) if dim == 2 else np.zeros((2, 3))
    for _ in range(4000):
        p, _ = cs.substep(p, np.zeros((2, dim)), zero, 2e-4)
        gap = p.position[1, 0] - p.position[0, 0] - 2 * R
        u = p.velocity[0, 0] - p.velocity[1, 0]  # closing speed
        if gap < 0.05:
            break
    assert 0.0 < gap < 0.05
    Rs = R / 2
    def c(g):
        return lub.coefficient(np.array([g]), np.array([R]), np.array([R]), dim)[0]

    expected = u0 - quad(c, gap, 0.4, limit=200)[0] / m_red
    assert expected > 0.0 and u == pytest.approx(expected, rel=0.01)
    if dim == 3:  # closed form of the same integral: c = 6 pi mu [Rs^2 (1/g - 1/delta) + l ln(delta/g)]
        arm = 9 * R / 40  # Jeffrey & Onishi's log term of equal spheres

        def log_part(g):
            return g * np.log(delta / g) + g

        closed = u0 - 6 * np.pi * mu * (Rs**2 * (np.log(0.4 / gap) - (0.4 - gap) / delta)
                                        + arm * (log_part(0.4) - log_part(gap))) / m_red
        assert u == pytest.approx(closed, rel=0.01)


def test_lubrication_stops_a_slow_approach_before_contact():
    from fbmflow.contact import Lubrication

    p = Particles.at_rest([Ball(0.5, 3)] * 2, 1.0, [[0.0, 0.0, 0.0], [1.2, 0.0, 0.0]])
    p.velocity[0, 0] = 0.1
    cs = ContactSet(lubrication=Lubrication(0.05, 0.5, 1e-6))
    q, _ = _run(cs, p, np.zeros((2, 3)), 1e-3, 3000)
    gap = q.position[1, 0] - q.position[0, 0] - 1.0
    assert 0.0 < gap < 0.2 and abs(q.velocity[0, 0] - q.velocity[1, 0]) < 0.005  # from 0.1


@pytest.mark.parametrize("dim", [2, 3])
def test_a_pair_across_a_periodic_side_collides_as_the_same_pair_inside_the_box(dim):
    """Two balls meeting obliquely through the periodic side x = 0 / 4, with restitution and
    friction (so the contact point's arms matter), move exactly as the same pair shifted into the
    middle of the box, which meets without the images."""
    periods = [4.0, 0.0] + [0.0] * (dim - 2)
    lower = [0.0] * dim

    def pair(x0):
        X = np.zeros((2, dim))
        X[:, 0], X[:, 1] = [x0, x0 - 0.62], [1.0, 1.3]
        p = Particles.at_rest([Ball(0.25, dim), Ball(0.2, dim)], [1.0, 2.0], X)
        p.velocity[0, 0], p.velocity[1, 0] = -1.0, 0.5
        return p
    results = []
    for x0 in (0.2, 2.2):  # across the side (the second ball at x = 3.58), and inside
        p = pair(x0)
        p.position[:, 0] = np.mod(p.position[:, 0], 4.0)
        cs = ContactSet(restitution=0.5, friction=0.3, periods=periods, origin=lower)
        q, report = _run(cs, p, np.zeros((2, dim)), 0.01, 40)
        assert report.max_overlap <= 1e-12
        results.append(q)
    across, inside = results
    assert abs(inside.velocity[0, 0] + 1.0) > 0.1  # they did collide
    assert np.allclose(across.velocity, inside.velocity, atol=1e-12)
    assert np.allclose(across.angular_velocity, inside.angular_velocity, atol=1e-12)
    moved = across.position - inside.position
    moved[:, 0] += 2.0  # the pairs started 2 apart along x: the same positions up to the period
    moved[:, 0] -= 4.0 * np.round(moved[:, 0] / 4.0)
    assert np.allclose(moved, 0.0, atol=1e-12)


def test_periodic_candidates_are_the_nearest_image_pairs():
    """Against brute force on the nearest-image distances: random spheres in a box periodic
    along x and z, some outside it (centres drift out during contact sub-steps)."""
    from fbmflow.contact.broadphase import candidate_pairs
    rng = np.random.default_rng(3)
    L = np.array([3.0, 0.0, 2.0])
    X = rng.uniform([-0.5, 0.0, 0.0], [3.5, 3.0, 2.0], size=(200, 3))
    R = rng.uniform(0.05, 0.15, size=200)
    margin = 0.05
    for method in ("grid", "brute-force", "hierarchical-grid"):
        pairs = candidate_pairs(X, R, margin, method, periods=L, origin=np.zeros(3))
        diff = X[:, None, :] - X[None, :, :]
        diff -= L * np.round(diff / np.where(L > 0, L, 1.0))
        close = np.linalg.norm(diff, axis=2) <= R[:, None] + R[None, :] + margin
        expected = np.argwhere(np.triu(close, 1))
        assert np.array_equal(pairs, expected), method
    with pytest.raises(ValueError, match="shorter than two of the largest"):
        candidate_pairs(X, R, margin, periods=np.array([0.5, 0.0, 0.0]))


def test_row_masses_kernel_matches_numpy():
    """The kernel's angular parts and effective inverse masses against the NumPy formulas
    (cross products, ``I^-1 a``, ``k = 1/m_i |d|^2 + a_i . b_i + ...``) on random contacts,
    a third of them with a plane (``j < 0``)."""
    from fbmflow.contact import _kernels
    rng = np.random.default_rng(5)
    n, m = 7, 40
    ci = rng.integers(0, n, m)
    cj = np.where(rng.random(m) < 1 / 3, -1, rng.integers(0, n, m))
    D = rng.standard_normal((m, 3, 3))
    ri, rj = rng.standard_normal((m, 3)), rng.standard_normal((m, 3))
    inv_m = rng.uniform(0.5, 2.0, n)
    S = rng.standard_normal((n, 3, 3))
    inv_I = S @ S.transpose(0, 2, 1) + np.eye(3)
    Ai, Aj, Bi, Bj, K = _kernels.row_masses(ci, cj, D, ri, rj, inv_m, inv_I)
    wall = (cj < 0)[:, None]
    jj = np.maximum(cj, 0)
    ref_Ai = np.cross(ri[:, None, :], D)
    ref_Aj = np.where(wall[:, :, None], 0.0, np.cross(rj[:, None, :], D))
    ref_Bi = np.einsum("mab,mqb->mqa", inv_I[ci], ref_Ai)
    ref_Bj = np.einsum("mab,mqb->mqa", inv_I[jj], ref_Aj)
    dd = np.einsum("mqa,mqa->mq", D, D)
    ref_K = (inv_m[ci][:, None] * dd + np.einsum("mqa,mqa->mq", ref_Ai, ref_Bi)
             + np.where(wall, 0.0, inv_m[jj][:, None] * dd + np.einsum("mqa,mqa->mq", ref_Aj, ref_Bj)))
    for got, ref in ((Ai, ref_Ai), (Aj, ref_Aj), (Bi, ref_Bi), (Bj, ref_Bj), (K, ref_K)):
        np.testing.assert_allclose(got, ref, rtol=1e-13, atol=1e-13)


@pytest.mark.parametrize("periodic", [False, True])
def test_an_advance_with_its_pair_list_takes_the_substeps_one_by_one(periodic, monkeypatch):
    """200 disks falling and colliding in a box (periodic in x or walled), 40 sub-steps in one
    :meth:`ContactSet.advance`, whose sub-steps share a pair list (a broadphase every few
    sub-steps), against the same sub-steps called one by one with a broadphase each: the same
    contacts, impulses and states."""
    from fbmflow.contact import contact_set
    broadphases = []
    search = contact_set.candidate_pairs
    monkeypatch.setattr(contact_set, "candidate_pairs",
                        lambda *a, **k: broadphases.append(1) or search(*a, **k))
    N, R = 200, 0.01
    rng = np.random.default_rng(3)
    k = np.arange(N)
    X = np.column_stack([(k % 20 + 0.5) * 2.05 * R, (k // 20 + 0.5) * 2.05 * R + R])
    X += rng.uniform(-0.02 * R, 0.02 * R, X.shape)
    p = Particles.at_rest([Ball(R, 2)] * N, 2500.0, X)
    p.velocity = rng.normal(0.0, 0.3, (N, 2))
    L = 20 * 2.05 * R
    planes = Planes.box([0.0, 0.0], [L, 1.0], faces=[(1, 0), (1, 1)] if periodic else None)
    kwargs = dict(restitution=0.5, friction=0.3, skin=0.1 * R,
                  periods=[L, 0.0] if periodic else None, origin=[0.0, 0.0] if periodic else None)
    acc, alpha = np.tile([0.0, -9.81], (N, 1)), np.zeros(N)
    listed, single = ContactSet(planes, **kwargs), ContactSet(planes, **kwargs)
    q, report = listed.advance(p, acc, alpha, 0.02, substeps=40)
    assert 1 <= len(broadphases) <= 20
    r = p
    for _ in range(40):
        r, _ = single.substep(r, acc, alpha, 0.02 / 40)
    assert report.contacts > N  # many pairs in touch, some of them across the periodic side
    np.testing.assert_array_equal(listed.state()["keys"], single.state()["keys"])
    np.testing.assert_allclose(q.position, r.position, rtol=0, atol=1e-14)
    np.testing.assert_allclose(q.velocity, r.velocity, rtol=0, atol=1e-12)
