"""The sharp fictitious boundary: the no-slip condition on the particle's surface itself.

With the nodal constraints (:func:`~fbmflow.coupling.indicator.rigid_body_constraints`) every node inside
a particle moves rigidly, and the discrete flow sees the particle's surface where the
constrained nodes end, up to a node spacing inside the true one: the particle is
hydrodynamically smaller, an error of first order in the mesh size. The sharp boundary changes
three things in the cells the surface cuts (cells with nodes inside and outside a particle):

1. **Ghost nodes.** The nodes of a particle in a cut cell (at depth ``a`` below the surface)
   carry the flow continued through the surface instead of the rigid motion: linear along the
   normal between the rigid velocity at the closest surface point ``x_b`` and the flow at the
   image point ``x_I = x_b + l n`` outside,

       u_G = (1 + a / l) U_b - (a / l) u_h(x_I),        U_b = U + omega x (x_b - X),

   ``l = max(a, h)`` with ``h`` the node spacing there, so that the weights stay within
   ``[-1, 2]``; ``u_h(x_I)`` is the Q2 field of the cell containing ``x_I`` (ghost nodes among
   its nodes make this a coupled linear system, solved with the flow: the ghost nodes' momentum
   equations are replaced, :class:`~fbmflow.fem.constraints.RowConstraints`). This is the
   image-point ghost-cell method of immersed boundaries (Tseng & Ferziger 2003, Mittal et al.
   2008) in finite element form. The flow's equations in the cut cells then see the smooth
   continuation of the flow, and the velocity meets the particle's on the true surface to
   second order.
2. **Continuity over the fluid part.** The continuation is not divergence-free inside the
   particle, so the cut cells' continuity equations are integrated over their part outside the
   particle only (a tensor Gauss rule of 8 points per axis with the shape's inside test;
   :class:`~fbmflow.fem.constraints.ContinuityRows`).
3. **Pressure continued from a fluid cell.** A cut cell's own pressure modes are seen only weakly
   by the few fluid velocities in it; left free they made the system nearly singular (measured,
   dfg-2d-1 Stokes flow at 4 cells per diameter: velocities 20 times the inflow). Each cut
   cell's P1disc pressure is therefore the linear pressure of a neighbouring fluid cell
   continued (P1disc is linear in physical coordinates), and its continuity equations join that
   cell's (:class:`~fbmflow.fem.constraints.PressureExtension`): cell agglomeration, as in
   unfitted discontinuous Galerkin methods.

Ghost nodes whose image point falls outside the domain (a particle at a wall) and cut cells
without a fluid cell within two cells keep the nodal treatment. Shapes need ``project``
(closest surface point and outward normal): balls, boxes, cylinders. Rows reach
:func:`reach_layers` cell layers (the halo a process's slab needs).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from ..fem.constraints import ContinuityRows, DirichletConstraints, PressureExtension, RowConstraints
from ..fem.dofmap import DofMap
from ..fem.functions import locate
from ..fem.quadrature import gauss_tensor
from ..fem.space import FlowSpace
from .indicator import periodic_offset

CUT_CELL_POINTS = 8  # Gauss points per axis of the cut cells' fluid-part continuity rows


@dataclass(frozen=True)
class GhostNodes:
    """Where the flow is continued through the particles' surfaces, for one particle state.

    Attributes
    ----------
    nodes : (n_g,) int64   ghost nodes (Q2 velocity nodes), sorted
    particle : (n_g,) int64   owner of each
    surface : (n_g, dim) float64   closest surface point ``x_b``, relative to the particle's
        centre (minimum image on periodic axes)
    weight : (n_g,) float64   ``1 + a / l``, the weight of the rigid velocity at ``x_b``
    matrix : (n_g, n_v) CSR   scalar constraint rows ``e_G + (a / l) phi(x_I)``
    beyond : (m,) int64   particle nodes of cut cells whose image point lies in the domain but
        off this mesh (one process's slab: their rows are the process's that holds the image)
    """

    nodes: np.ndarray
    particle: np.ndarray
    surface: np.ndarray
    weight: np.ndarray
    matrix: sp.csr_matrix
    beyond: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))

    @property
    def dim(self) -> int:
        return self.surface.shape[1]

    @property
    def dofs(self) -> np.ndarray:
        """Component-blocked velocity DOFs of the ghost nodes, (dim n_g,) sorted."""
        n_v = self.matrix.shape[1]
        return np.concatenate([c * n_v + self.nodes for c in range(self.dim)])

    def constraints(self, velocities: np.ndarray, angular: np.ndarray) -> RowConstraints:
        """Row constraints of every velocity component of the ghost nodes: ``C`` is the scalar
        rows repeated per component, ``g = (1 + a / l) U_b``."""
        value = self.weight[:, None] * _rigid_motion(self.surface, self.particle, velocities, angular)
        return RowConstraints(self.dofs, sp.block_diag([self.matrix] * self.dim, format="csr"),
                              value.T.ravel())

    def uncovered(self, V: DofMap, owner: np.ndarray, centres: np.ndarray, velocities: np.ndarray,
                  angular: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The ghost nodes that the particles have uncovered, with the velocity of the solid
        that covered them.

        ``owner (n_v,)`` is the node ownership of a later particle state (centres
        ``(n, dim)``, velocities ``(n, dim)``, ``angular`` as for
        :func:`~fbmflow.coupling.indicator.rigid_body_constraints`). A ghost node that ``owner`` puts in the
        fluid was inside its particle a step ago: the material there moved with the solid, at
        ``U + omega x (x - X)``. Its value in the flow, the continuation through the surface
        (far from that near a thin boundary layer, where the continuation extrapolates a steep
        slope), is no velocity of any material, and as the start of the next time step it would
        inject a spurious acceleration (measured: a disk at particle Reynolds number 145 on 4
        cells per diameter, Newton failing). Returns the component-blocked velocity DOFs
        (dim k,) int64 of the uncovered nodes and their rigid velocities (dim k,) float64.
        """
        out = owner[self.nodes] < 0
        nodes, part = self.nodes[out], self.particle[out]
        rel = periodic_offset(V, V.coordinates[nodes], np.asarray(centres, dtype=float)[part])
        value = _rigid_motion(rel, part, velocities, angular)
        return np.concatenate([c * V.n_dofs + nodes for c in range(self.dim)]), value.T.ravel()

    def liftings(self, free: np.ndarray) -> sp.csr_matrix:
        """How the constraint values ``g`` change with the particles' generalised velocities:
        (dim n_v, k) CSR with rows at :attr:`dofs`, one column per True entry of
        ``free (n_particles, r)`` in the column order of :func:`~fbmflow.coupling.indicator.rigid_liftings`
        (``r = 3`` in 2D: ``U_x, U_y, omega_z``; 6 in 3D)."""
        n, r = free.shape
        d, n_g = self.dim, len(self.nodes)
        column = np.full(free.shape, -1, dtype=np.int64)
        column[free] = np.arange(int(free.sum()))
        rows, cols, vals = [], [], []
        for b in range(r):  # unit generalised velocity b of every particle at once
            v = np.zeros((n, d))
            w = np.zeros(n) if d == 2 else np.zeros((n, 3))
            if b < d:
                v[:, b] = 1.0
            elif d == 2:
                w[:] = 1.0
            else:
                w[:, b - d] = 1.0
            motion = self.weight[:, None] * _rigid_motion(self.surface, self.particle, v, w)
            sel = np.flatnonzero(free[self.particle, b])
            for c in range(d):
                rows.append(c * n_g + sel)
                cols.append(column[self.particle[sel], b])
                vals.append(motion[sel, c])
        local = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                              shape=(d * n_g, int(free.sum())))
        embed = sp.csr_matrix((np.ones(d * n_g), (self.dofs, np.arange(d * n_g))),
                              shape=(d * self.matrix.shape[1], d * n_g))
        return (embed @ local).tocsr()


