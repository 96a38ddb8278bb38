"""How ten Cate's box divides among processes: slabs against the grid fbmflow chooses.

Question: for ten Cate's quarter box at levels 1-3 with the sharp boundary's halo, on 2 to 128
processes, which process grid does fbmflow choose (fbmflow.flow.blocks.choose_grid), how many
multigrid levels do its blocks divide, and how many unknowns does a middle process hold and
receive per ghost update, against slabs along the last axis where slabs divide the mesh at all?
Answer: up to 8 processes ten Cate's box is cut in slabs at levels 1-3; from 16 on, in blocks
(1 x 2 x 8, 2 x 2 x 8, 2 x 2 x 16, 2 x 4 x 16). Slabs stop at 12 processes on level 1 and 24 on
level 2 (a slab needs 5 layers); the blocks go on to 32 and 128 here (384 on level 2 and 1 197 on
level 3 by choose_grid alone). At level 3 on 32 processes the middle process receives 398 851
unknowns per update on blocks against 553 587 on slabs, and the blocks divide 4 levels against 2;
at level 2 on 16 the two are alike (143 235 against 140 883). The halo is 0.5 of a block's owned
unknowns at 16 processes on level 3 and 5.8 at 128 on level 2.
Measured: 2026-11-30, commit 6622083 and the grid rule after it (tag geometry); quoted in
docs/validation/several-processes.md, "Blocks in two and three directions"
Run: python -m fbmbench block_grids

Geometry only, one process, no MPI: for every level and process count the grid is chosen as a
run would choose it, and the partition (fbmflow.parallel.blocks.BlockPartition) of the process
in the middle of the grid (coordinate ``g // 2`` along every axis) is built on the fine mesh
with the halo of fbmflow.coupling.sharp.reach_layers; the same for the slab grid ``(1, 1, P)``.
Owned: its owned unknowns; held: its block mesh's; received: the ghosts an update writes (the
halo exchange's volume, in unknowns of 8 bytes); messages: the exchanges per update (grid
offsets with a neighbour).

writes benchmarks/results/block_grids.{json,md}; ``--tag`` names the run (rows with other tags
are kept).
"""
from __future__ import annotations

import json

from studies.thread_scaling import RESULTS, commit


def middle(mesh, size, grid, halo):
    """The partition of the process in the middle of the grid of ``size`` processes on ``mesh``
    (``grid``, or the chosen one where None; the chosen bounds) and its deepest divided level."""
    from fbmflow.flow.blocks import choose_grid
    from fbmflow.parallel.blocks import BlockPartition, split_layers

    levels = 1
    shape = mesh.shape
    while all(n % 2 == 0 for n in shape):
        shape = tuple(n // 2 for n in shape)
        levels += 1
    grid, J = choose_grid(mesh.shape, mesh.periodic, levels, size, halo, grid)
    bounds = [split_layers(n, g, 2**J) for n, g in zip(mesh.shape, grid)]
    rank, stride = 0, 1
    for g in grid:
        rank += (g // 2) * stride
        stride *= g
    return BlockPartition(mesh, size, rank, bounds, halo=halo, grid=grid), J


def table(rows: list[dict]) -> str:
    lines = ["# Ten Cate's box over processes: slabs against the chosen grid "
             "(python -m fbmbench block_grids)", "",
             "Geometry only (no MPI): the process in the middle of the grid, on the fine mesh, with the "
             "sharp boundary's halo. Levels: the multigrid levels the blocks divide (the next is the "
             "coarsest, held whole by every process). Received: the ghosts one update writes (unknowns of "
             "8 bytes); messages: exchanges per update. `-`: the slabs do not divide the mesh (a slab needs "
             "the halo plus one layer on a level above the coarsest).", "",
             "| tag | tree | level | unknowns | processes | grid | levels divided | owned | held | "
             "received | received / owned | messages | slabs: levels | slabs: received | "
             "slabs: received / owned |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        s = r["slabs"]
        slabs = (f"{s['levels']} | {s['received']} | {s['received'] / s['owned']:.3f}" if s else "- | - | -")
        lines.append(f"| {r['tag']} | {r['tree']} | {r['level']} | {r['unknowns']} | {r['processes']} | "
                     f"{' x '.join(map(str, r['grid']))} | {r['levels']} | {r['owned']} | {r['held']} | "
                     f"{r['received']} | {r['received'] / r['owned']:.3f} | {r['messages']} | {slabs} |")
    return "\n".join(lines) + "\n"


def run(*, levels: list[int] = (1, 2, 3), processes: list[int] = (2, 4, 8, 16, 32, 64, 128),
        tag: str = "dev") -> None:
    """Divide ten Cate's box at every level among every number of processes.

    Parameters
    ----------
    levels : ten Cate's levels (quarter box, graded mesh)
    processes : the process counts
    tag : this run's name in the results (rows with other tags are kept)
    """
    from fbmflow.coupling.sharp import reach_layers
    from fbmflow.fem import FlowSpace
    from fbmflow.scenes.tencate import TenCate

    RESULTS.mkdir(exist_ok=True)
    path = RESULTS / "block_grids.json"
    kept = [r for r in json.loads(path.read_text()) if r["tag"] != tag] if path.exists() else []
    done = []
    for level in levels:
        mesh = TenCate.mesh(level, "quarter")
        halo = reach_layers(mesh)
        for size in processes:
            figures = {}
            for kind, grid in (("chosen", None), ("slabs", (1,) * (mesh.dim - 1) + (size,))):
                try:
                    part, J = middle(mesh, size, grid, halo)
                except ValueError:
                    figures[kind] = None
                    continue
                received = sum(0 if receive is None else receive.size for _, _, _, receive in part.exchanges)
                figures[kind] = dict(grid=list(part.grid), levels=J + 1, owned=int(part.owned.sum()),
                                     held=int(part.owned.size), received=int(received),
                                     messages=len(part.exchanges))
            if figures["chosen"] is None:
                print(f"level {level}, {size} processes: no grid divides the mesh", flush=True)
                continue
            row = dict(figures["chosen"], tag=tag, tree=commit(), level=level, processes=size,
                       unknowns=FlowSpace.estimate_dofs(mesh), slabs=figures["slabs"])
            print(f"level {level}, {size} processes: {row['grid']}, received {row['received']} "
                  f"(slabs {figures['slabs'] and figures['slabs']['received']})", flush=True)
            done.append(row)
            path.write_text(json.dumps(kept + done, indent=1))
            (RESULTS / "block_grids.md").write_text(table(kept + done))
