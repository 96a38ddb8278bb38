"""Flexible GMRES (Saad 1993) with right preconditioning, for variable (multigrid) preconditioners."""
from __future__ import annotations

import sys
from typing import Callable

import numpy as np


def array_module(a):
    """The array module of ``a``: ``cupy`` for a CuPy array (imported already where one exists),
    else ``numpy``."""
    return sys.modules["cupy"] if type(a).__module__.startswith("cupy") else np


def fgmres(apply_A: Callable, precondition: Callable, b: np.ndarray, x0: np.ndarray, rtol: float,
           max_iterations: int, restart: int = 40, project: Callable | None = None,
           augment: np.ndarray | None = None, inner: Callable | None = None):
    """Solve ``A x = b`` to ``|b - A x| <= rtol |b - A x0|``.

    Parameters
    ----------
    apply_A, precondition : (n,) -> (n,) float64
    project : optional, applied in place to every preconditioned vector (e.g. removing a null
        space component of a singular but consistent system)
    augment : optional (n,) float64 ``e``: solve ``A x + lam e = b`` for ``x`` and a scalar
        ``lam`` instead, for a singular ``A`` whose range ``b`` may miss along ``e`` (the
        Lagrange multiplier of a bordered system ``[[A, e], [w^T, 0]]``, whose border row
        ``project`` enforces). Every restart cycle takes ``e`` as one extra search direction (no
        preconditioner application, not counted in ``iterations``); ``x`` is returned, ``lam``
        dropped, and the residuals are those of ``A x + lam e = b``.
    inner : optional ``(x, y) -> float``, the inner product (default ``x @ y``): a distributed
        vector's sum over the unknowns each process owns
        (:meth:`fbmflow.parallel.blocks.BlockPartition.dot`)

    The vectors may be CuPy arrays (a device solver's, :mod:`fbmflow.gpu`): the Krylov basis is
    then held on the device, the small Hessenberg problem on the host.

    Returns
    -------
    x : (n,) float64
    residuals : list of float, the true residual norm at each restart and the estimated one after
        every iteration
    iterations : int
    """
    xp = array_module(b)
    if inner is None:
        def inner(v, w):
            return float(xp.dot(v, w))

        def norm(v):
            return float(xp.linalg.norm(v))
    else:
        def norm(v):
            return np.sqrt(inner(v, v))
    x = x0.copy()
    lam = 0.0
    r = b - apply_A(x)
    beta = float(norm(r))
    residuals = [beta]
    target = rtol * beta
    its = 0
    aug = int(augment is not None)
    while beta > target and its < max_iterations:
        m = min(restart, max_iterations - its) + aug
        n = b.size
        V = xp.zeros((m + 1, n))
        Z = xp.zeros((m, n))
        H = np.zeros((m + 1, m))
        cs, sn = np.zeros(m), np.zeros(m)
        g = np.zeros(m + 1)
        g[0] = beta
        V[0] = r / beta
        k_done = 0
        for k in range(m):
            if aug and k == 0:  # the direction of lam: A-image e, no preconditioning
                w = augment.astype(float)
            else:  # V[1] of an augmented cycle is e's direction, which needs no preconditioning
                z = precondition(V[0 if aug and k == 1 else k])
                if project is not None:
                    project(z)
                Z[k] = z
                w = apply_A(z)
                its += 1
            for j in range(k + 1):  # modified Gram–Schmidt
                H[j, k] = inner(w, V[j])
                w -= H[j, k] * V[j]
            H[k + 1, k] = norm(w)
            if H[k + 1, k] > 0:
                V[k + 1] = w / H[k + 1, k]
            for j in range(k):  # apply previous Givens rotations
                H[j, k], H[j + 1, k] = (cs[j] * H[j, k] + sn[j] * H[j + 1, k],
                                        -sn[j] * H[j, k] + cs[j] * H[j + 1, k])
            denom = np.hypot(H[k, k], H[k + 1, k])
            cs[k], sn[k] = (1.0, 0.0) if denom == 0 else (H[k, k] / denom, H[k + 1, k] / denom)
            H[k, k] = cs[k] * H[k, k] + sn[k] * H[k + 1, k]
            H[k + 1, k] = 0.0
            g[k], g[k + 1] = cs[k] * g[k], -sn[k] * g[k]
            k_done = k + 1
            residuals.append(abs(g[k + 1]))
            if abs(g[k + 1]) <= target:
                break
        y = np.linalg.solve(np.triu(H[:k_done, :k_done]), g[:k_done]) if k_done else np.zeros(0)
        x += xp.asarray(y[aug:]) @ Z[aug:k_done]
        if aug and k_done:
            lam += y[0]
        r = b - apply_A(x) - (lam * augment if aug else 0.0)
        beta = float(norm(r))
        residuals.append(beta)
    return x, residuals, its