@dataclass(frozen=True)
class SharpBoundary:
    """What the sharp boundary changes in the discrete problem for one particle state."""

    ghosts: GhostNodes
    continuity: ContinuityRows
    extension: PressureExtension

    def constraints(self, rigid: DirichletConstraints, velocities: np.ndarray,
                    angular: np.ndarray) -> DirichletConstraints:
        """``rigid`` (the particles' nodal constraints; their values are the first guess on the
        ghost nodes) with the ghost nodes' rows, the cut cells' continuity rows and the pressure
        extension, for the particle velocities ``velocities (n, dim)`` and ``angular``."""
        rows = self.ghosts.constraints(velocities, angular) if self.ghosts.nodes.size else None
        return DirichletConstraints(rigid.dofs, rigid.values, rows, self.continuity, self.extension)


def _rigid_motion(rel: np.ndarray, particle: np.ndarray, velocities: np.ndarray,
                  angular: np.ndarray) -> np.ndarray:
    """``U_i + omega_i x rel`` for points at ``rel (n, dim)`` from the centre of their particle."""
    vel = np.asarray(velocities, dtype=float)[particle].copy()
    if rel.shape[1] == 2:
        w = np.asarray(angular, dtype=float).reshape(-1)[particle]
        vel[:, 0] -= w * rel[:, 1]
        vel[:, 1] += w * rel[:, 0]
    else:
        vel += np.cross(np.asarray(angular, dtype=float)[particle], rel)
    return vel


