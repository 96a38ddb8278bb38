"""Evaluation of discrete Q2/P1disc fields: point sampling, integrals and error norms."""
from __future__ import annotations

from typing import Callable

import numpy as np

from ..mesh import StructuredMesh
from . import _kernels
from .elements import ElementQ1
from .quadrature import gauss_tensor
from .space import FlowSpace


def locate(mesh: StructuredMesh, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cell and reference coordinates of physical points on a tensor-product (uniform or
    rectilinear) mesh.

    Parameters
    ----------
    mesh : StructuredMesh
    points : (n, dim) float64 inside the box (the boundary included)

    Returns
    -------
    cells : (n,) int64
    xi : (n, dim) float64 in [-1, 1]^dim
    """
    axes = mesh.axis_coordinates
    if axes is None:
        raise NotImplementedError("point location on a deformed mesh is not implemented")
    points = np.atleast_2d(np.asarray(points, dtype=float))
    lower, upper = np.array(mesh.lower), np.array(mesh.upper)
    tol = 1e-9 * (upper - lower)
    if np.any(points < lower - tol) or np.any(points > upper + tol):
        raise ValueError("points outside the mesh box")
    idx = np.empty(points.shape, dtype=np.int64)
    xi = np.empty(points.shape)
    for d, a in enumerate(axes):  # one binary search per axis, all points at once
        k = np.clip(np.searchsorted(a, points[:, d], side="right") - 1, 0, a.size - 2)
        idx[:, d] = k
        xi[:, d] = 2.0 * (points[:, d] - a[k]) / (a[k + 1] - a[k]) - 1.0
    strides = np.cumprod((1,) + mesh.shape[:-1])
    return (idx * strides).sum(axis=1), xi


def sample_velocity(space: FlowSpace, u: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Velocity at physical points: u (dim * n_v,), points (n, dim) -> (n, dim) float64."""
    cells, xi = locate(space.mesh, points)
    phi, _ = space.V.element.tabulate(xi)  # (n, nl)
    uu = u.reshape(space.dim, space.n_v)
    return np.einsum("ina,na->ni", uu[:, space.V.cell_dofs[cells]], phi)


def sample_pressure(space: FlowSpace, p: np.ndarray, points: np.ndarray,
                    cells_at: np.ndarray | None = None) -> np.ndarray:
    """Pressure at physical points: p (n_p,), points (n, dim) -> (n,) float64.

    With ``cells_at (n, dim)`` the linear pressure of the cell containing ``cells_at[k]`` is
    evaluated at ``points[k]`` (extrapolation from a neighbouring cell, e.g. from the fluid side of
    a fictitious boundary).
    """
    cells, _ = locate(space.mesh, points if cells_at is None else cells_at)
    points = np.atleast_2d(points)
    psi = space.Q.element.tabulate(points, space.Q.centre[cells], space.Q.scale[cells])
    return np.einsum("nm,nm->n", p.reshape(-1, space.dim + 1)[cells], psi)


def node_integrals(space: FlowSpace) -> np.ndarray:
    """``int phi_a dx`` of every Q2 basis function over the mesh's cells, (n_v,) float64 (exact:
    the element's quadrature); on a slab of several processes' mesh, complete at the nodes of
    its owned cells."""
    weight = np.einsum("cq,qa->ca", space.detJw, space.phi)
    return np.bincount(space.V.cell_dofs.ravel(), weights=weight.ravel(), minlength=space.n_v)


def mean_velocity(space: FlowSpace, u: np.ndarray) -> np.ndarray:
    """Volume average of the velocity ``u (dim * n_v,)`` over the mesh, ``int u dx / |Omega|``,
    (dim,) float64 (exact for the Q2 field, :func:`node_integrals`). Inside fictitious particles
    ``u`` is their rigid motion, so with particles this is the mean velocity of the mixture: its
    volume flux per unit area."""
    w = node_integrals(space)
    return u.reshape(space.dim, space.n_v) @ w / w.sum()


def quadrature_fields(space: FlowSpace, u: np.ndarray, p: np.ndarray, n_quad: int = 5):
    """Fields at a Gauss rule of ``n_quad`` points per axis on every cell.

    Returns
    -------
    x : (n_cells, nq, dim) physical points
    detJw : (n_cells, nq) integration weights
    uh : (n_cells, nq, dim) velocity
    grad_uh : (n_cells, nq, dim, dim) ``d u_i / d x_k``
    ph : (n_cells, nq) pressure
    """
    mesh, d = space.mesh, space.dim
    pts, w = gauss_tensor(d, n_quad)
    phi, dphi = space.V.element.tabulate(pts)
    _, dN = ElementQ1(d).tabulate(pts)
    detJw, Jinv = _kernels.cell_geometry(mesh.cell_coordinates(), dN, w)
    x = mesh.map_to_physical(pts)
    uloc = u.reshape(d, space.n_v)[:, space.V.cell_dofs]  # (d, n_cells, nl)
    uh = np.einsum("ica,qa->cqi", uloc, phi)
    gref = np.einsum("ica,qal->cqil", uloc, dphi)
    grad = np.einsum("cqil,cqlk->cqik", gref, Jinv)
    psi = space.Q.element.tabulate(x, space.Q.centre[:, None, :], space.Q.scale[:, None, :])
    ph = np.einsum("cm,cqm->cq", p.reshape(-1, d + 1), psi)
    return x, detJw, uh, grad, ph


def error_norms(space: FlowSpace, u: np.ndarray, p: np.ndarray, u_exact: Callable,
                grad_exact: Callable, p_exact: Callable, mean_free_pressure: bool = True) -> dict:
    """L2 and H1-seminorm velocity errors and the L2 pressure error.

    ``u_exact(x) -> (n, dim)``, ``grad_exact(x) -> (n, dim, dim)`` with ``[i, k] = du_i/dx_k``,
    ``p_exact(x) -> (n,)`` for points ``x (n, dim)``. With ``mean_free_pressure`` both pressures
    are compared after removing their means. Returns dict with ``u_l2, u_h1, p_l2``.
    """
    x, wq, uh, gh, ph = quadrature_fields(space, u, p)
    xf = x.reshape(-1, space.dim)
    w = wq.ravel()
    eu = uh.reshape(-1, space.dim) - u_exact(xf)
    eg = gh.reshape(-1, space.dim, space.dim) - grad_exact(xf)
    pe = p_exact(xf)
    phf = ph.ravel()
    if mean_free_pressure:
        area = w.sum()
        pe = pe - (w @ pe) / area
        phf = phf - (w @ phf) / area
    return {"u_l2": float(np.sqrt(w @ (eu ** 2).sum(axis=1))),
            "u_h1": float(np.sqrt(w @ (eg ** 2).sum(axis=(1, 2)))),
            "p_l2": float(np.sqrt(w @ (phf - pe) ** 2))}
