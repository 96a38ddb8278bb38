"""Manufactured divergence-free solutions for the convergence tests (exact Laplacian -k pi^2 u)."""
import numpy as np

PI = np.pi


class Manufactured2D:
    """u = (sin px cos py, -cos px sin py), p = sin px sin py on any box; Laplace u = -2 pi^2 u."""

    dim = 2
    k = 2

    @staticmethod
    def u(x):
        sx, cx = np.sin(PI * x[:, 0]), np.cos(PI * x[:, 0])
        sy, cy = np.sin(PI * x[:, 1]), np.cos(PI * x[:, 1])
        return np.stack([sx * cy, -cx * sy], axis=1)

    @staticmethod
    def grad(x):
        sx, cx = np.sin(PI * x[:, 0]), np.cos(PI * x[:, 0])
        sy, cy = np.sin(PI * x[:, 1]), np.cos(PI * x[:, 1])
        g = np.empty((x.shape[0], 2, 2))
        g[:, 0, 0] = PI * cx * cy
        g[:, 0, 1] = -PI * sx * sy
        g[:, 1, 0] = PI * sx * sy
        g[:, 1, 1] = -PI * cx * cy
        return g

    @staticmethod
    def p(x):
        return np.sin(PI * x[:, 0]) * np.sin(PI * x[:, 1])

    @staticmethod
    def grad_p(x):
        return PI * np.stack([np.cos(PI * x[:, 0]) * np.sin(PI * x[:, 1]),
                              np.sin(PI * x[:, 0]) * np.cos(PI * x[:, 1])], axis=1)


class Manufactured3D:
    """u = (s c c, c s c, -2 c c s) (s = sin pi., c = cos pi.), p = s s s; Laplace u = -3 pi^2 u."""

    dim = 3
    k = 3

    @staticmethod
    def _sc(x):
        return np.sin(PI * x), np.cos(PI * x)

    @classmethod
    def u(cls, x):
        (sx, sy, sz), (cx, cy, cz) = cls._sc(x.T)
        return np.stack([sx * cy * cz, cx * sy * cz, -2 * cx * cy * sz], axis=1)

    @classmethod
    def grad(cls, x):
        (sx, sy, sz), (cx, cy, cz) = cls._sc(x.T)
        g = np.empty((x.shape[0], 3, 3))
        g[:, 0] = PI * np.stack([cx * cy * cz, -sx * sy * cz, -sx * cy * sz], axis=1)
        g[:, 1] = PI * np.stack([-sx * sy * cz, cx * cy * cz, -cx * sy * sz], axis=1)
        g[:, 2] = PI * np.stack([2 * sx * cy * sz, 2 * cx * sy * sz, -2 * cx * cy * cz], axis=1)
        return g

    @classmethod
    def p(cls, x):
        (sx, sy, sz), _ = cls._sc(x.T)
        return sx * sy * sz

    @classmethod
    def grad_p(cls, x):
        (sx, sy, sz), (cx, cy, cz) = cls._sc(x.T)
        return PI * np.stack([cx * sy * sz, sx * cy * sz, sx * sy * cz], axis=1)


def body_force(sol, mu, rho, convection):
    """f = -mu Laplace u + grad p + rho (u . grad) u for the manufactured solution."""
    def f(x, t=0.0):
        out = sol.k * PI ** 2 * mu * sol.u(x) + sol.grad_p(x)
        if convection:
            out += rho * np.einsum("nik,nk->ni", sol.grad(x), sol.u(x))
        return out
    return f


def fitted_order(h, err):
    """Least-squares slope of log(err) against log(h)."""
    return float(np.polyfit(np.log(h), np.log(err), 1)[0])