def reach_layers(mesh) -> int:
    """Cell layers along the last axis of the tensor-product ``mesh`` that the sharp boundary's
    rows of a node in the finest cells reach beyond the node's own, four at least:
    ``floor(2 D / h) + 1``, ``D`` the finest cells' diagonal and ``h`` the thinnest layer. A ghost
    node in a cut cell lies at most a cell's diagonal below the surface (the cell has a fluid
    node), and its image point ``a + l <= 2 D`` away (``l = max(a, h_node)``); a cut cell's
    pressure comes from a cell two layers away at most, whose own is chosen among cells two
    further. On several processes this is the fine slab's halo
    (:class:`~fbmflow.parallel.blocks.BlockPartition`): 4 for cubic cells, 4 on Glowinski's
    level 0. Cut cells coarser than the finest (a graded mesh's outer zone) may reach further:
    :attr:`GhostNodes.beyond` says where."""
    finest = mesh.finest_spacing
    return max(4, int(np.floor(2.0 * float(np.linalg.norm(finest)) / float(finest[-1]))) + 1)


def supports_sharp_boundary(shapes) -> bool:
    """True when every shape offers ``project`` (closest surface point and normal)."""
    return all(callable(getattr(s, "project", None)) for s in shapes)


def sharp_boundary(space: FlowSpace, owner: np.ndarray, centres: np.ndarray, shapes: list,
                   rotations: np.ndarray | None = None, domain=None) -> SharpBoundary:
    """The sharp boundary of the particles at ``centres (n, dim)`` with body-to-world
    ``rotations (n, dim, dim)`` (identity if omitted) and node ``owner`` from
    :func:`~fbmflow.coupling.indicator.node_owner`, on a tensor-product mesh. ``domain``: the
    whole mesh of which ``space``'s is one process's slab (None: the same). Vectorised over
    nodes and cells; one ``project`` and ``inside`` call per distinct shape."""
    if not supports_sharp_boundary(shapes):
        raise ValueError("the sharp fictitious boundary needs shapes with a closest-point projection "
                         "(Ball, Box, Cylinder); use the nodal boundary for the others")
    o = owner[space.V.cell_dofs]
    cut = np.flatnonzero((o < 0).any(axis=1) & (o >= 0).any(axis=1))
    centres = np.asarray(centres, dtype=float)
    return SharpBoundary(ghost_nodes(space.V, owner, cut, centres, shapes, rotations, domain),
                         fluid_continuity(space, owner, cut, centres, shapes, rotations),
                         pressure_extension(space, owner, cut, centres))


def _by_shape(shapes: list, particle: np.ndarray):
    """``(rows, shape)`` for every distinct shape object among the ``particle`` entries."""
    group = np.unique(np.array([id(s) for s in shapes], dtype=np.int64), return_inverse=True)[1]
    for g in np.unique(group[particle]):
        yield np.flatnonzero(group[particle] == g), shapes[int(np.flatnonzero(group == g)[0])]


