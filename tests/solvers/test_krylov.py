import numpy as np

from fbmflow.solvers.krylov import fgmres


def _singular(n=40, seed=3):
    """A nonsymmetric matrix of rank n - 1 with left null vector ``psi``: (A, psi)."""
    rng = np.random.default_rng(seed)
    A = np.eye(n) * 4 + rng.standard_normal((n, n)) * 0.3
    psi = rng.standard_normal(n)
    A -= np.outer(psi, psi @ A) / (psi @ psi)  # psi^T A = 0
    return A, psi


def test_fgmres_matches_a_direct_solve():
    rng = np.random.default_rng(0)
    A = np.eye(30) * 3 + rng.standard_normal((30, 30)) * 0.2
    b = rng.standard_normal(30)
    x, res, its = fgmres(lambda v: A @ v, lambda v: v / 3, b, np.zeros(30), 1e-12, 100, restart=8)
    assert np.allclose(x, np.linalg.solve(A, b), atol=1e-10)
    assert res[-1] <= 1e-12 * res[0] * 1.01 and its <= 60


def test_fgmres_solves_for_the_border_multiplier():
    """``A x + lam e = b`` with ``b`` outside the range of a singular ``A``: the result satisfies
    it for some ``lam``, which is the bordered system's multiplier, ``psi.b / psi.e``; without
    ``augment`` the residual stalls at the inconsistent part."""
    A, psi = _singular()
    rng = np.random.default_rng(1)
    b, e = rng.standard_normal(40), rng.standard_normal(40)
    lam = (psi @ b) / (psi @ e)
    x, res, its = fgmres(lambda v: A @ v, lambda v: v / 4, b, np.zeros(40), 1e-10, 200, restart=10, augment=e)
    assert np.linalg.norm(b - lam * e - A @ x) <= 1e-8 * np.linalg.norm(b)
    _, plain, _ = fgmres(lambda v: A @ v, lambda v: v / 4, b, np.zeros(40), 1e-10, 200, restart=10)
    assert plain[-1] > 1e-3 * plain[0]
