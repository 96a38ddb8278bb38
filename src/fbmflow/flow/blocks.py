"""The flow of one process among several: every multigrid level's block
(:mod:`fbmflow.parallel.blocks`) with its operators, the transfers between the blocks, and the
whole coarsest mesh, which every process holds (:mod:`fbmflow.solvers.distributed`); and the
Navier–Stokes problem on the blocks.

The fine mesh is coarsened as for one process (:func:`~fbmflow.flow.levels.coarse_levels`). The
blocks are cut on the fine mesh in whole multiples of ``2^J`` cell layers along every divided
axis, so that they stay blocks of two layers at least on the ``J`` coarser levels; the level
below the last block level is the coarsest, held whole. A fine halo of ``w`` layers (rows that
reach further than a cell: the sharp boundary) halves from level to level,
``max(1, ceil(w / 2^j))`` on level ``j``, so that every block's coarse correction covers the fine
block it is prolongated onto, halo included.

The process grid (how many processes divide every axis) is given, or chosen among every
factorisation of the number of processes: the one that divides the most levels (the smallest
coarsest mesh, which every process solves whole), then the one with the fewest cell faces
between blocks (:func:`~fbmflow.parallel.blocks.halo_faces`, what the exchanges grow with).
Slabs along the last axis win on long meshes and few processes (ten Cate's box on up to 4),
blocks in two or three directions on many.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..fem import FlowSpace
from ..fem.dofmap import DofMap, PressureDofMap
from ..mesh import StructuredMesh, face_tags
from ..parallel import BlockPartition, max_over, sum_over
from ..parallel.blocks import box_numbers, cut_box, halo_faces, process_grids, split_layers
from ..solvers import NewtonSettings
from ..solvers.multigrid import MultigridSettings, MultigridSolver
from ..solvers.system import SaddlePointSystem
from ..solvers.transfer import prolongation_p1disc, prolongation_q2
from .boundary import DoNothing, check_boundary, pressure_is_determined
from .levels import FlowLevel
from .navier_stokes import NavierStokesProblem


class BlockFlowLevels:
    """Process ``comm.rank``'s blocks of the multigrid levels of ``mesh``.

    Parameters
    ----------
    mesh : StructuredMesh, the fine mesh (a divided periodic axis: its blocks form a ring)
    boundary : dict, the whole mesh's boundary conditions (:mod:`fbmflow.flow.boundary`)
    pressure_fixed : bool, whether ``int p = 0`` closes the system (a closed domain)
    comm : the processes' communicator
    min_cells : int, the coarsest level keeps at least so many cells
    extra_constraints : callable ``(DofMap, t) -> DirichletConstraints`` or None, further
        constraints on every level (particles), evaluated on each level's DOF map (the blocks'
        and the whole coarsest mesh's)
    halo : int, the fine block's halo layers (see the module docstring)
    grid : tuple of int or None, the processes along every axis (None: :func:`choose_grid`);
        ValueError where it cannot divide the mesh

    Attributes
    ----------
    grid : tuple of int, the process grid
    partitions : list of BlockPartition, finest first, the block levels
    levels : list of FlowLevel, on the block meshes
    coarsest : FlowLevel, on the whole coarsest mesh
    """

    def __init__(self, mesh: StructuredMesh, boundary: dict, pressure_fixed: bool, comm, min_cells: int = 1,
                 extra_constraints=None, halo: int = 1, grid=None):
        size, rank = comm.size, comm.rank
        meshes = [mesh]
        while all(n % 2 == 0 for n in meshes[-1].shape) and meshes[-1].n_cells // 2**mesh.dim >= min_cells:
            try:
                meshes.append(meshes[-1].coarsen())
            except ValueError:
                break
        halos = [max(1, -(-halo // 2**j)) for j in range(len(meshes))]
        if len(meshes) == 1:
            raise ValueError(f"the mesh {mesh.shape} does not coarsen (an odd number of cells along an "
                             f"axis), so {size} processes have no multigrid level to divide: run it on one "
                             "process or on a mesh with even cell counts")
        grid, J = choose_grid(mesh.shape, mesh.periodic, len(meshes), size, halo, grid)
        bounds = [split_layers(n, g, 2**J) for n, g in zip(mesh.shape, grid)]
        self.comm = comm
        #: the processes along every axis
        self.grid = grid
        self.partitions = [BlockPartition(meshes[j], size, rank, [b // 2**j for b in bounds], comm, halos[j],
                                          grid) for j in range(J + 1)]
        self.levels = [FlowLevel(part.mesh, _block_boundary(boundary, part), pressure_fixed,
                                 extra_constraints) for part in self.partitions]
        self.coarsest = FlowLevel(meshes[J + 1], boundary, pressure_fixed, extra_constraints)
        holders = self.partitions[1:] + [None]
        self.prolongations = [_block_prolongation(part, meshes[j + 1], holders[j])
                              for j, part in enumerate(self.partitions)]
        #: per coarser level, the finer block's local node at each of its nodes that the finer
        #: block owns, and which they are (the injection's, found once)
        self._injections = [_injection(self.partitions[j], part, self.coarsest)
                            for j, part in enumerate(holders)]

    def inject(self, u: np.ndarray) -> list[np.ndarray]:
        """A consistent fine velocity ``u`` (local) injected into every coarser level: the block
        levels' local vectors (consistent) and the whole coarsest mesh's (the same on every
        process)."""
        out = [u]
        d = self.partitions[0].dim
        for part, (fine_nodes, inside) in zip(self.partitions[1:] + [None], self._injections):
            v = np.zeros((d, inside.size))
            v[:, inside] = out[-1].reshape(d, -1)[:, fine_nodes]
            if part is not None:
                v = v.ravel()
                part.update_ghosts(v)
                out.append(v)
            else:
                out.append(sum_over(v.ravel(), self.comm))
        return out

    def systems(self, u: np.ndarray, m: float, a: float, rho: float, mu: float, convection: bool,
                newton: bool = False, con=None, orphans=None, t: float = 0.0,
                extra=None) -> SaddlePointSystem:
        """The linearisations ``m rho M + a (mu L + rho N(u))`` (with the Newton term ``R(u)``
        where ``newton``) at the consistent local fine velocity ``u`` on every level, chained:
        this process's part of the fine system, its ``coarser`` chain the block levels' (each
        with its ``partition`` and ``prolongation``) and the whole coarsest mesh's last
        (:class:`~fbmflow.solvers.distributed.DistributedMultigrid`'s input).

        ``con``, ``orphans``: the fine system's constraints and orphaned pressure modes (default:
        the walls'); the coarser levels' are the walls' and the extra constraints at time ``t``
        (``extra``: a solve's own instead of the levels'), homogeneous."""
        velocities = self.inject(u)
        coarsest = self.coarsest.system(velocities[-1], m, a, rho, mu, convection, newton=newton,
                                        con=self.coarsest.homogeneous_constraints(t, extra))
        system = coarsest
        for j, (part, level, P, v) in reversed(list(enumerate(zip(self.partitions, self.levels,
                                                                  self.prolongations, velocities)))):
            if j == 0 and con is not None:
                finer = level.system(v, m, a, rho, mu, convection, newton=newton, con=con, orphans=orphans)
            else:
                finer = level.system(v, m, a, rho, mu, convection, newton=newton,
                                     con=level.homogeneous_constraints(t, extra))
            finer.partition, finer.prolongation, finer.coarser = part, P, system
            system = finer
        return system


#: grids whose largest block holds at most this many times the fewest cells tie on it (the
#: slabs of ten Cate's level-3 box on 8 processes hold 1.008 times the cells of 1 x 2 x 4 blocks,
#: for fewer faces between them and 2 exchanges instead of 8)
NEAR_LARGEST = 1.05


def choose_grid(shape, periodic, n_levels: int, size: int, halo: int = 1, grid=None) -> tuple:
    """The process grid for ``size`` processes on a mesh of ``shape`` cells (``periodic`` axes)
    with ``n_levels`` multigrid levels and a fine halo of ``halo`` layers (halving per level), and
    the deepest level ``J`` its blocks divide: among every grid (or ``grid`` alone where given)
    that divides a level above the coarsest, those that divide the most levels (the smallest
    coarsest mesh, which every process solves whole); among them those whose largest block mesh
    holds at most :data:`NEAR_LARGEST` times the fewest cells (its owned cells and its halo: what
    the process assembles, and its ghosts, which it receives); among those the one with the
    fewest cell faces between blocks, then the one that divides the later axes most (slabs where
    they tie). ValueError where none does, naming the remedy."""
    halos = [max(1, -(-halo // 2**j)) for j in range(n_levels)]
    grids = process_grids(size, len(shape)) if grid is None else [tuple(grid)]
    found = []  # (deepest level, largest block, faces between blocks, the later axes first, grid)
    for g in grids:
        deepest = [J for J in range(n_levels - 1) if _fits(shape, periodic, g, J, halos)]
        if deepest:
            J = deepest[-1]
            found.append((J, _largest_block(shape, periodic, g, J, halo), halo_faces(shape, g),
                          tuple(-k for k in g[::-1]), g))
    if not found:
        raise ValueError(_refusal(shape, periodic, size, halo, n_levels, grid))
    J = max(f[0] for f in found)
    found = [f for f in found if f[0] == J]
    least = min(f[1] for f in found)
    best = min((f for f in found if f[1] <= NEAR_LARGEST * least), key=lambda f: f[2:4])
    return best[-1], J


def _largest_block(shape, periodic, grid, J: int, halo: int) -> int:
    """The cells of the largest fine block mesh of ``grid`` (blocks in multiples of ``2^J``
    layers, ``halo`` layers towards every neighbour)."""
    cells = 1
    for n, g, p in zip(shape, grid, periodic):
        widths = np.diff(split_layers(n, g, 2**J))
        sides = np.full(g, 2 if g > 1 else 0)  # halos per block: none where the axis is not cut,
        if g > 1 and not p:  # one at the ends of a closed axis
            sides[[0, -1]] = 1
        cells *= int((widths + halo * sides).max())
    return cells


def _fits(shape, periodic, grid, J: int, halos: list[int]) -> bool:
    """Whether blocks of ``grid`` in multiples of ``2^J`` layers hold ``halo + 1`` layers along
    every divided axis on the levels ``0..J`` (and, on a periodic axis, wrap not onto
    themselves)."""
    for n, g, p in zip(shape, grid, periodic):
        if g == 1:
            continue
        bounds = split_layers(n, g, 2**J)
        for j in range(J + 1):
            widths = np.diff(bounds // 2**j)
            if widths.min() <= halos[j] or (p and widths.max() + 2 * halos[j] >= n // 2**j):
                return False
    return True


def _refusal(shape, periodic, size: int, halo: int, levels: int, grid) -> str:
    """Why no grid of ``size`` processes divides the mesh, and what to do."""
    least = max(2, halo + 1)
    need = "two cell layers each" if least == 2 else f"{least} cell layers each (a halo of {halo})"
    most = int(np.prod([max(1, n // (2 * least)) for n in shape]))
    fix = f"use at most {most} processes or a finer mesh" if most > 1 else \
        "run it on one process or a finer mesh"
    if any(periodic) and size * least <= max(shape):
        need += " and, along a periodic axis, a block and its two halos shorter than the axis"
        fix = "use more processes, a finer mesh or one process"
    which = f"a grid {tuple(grid)} of processes needs" if grid is not None else f"{size} processes need"
    return (f"{which} {need} along every divided axis on a level above the coarsest; the mesh has "
            f"{tuple(shape)} cells and {levels} level(s): {fix}")


def _block_boundary(boundary: dict, part: BlockPartition) -> dict:
    """The conditions on a block mesh's faces: the whole mesh's, the faces cut between blocks
    unconstrained (their rows are the neighbours')."""
    tags = face_tags(part.dim)
    local = dict(boundary)
    for a, ((lo, hi), (ha, hb)) in enumerate(zip(part.layers, part.held)):
        if ha < lo:
            local[tags[2 * a]] = DoNothing()
        if hb > hi:
            local[tags[2 * a + 1]] = DoNothing()
    return local


def _node_counts(mesh: StructuredMesh) -> list[int]:
    """Q2 nodes along every axis of ``mesh``."""
    return [2 * n if p else 2 * n + 1 for n, p in zip(mesh.shape, mesh.periodic)]


def _fine_node(coarse: StructuredMesh, nodes: np.ndarray) -> np.ndarray:
    """The next finer mesh's node at every Q2 node ``nodes`` of ``coarse`` (global numbers)."""
    counts = _node_counts(coarse)
    fine = [2 * c if p else 2 * c - 1 for c, p in zip(counts, coarse.periodic)]
    out = np.zeros_like(nodes)
    rest, stride = nodes.copy(), 1
    for c, f in zip(counts, fine):
        out += 2 * (rest % c) * stride
        rest //= c
        stride *= f
    return out


def _injection(fine: BlockPartition, coarse: BlockPartition | None, coarsest: FlowLevel) -> tuple:
    """For the coarser level's local nodes (``coarse``'s block, or the whole ``coarsest`` mesh's):
    the local node of ``fine``'s block at those of them that ``fine`` owns, and a mask of which
    they are."""
    coarse_mesh = coarse.whole if coarse is not None else coarsest.mesh
    nodes = coarse.nodes if coarse is not None else np.arange(coarsest.space.n_v)
    fine_nodes = fine.local_nodes(_fine_node(coarse_mesh, nodes))
    inside = fine_nodes >= 0
    inside[inside] &= fine.owned_nodes[fine_nodes[inside]]
    return fine_nodes[inside], inside


def _block_prolongation(fine: BlockPartition, coarse_mesh: StructuredMesh, coarse: BlockPartition | None):
    """The scalar Q2 and P1disc prolongations ``(P_v, P_p)`` from the coarser level's local
    vectors (``coarse``'s block, or the whole ``coarse_mesh`` where None) onto ``fine``'s block:
    built between the coarse cells under the fine block and their refinement, the rows of the
    fine block's nodes and cells taken."""
    lower = [ha // 2 for ha, _ in fine.held]
    upper = [(hb + 1) // 2 for _, hb in fine.held]
    sub = cut_box(coarse_mesh, lower, upper)
    refined = cut_box(fine.whole, [2 * a for a in lower], [2 * b for b in upper])
    sub_v, refined_v = DofMap(sub), DofMap(refined)
    P_v = prolongation_q2(sub_v, refined_v)
    P_p = prolongation_p1disc(PressureDofMap(sub), PressureDofMap(refined))
    npl = fine.dim + 1
    whole_counts = _node_counts(coarse_mesh)
    # the fine block's nodes and cells in ``refined``'s numbers, ``sub``'s in the coarse level's
    rows_v = box_numbers([np.arange(m) + 2 * (ha - 2 * a) for m, (ha, _), a in
                           zip(fine.node_counts, fine.held, lower)], _node_counts(refined))
    rows_c = box_numbers([np.arange(hb - ha) + (ha - 2 * a) for (ha, hb), a in zip(fine.held, lower)],
                          list(refined.shape))
    nodes = box_numbers([(2 * a + np.arange(m)) % c for a, m, c in
                          zip(lower, _node_counts(sub), whole_counts)], whole_counts)
    cells = box_numbers([(a + np.arange(m)) % n for a, m, n in zip(lower, sub.shape, coarse_mesh.shape)],
                         list(coarse_mesh.shape))
    if coarse is not None:
        nodes, cells = coarse.local_nodes(nodes), coarse.local_cells(cells)
        n_v_c, n_cells_c = coarse.n_v, coarse.n_cells
    else:
        n_v_c, n_cells_c = int(np.prod(whole_counts)), coarse_mesh.n_cells
    pressures = (cells[:, None] * npl + np.arange(npl)).ravel()
    rows_p = (rows_c[:, None] * npl + np.arange(npl)).ravel()

    def cut(P, rows, columns, n_cols):
        P = P.tocsr()[rows]
        return sp.csr_matrix((P.data, columns[P.indices], P.indptr), shape=(rows.size, n_cols))

    return cut(P_v, rows_v, nodes, n_v_c), cut(P_p, rows_p, pressures, n_cells_c * npl)


class BlockNavierStokesProblem(NavierStokesProblem):
    """A :class:`~fbmflow.flow.navier_stokes.NavierStokesProblem` of which this process holds one
    block (its owned cell layers and a halo layer each side, :mod:`fbmflow.parallel.blocks`).

    Vectors are this process's local ``[u, p]`` on its block mesh, *consistent* (ghosts hold their
    owners' values): every residual and operator product is completed by a ghost update, norms
    and the closed box's volume balance sum over the owned unknowns, and the linear steps are
    solved by :class:`~fbmflow.solvers.distributed.DistributedMultigrid` on the block levels of
    :class:`BlockFlowLevels` (the Picard hierarchy inside FGMRES, which applies the Newton
    operator where there is convection). The time schemes (:func:`~fbmflow.flow.time_schemes.advance`)
    run unchanged on every process.

    Parameters
    ----------
    mesh : StructuredMesh, the whole fine mesh
    viscosity, boundary, density, body_force, convection, newton :
        as :class:`~fbmflow.flow.navier_stokes.NavierStokesProblem`'s (``boundary``: the whole
        mesh's conditions)
    comm : the processes' communicator
    multigrid : MultigridSettings or None, the solver's (V-cycles, vanka-factored, FGMRES; the
        coarse levels see particles by their own nodes)
    extra_constraints : as :class:`~fbmflow.flow.navier_stokes.NavierStokesProblem`'s (particles),
        evaluated on every block's and the whole coarsest mesh's DOF map; the fine level's fluid
        pockets are closed over the whole mesh
        (:meth:`~fbmflow.parallel.blocks.BlockPartition.join_components`)
    coarse_cells : int or None, the coarsest level keeps at least so many cells (None: as few as
        the blocks allow)
    halo : int, the fine block's halo layers: as far as a constraint row of an owned unknown
        reaches (the sharp boundary's, :func:`~fbmflow.coupling.sharp.reach_layers`). Constraints
        of the outer halo may then differ from their owners' (an image point off the block mesh):
        every vector a process changes by its own constraints is completed from the owners
        (:meth:`make_consistent`)
    grid : tuple of int or None, the processes along every axis (None: chosen,
        :class:`BlockFlowLevels`)
    """

    def __init__(self, mesh: StructuredMesh, viscosity: float, boundary: dict, comm, density: float = 1.0,
                 body_force=None, convection: bool = True, newton: NewtonSettings = NewtonSettings(),
                 multigrid: MultigridSettings | None = None, extra_constraints=None,
                 coarse_cells: int | None = None, halo: int = 1, grid=None):
        check_boundary(mesh.tags, boundary)
        multigrid = multigrid or MultigridSettings()
        if extra_constraints is not None and multigrid.coarse_obstacle != "nodes":
            raise ValueError("on several processes the coarse levels see particles by their own nodes: set "
                             "solver.multigrid.coarse_obstacle = 'nodes'")
        self.blocks = BlockFlowLevels(mesh, boundary, not pressure_is_determined(boundary), comm,
                                    min_cells=coarse_cells or 1, extra_constraints=extra_constraints,
                                    halo=halo, grid=grid)
        self.partition = part = self.blocks.partitions[0]
        solver = MultigridSolver(multigrid, rtol=newton.linear_rtol or 1e-8)
        super().__init__(part.mesh, viscosity, _block_boundary(boundary, part), density, body_force,
                         convection, solver, newton, extra_constraints=extra_constraints)
        self.whole_mesh = mesh
        self._whole_space = None
        self._pressure_fixed = not pressure_is_determined(boundary)
        self._pressure_dot = part.pressure_dot

    def _fine_level(self, mesh, boundary, pressure_fixed, extra_constraints) -> FlowLevel:
        return self.blocks.levels[0]

    def dot(self, x: np.ndarray, y: np.ndarray) -> float:
        return self.partition.dot(x, y)

    def _any(self, flag: bool) -> bool:
        return max_over(float(bool(flag)), self.partition.comm) > 0.0

    def max_abs(self, x: np.ndarray) -> float:
        own = self.partition.owned[:x.size]
        return max_over(float(np.abs(x[own]).max(initial=0.0)), self.partition.comm)

    def _close_pockets(self, con):
        return self.fine.close_pockets(con, self.partition)

    @property
    def whole_space(self) -> FlowSpace:
        """The whole mesh's FlowSpace, made once on a process that asks (for output and
        measurements; its arrays grow with the whole mesh)."""
        if self._whole_space is None:
            self._whole_space = FlowSpace(self.whole_mesh)
        return self._whole_space

    def whole_flow(self, x: np.ndarray) -> tuple[FlowSpace, np.ndarray]:
        part = self.partition
        space = self.whole_space
        return space, part.comm.bcast(part.gather(x, space.n_dofs))

    def whole_indices(self, unknowns: np.ndarray) -> np.ndarray:
        part = self.partition
        mine = part.unknowns_of_whole[unknowns[part.owned[unknowns]]]
        return np.sort(np.concatenate(part.comm.allgather(mine)))

    def make_consistent(self, x: np.ndarray) -> np.ndarray:
        self.partition.update_ghosts(x)
        return x

    def _complete(self, U: np.ndarray, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        X = np.vstack([U, P])
        self.partition.update_ghosts(X)
        return X[:U.shape[0]], X[U.shape[0]:]

    def residual(self, x, m, a, rhs, con, orphans=None) -> np.ndarray:
        F = super().residual(x, m, a, rhs, con, orphans)
        self.partition.update_ghosts(F)
        return F

    def load(self, t: float = 0.0) -> np.ndarray:
        f = super().load(t)
        self.partition.update_ghosts(f)
        return f

    def apply_mass(self, u: np.ndarray) -> np.ndarray:
        v = super().apply_mass(u)
        self.partition.update_ghosts(v)
        return v

    def apply_spatial(self, u: np.ndarray) -> np.ndarray:
        v = super().apply_spatial(u)
        self.partition.update_ghosts(v)
        return v

    def linear_system(self, x, m, a, con, t=0.0, extra=None) -> SaddlePointSystem:
        """The Picard linearisation on every block level (:meth:`BlockFlowLevels.systems`; the fine
        level under ``con``, the coarser ones under their walls and the particles' nodes), or,
        with convection, the Newton system whose ``preconditioner`` it is."""
        u = x[:self.space.n_u]
        picard = self.blocks.systems(u, m, a, self.rho, self.mu, self.convection, con=con,
                                    orphans=self._known_orphans(con), t=t, extra=extra)
        if self.convection and a != 0.0:
            return self.fine.newton_system(picard, u, a, self.rho)
        return picard