def ghost_nodes(V: DofMap, owner: np.ndarray, cut: np.ndarray, centres: np.ndarray, shapes: list,
                rotations: np.ndarray | None = None, domain=None) -> GhostNodes:
    """The particles' nodes in the ``cut (n_c,)`` cells with their constraint rows (see the
    module docstring); those whose image point leaves the ``domain`` mesh's box (None:
    ``V``'s) are left out, and those whose image lies in it but off ``V``'s mesh are
    :attr:`GhostNodes.beyond`."""
    mesh = V.mesh
    domain = mesh if domain is None else domain
    nodes = np.unique(V.cell_dofs[cut][owner[V.cell_dofs[cut]] >= 0])
    part = owner[nodes]
    rel = periodic_offset(V, V.coordinates[nodes], centres[part])
    body = rel if rotations is None else np.einsum("kd,kde->ke", rel, rotations[part])
    surf_b, normal_b = np.empty_like(body), np.empty_like(body)
    for rows, shape in _by_shape(shapes, part):
        surf_b[rows], normal_b[rows] = shape.project(body[rows])
    if rotations is None:
        surface, normal = surf_b, normal_b
    else:
        surface = np.einsum("kde,ke->kd", rotations[part], surf_b)
        normal = np.einsum("kde,ke->kd", rotations[part], normal_b)
    depth = np.linalg.norm(surf_b - body, axis=1)
    reach = np.maximum(depth, _node_spacing(V, nodes))
    image = centres[part] + surface + reach[:, None] * normal
    x = V.coordinates[nodes]
    image = x + periodic_offset(V, image, x)  # by its node (a piece of a periodic mesh: in its frame)
    lower, upper = np.array(domain.lower), np.array(domain.upper)
    image = np.where(np.array(mesh.periodic), lower + np.mod(image - lower, upper - lower), image)
    keep = np.all((image >= lower) & (image <= upper) | np.array(domain.periodic), axis=1)
    here = keep & np.all((image >= np.array(mesh.lower)) & (image <= np.array(mesh.upper)), axis=1)
    beyond = nodes[keep & ~here]
    nodes, part, surface, depth, reach, image = (a[here] for a in (nodes, part, surface, depth, reach, image))
    cells, xi = locate(mesh, image)
    phi, _ = V.element.tabulate(xi)
    ratio = depth / reach
    n_g, nl = phi.shape
    rows = np.concatenate([np.arange(n_g), np.repeat(np.arange(n_g), nl)])
    cols = np.concatenate([nodes, V.cell_dofs[cells].ravel()])
    vals = np.concatenate([np.ones(n_g), (ratio[:, None] * phi).ravel()])
    matrix = sp.csr_matrix((vals, (rows, cols)), shape=(n_g, V.n_dofs))
    matrix.sum_duplicates()
    return GhostNodes(nodes, part, surface, 1.0 + ratio, matrix, beyond)


def fluid_continuity(space: FlowSpace, owner: np.ndarray, cut: np.ndarray, centres: np.ndarray,
                     shapes: list, rotations: np.ndarray | None = None,
                     n_1d: int = CUT_CELL_POINTS) -> ContinuityRows:
    """Continuity rows of the ``cut`` cells integrated over their fluid part only,
    ``-int_{cell outside the particles} psi_m d phi_a / d x_i``, by a tensor Gauss rule of
    ``n_1d`` points per axis with the inside test of every particle that has nodes in the cell
    (the lowest and highest index tested). Axis-aligned (tensor-product mesh) cells."""
    V, mesh, d = space.V, space.mesh, space.dim
    xi, w = gauss_tensor(d, n_1d)
    _, dphi = V.element.tabulate(xi)
    corners = mesh.vertices[mesh.cell_vertices[cut]]
    lo = corners.min(axis=1)                                              # (n_c, d)
    h = corners.max(axis=1) - lo
    x = lo[:, None, :] + 0.5 * (xi[None, :, :] + 1.0) * h[:, None, :]      # (n_c, nq, d)
    fluid = np.ones(x.shape[:2], dtype=bool)
    oc = owner[V.cell_dofs[cut]]
    highest = oc.max(axis=1)
    lowest = np.where(oc >= 0, oc, highest[:, None]).min(axis=1)
    for part in (highest, lowest):
        rel = periodic_offset(V, x, centres[part][:, None, :])
        if rotations is not None:
            rel = np.einsum("cqd,cde->cqe", rel, rotations[part])
        for rows, shape in _by_shape(shapes, part):
            fluid[rows] &= ~shape.inside(rel[rows].reshape(-1, d)).reshape(len(rows), -1)
    psi = np.concatenate([np.ones((len(xi), 1)), xi], axis=1)  # P1disc on an axis-aligned cell
    # local[c, m, i, a] = sum_q fluid psi_m (dphi_a / dxi_i) (2 / h_i) w_q |det J|: the cells'
    # fluid points times one table of the reference cell (a matrix product; a four-operand
    # einsum loops over every index)
    nl = dphi.shape[1]
    table = np.einsum("qm,qai,q->qmia", psi, dphi, w).reshape(len(w), -1)
    local = (fluid.astype(float) @ table).reshape(len(cut), d + 1, d, nl)
    local *= (2.0 / h)[:, None, :, None] * np.prod(0.5 * h, axis=1)[:, None, None, None]
    data = np.zeros((len(cut), d + 1, d * nl))
    rank = np.broadcast_to(space.local_rank[cut][:, None, :], (len(cut), d + 1, nl))
    for i in range(d):  # columns of a row: component-major, nodes in ascending DOF order
        np.put_along_axis(data[:, :, i * nl:(i + 1) * nl], rank, -local[:, :, i, :], axis=2)
    return ContinuityRows(cut, data)


