"""Newton's linear steps in time steps, on the same steps of a run, in one process: the last-step
forcing against a fixed linear tolerance, and the Newton block moved to each iterate against the
chord method.

Question: how much time per step do Newton's last-step forcing and the reused linearisation
moved to each iterate save against a fixed linear tolerance and the chord method, on the same
steps of a ten Cate run?
Answer: the last-step forcing: 12.2 -> 10.0 s per step at level 1 (-18 %, cycles 18.7 -> 15.3)
and 68.2 -> 62.1 s at level 2 (-9 %); the relinearised block against the chord method: 10.58 ->
9.35 s at level 1 (-9 to -12 %) and 63.5 -> 53.4 s at level 2 (-8 to -16 %), the velocities the
same to 1e-8 (no results file; the figures are those docs/validation/ quotes).
Measured: 2026-11-28, commit 017045c; quoted in docs/validation/multigrid-with-fictitious-boundaries.md
Run: python -m fbmbench newton_forcing RUN_DIR --steps 3

The chord method against the relinearised block: ``python -m fbmbench newton_forcing RUN_DIR
--steps 3 --rounds R --variants chord relinearised``.

``RUN_DIR`` holds ``run.json`` and ``checkpoint.h5`` (``fbmflow run ... --checkpoint-every N``,
e.g. ``fbmflow run ten-cate --level 2 --set solver.linear=multigrid --set time.dt=0.01 --set
time.t_end=0.3 --checkpoint-every 5`` stopped after step 25). The scene is built once; each
round restores the checkpoint and runs ``--steps`` steps with each variant in turn:

- ``fixed``: every linear step asked for ``solver.linear_rtol``
  (:data:`fbmflow.solvers.newton.LAST_STEP_FORCING` set to it), the chord method (a reused
  linearisation stays at the point where it was built);
- ``chord``: the last-step forcing, the chord method;
- ``relinearised``: the package's rule, the last-step forcing with a reused linearisation moved
  to each iterate (:meth:`fbmflow.flow.levels.NewtonBlock.relinearise`).

Prints every step's wall time, linear solves, multigrid cycles, Newton iterations and the first
particle's velocity, and the means per variant.
"""
from __future__ import annotations

import json
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from fbmflow.config import from_dict
from fbmflow.flow.levels import NewtonBlock
from fbmflow.io import load_checkpoint
from fbmflow.scenes import get_scene
from fbmflow.solvers import newton

VARIANTS = ("fixed", "chord", "relinearised")


@contextmanager
def variant(name: str, linear_rtol: float):
    """The package with ``name``'s rule in place (restored afterwards)."""
    forcing, relinearise = newton.LAST_STEP_FORCING, NewtonBlock.relinearise
    if name == "fixed":
        newton.LAST_STEP_FORCING = linear_rtol
    if name in ("fixed", "chord"):  # set once, where the block is built
        NewtonBlock.relinearise = lambda block, u: None if hasattr(block, "react") else relinearise(block, u)
    try:
        yield
    finally:
        newton.LAST_STEP_FORCING, NewtonBlock.relinearise = forcing, relinearise


def run(*, run_dir: Path, steps: int = 2, rounds: int = 2, variants: list[str] = VARIANTS) -> None:
    """Run the same steps from the checkpoint with each variant in turn and print the means.

    Parameters
    ----------
    run_dir : a run's folder with run.json and checkpoint.h5
    steps : steps per variant and round
    rounds : rounds (each variant once per round)
    variants : the variants (fixed, chord, relinearised)
    """
    unknown = [v for v in variants if v not in VARIANTS]
    if unknown:
        raise SystemExit(f"newton_forcing: no variant {', '.join(unknown)}; variants: {', '.join(VARIANTS)}")
    run_dir = Path(run_dir)
    meta = json.loads((run_dir / "run.json").read_text())
    scene = get_scene(meta["scene"])
    sim = scene.build(from_dict(scene.Params, meta["params"]), meta["level"]).sim
    state = load_checkpoint(run_dir / "checkpoint.h5")[0]
    rows = {name: [] for name in variants}
    for _ in range(rounds):
        for name in variants:
            with variant(name, sim.flow.newton.linear_rtol):
                sim.set_state(state)
                for _ in range(steps):
                    t0 = time.perf_counter()
                    r = sim.step()
                    wall = time.perf_counter() - t0
                    rows[name].append((wall, r.linear.time_s, r.linear.solves, r.linear.iterations,
                                       r.newton_iterations))
                    print(f"{name}: step {r.step} {wall:.2f} s (solves {r.linear.time_s:.2f} s), "
                          f"{r.linear.solves} solves, {r.linear.iterations} cycles, "
                          f"{r.newton_iterations} Newton"
                          + (f", velocity {r.velocity[0].tolist()}" if len(r.velocity) else ""), flush=True)
    for name, values in rows.items():
        v = np.array(values)
        print(f"{name}: {v[:, 0].mean():.2f} s per step ({v[:, 1].mean():.2f} s in {v[:, 2].mean():.2f} "
              f"solves, {v[:, 3].mean():.2f} cycles, {v[:, 4].mean():.2f} Newton)")

