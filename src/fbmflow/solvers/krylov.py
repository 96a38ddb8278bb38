"""Flexible GMRES (Saad 1993) with right preconditioning, for variable (multigrid) preconditioners."""
from __future__ import annotations

from typing import Callable

import numpy as np


def fgmres(apply_A: Callable, precondition: Callable, b: np.ndarray, x0: np.ndarray, rtol: float,
           max_iterations: int, restart: int = 40, project: Callable | None = None):
    """Solve ``A x = b`` to ``|b - A x| <= rtol |b - A x0|``.

    Parameters
    ----------
    apply_A, precondition : (n,) -> (n,) float64
    project : optional, applied in place to every preconditioned vector (e.g. removing a null
        space component of a singular but consistent system)

    Returns
    -------
    x : (n,) float64
    residuals : list of float, the true residual norm at each restart and the estimated one after
        every iteration
    iterations : int
    """
    x = x0.copy()
    r = b - apply_A(x)
    beta = float(np.linalg.norm(r))
    residuals = [beta]
    target = rtol * beta
    its = 0
    while beta > target and its < max_iterations:
        m = min(restart, max_iterations - its)
        n = b.size
        V = np.zeros((m + 1, n))
        Z = np.zeros((m, n))
        H = np.zeros((m + 1, m))
        cs, sn = np.zeros(m), np.zeros(m)
        g = np.zeros(m + 1)
        g[0] = beta
        V[0] = r / beta
        k_done = 0
        for k in range(m):
            z = precondition(V[k])
            if project is not None:
                project(z)
            Z[k] = z
            w = apply_A(z)
            for j in range(k + 1):  # modified Gram–Schmidt
                H[j, k] = w @ V[j]
                w -= H[j, k] * V[j]
            H[k + 1, k] = np.linalg.norm(w)
            if H[k + 1, k] > 0:
                V[k + 1] = w / H[k + 1, k]
            for j in range(k):  # apply previous Givens rotations
                H[j, k], H[j + 1, k] = cs[j] * H[j, k] + sn[j] * H[j + 1, k], -sn[j] * H[j, k] + cs[j] * H[j + 1, k]
            denom = np.hypot(H[k, k], H[k + 1, k])
            cs[k], sn[k] = (1.0, 0.0) if denom == 0 else (H[k, k] / denom, H[k + 1, k] / denom)
            H[k, k] = cs[k] * H[k, k] + sn[k] * H[k + 1, k]
            H[k + 1, k] = 0.0
            g[k], g[k + 1] = cs[k] * g[k], -sn[k] * g[k]
            its += 1
            k_done = k + 1
            residuals.append(abs(g[k + 1]))
            if abs(g[k + 1]) <= target:
                break
        y = np.linalg.solve(np.triu(H[:k_done, :k_done]), g[:k_done]) if k_done else np.zeros(0)
        x += y @ Z[:k_done]
        r = b - apply_A(x)
        beta = float(np.linalg.norm(r))
        residuals.append(beta)
    return x, residuals, its