def pressure_extension(space: FlowSpace, owner: np.ndarray, cut: np.ndarray,
                       centres: np.ndarray) -> PressureExtension:
    """Each ``cut`` cell's P1disc pressure continued from a fluid cell (no node owned by a
    particle): among the cells up to two index steps away, the one whose centre lies most nearly
    along the outward direction ``x_c - X_i`` from the centre of the cell's particle. A cut cell
    without one keeps its own pressure. Row scale: volume over smallest extent, the size of the
    cell's continuity rows."""
    V, mesh, d = space.V, space.mesh, space.dim
    npl = d + 1
    fluid = (owner[V.cell_dofs] < 0).all(axis=1)
    idx = mesh.cell_indices()
    shape, periodic = np.array(mesh.shape), np.array(mesh.periodic)
    strides = np.cumprod((1,) + tuple(mesh.shape[:-1]))
    xc = space.Q.centre[cut]
    out = periodic_offset(V, xc, centres[owner[V.cell_dofs[cut]].max(axis=1)])
    out /= np.maximum(np.linalg.norm(out, axis=1, keepdims=True), 1e-300)
    best = np.full(len(cut), -1, dtype=np.int64)
    at = np.arange(len(cut))
    for reach in (1, 2):
        offsets = np.indices((2 * reach + 1,) * d).reshape(d, -1).T - reach
        offsets = offsets[np.any(offsets != 0, axis=1)]
        cand = idx[cut][:, None, :] + offsets[None, :, :]             # (n_c, n_off, d)
        cand = np.where(periodic, cand % shape, cand)                 # periodic axes wrap
        valid = np.all((cand >= 0) & (cand < shape), axis=2)
        cid = (np.clip(cand, 0, shape - 1) * strides).sum(axis=2)
        valid &= fluid[cid]
        rel = periodic_offset(V, space.Q.centre[cid], xc[:, None, :])
        score = np.einsum("cod,cd->co", rel, out) / np.maximum(np.linalg.norm(rel, axis=2), 1e-300)
        pick = np.argmax(np.where(valid, score, -np.inf), axis=1)
        found = (best < 0) & valid[at, pick]
        best[found] = cid[at, pick][found]
    cells, best = cut[best >= 0], best[best >= 0]
    # the target's p = a + sum_l b_l (x - c_n)_l / s_n,l in the cell's basis {1, (x - c_c)_l / s_c,l}:
    # constant a + sum_l b_l (c_c - c_n)_l / s_n,l, linear coefficients b_l s_c,l / s_n,l
    cc, cn = space.Q.centre[cells], space.Q.centre[best]
    sc, sn = space.Q.scale[cells], space.Q.scale[best]
    E = np.zeros((len(cells), npl, npl))
    E[:, 0, 0] = 1.0
    E[:, 0, 1:] = periodic_offset(V, cc, cn) / sn
    E[:, np.arange(1, npl), np.arange(1, npl)] = sc / sn
    rows = np.repeat(cells[:, None] * npl + np.arange(npl), npl, axis=1).ravel()
    cols = np.tile(best[:, None] * npl + np.arange(npl), (1, npl)).ravel()
    matrix = sp.csr_matrix((E.ravel(), (rows, cols)), shape=(space.n_p, space.n_p))
    dofs = np.sort((cells[:, None] * npl + np.arange(npl)).ravel())
    extent = 2.0 * space.Q.scale[dofs // npl]
    return PressureExtension(dofs, matrix, np.prod(extent, axis=1) / extent.min(axis=1))


def _node_spacing(V: DofMap, nodes: np.ndarray) -> np.ndarray:
    """Largest distance to a neighbouring lattice node along an axis at every node, (n,)."""
    out = np.zeros(len(nodes))
    lat = V.lattice[nodes]
    for d, axis in enumerate(V.lattice_axes):
        gaps = np.diff(axis)
        i = lat[:, d]
        below, above = gaps[np.clip(i - 1, 0, gaps.size - 1)], gaps[np.clip(i, 0, gaps.size - 1)]
        out = np.maximum(out, np.maximum(below, above))
    return out
