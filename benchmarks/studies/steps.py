"""Wall time of a few time steps continued from a run's checkpoint.

Question: how long do a few steps of a run take when continued from its checkpoint, mid-run, and
with how many Newton iterations, factorisations and PARDISO triangular solves (to compare two
versions of the code, or two settings, on the same state)?
Answer: ten-cate E4 at level 2, steps 26-35 from the step-25 checkpoint: 62.7 s per step on
average at 8.6 GB with Newton's last-step forcing (72 s in an earlier session); at level 1, three
steps from t = 0.04 s with ``solver.linear_rtol`` 1e-12 / 1e-8 / 1e-6: 169 / 135 / 100 triangular
solves, 279 / 272 / 250 s, 55 Newton iterations each (docs/method.md); no results file, the
figures are in the docs.
Measured: 2026-11-28, commit a876e71; quoted in docs/validation/multigrid-with-fictitious-boundaries.md
Run: python -m fbmbench steps RUN_DIR --steps 10

Other uses (docs/method.md): ``python -m fbmbench steps RUN_DIR --steps 3`` and
``python -m fbmbench steps RUN_DIR --steps 3 --set solver.linear_rtol=R``.

For comparing two versions of the code on the same state, mid-run, where the first steps from
rest are not representative: run the same command from each checkout (one at a time; a level-1
ten-cate step needs 10-15 GB). ``RUN_DIR`` is a folder with ``checkpoint.h5`` and ``run.h5``,
written by ``fbmflow run ... --checkpoint-every N`` or by the ``tencate`` study (its ``--runs``
folders). Both files are copied to a temporary folder; ``RUN_DIR`` is left as it is. The JIT
compilation is done first by a two-step run of the scene at level 0 and not timed.

Prints the steps, wall time, Newton iterations, linear factorisations (and how many of them
analysed afresh), PARDISO's triangular solves (refinement steps included), the peak memory of
the process and the scene's quantities (the time series' last values; full precision, to check
that two versions compute the same).
``--set`` overrides scene parameters for the timed steps, as ``fbmflow run --set`` does (e.g.
``solver.linear_rtol=1e-12``, PARDISO's refinement target in Newton steps); several go after one
``--set`` (``--set KEY=VALUE KEY=VALUE``).
"""
from __future__ import annotations

import json
import resource
import shutil
import tempfile
import time
from pathlib import Path

from fbmflow.config import from_dict, parse_value, set_dotted
from fbmflow.io import load_checkpoint
from fbmflow.run import RunFiles
from fbmflow.scenes import get_scene
from fbmflow.solvers import DirectSolver
from fbmflow.solvers.direct import PardisoAnalysis


def run(run_dir: Path, *, steps: int = 3, set: list[str] = ()) -> None:
    """Run ``steps`` steps of the run in ``run_dir`` from its checkpoint and print what they did.

    Parameters
    ----------
    run_dir : folder with checkpoint.h5 and run.h5
    steps : steps to run from the checkpoint (>= 1)
    set : override a scene parameter for the timed steps (KEY=VALUE), e.g. solver.linear_rtol=1e-12
    """
    overrides = list(set)
    if steps < 1:
        raise SystemExit(f"--steps must be at least 1, got {steps}")
    state, meta, _ = load_checkpoint(run_dir / "checkpoint.h5")
    scene = get_scene(meta["scene"])
    dt, step = from_dict(scene.Params, meta["params"]).time.dt, int(state["step_count"])

    def with_end(t_end: float):
        data = json.loads(json.dumps(meta["params"]))
        for item in overrides:
            key, _, value = item.partition("=")
            set_dotted(data, key.strip(), parse_value(value.strip()))
        data["time"]["t_end"] = t_end
        return from_dict(scene.Params, data)

    params = with_end((step + steps) * dt)
    scene.run(with_end(2 * dt), 0)  # JIT compilation, not timed

    factorisations, lu_solves, solvers = [], [], []
    factor, lu_solve = DirectSolver.factor, PardisoAnalysis.solve

    def counted_factor(self, system):
        factorisations.append(1)
        if all(s is not self for s in solvers):
            solvers.append(self)  # its analysis counts the factorisations that analysed afresh
        return factor(self, system)

    DirectSolver.factor = counted_factor
    PardisoAnalysis.solve = lambda self, M, B: lu_solves.append(1) or lu_solve(self, M, B)
    with tempfile.TemporaryDirectory() as tmp:
        for name in ("checkpoint.h5", "run.h5"):
            shutil.copy(run_dir / name, Path(tmp) / name)
        t0 = time.perf_counter()
        result = scene.run(params, meta["level"], None, RunFiles(tmp, 10**9, True, meta=meta))
        wall = time.perf_counter() - t0
    DirectSolver.factor, PardisoAnalysis.solve = factor, lu_solve
    analyses = sum(s.analysis.analyses for s in solvers)
    print(f"{meta['scene']} level {meta['level']}: steps {step} -> {result.steps} (dt {dt:g} s), "
          f"{wall:.1f} s ({wall / steps:.1f} s per step), Newton iterations "
          f"{result.newton_iterations} (whole run), factorisations {len(factorisations)} "
          f"({analyses} with a new PARDISO analysis), "
          f"PARDISO triangular solves {len(lu_solves)}, overrides {overrides}, "
          f"peak memory {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 / 1e9:.1f} GB")
    last = {k: (v[-1] if isinstance(v, list) else v) for k, v in result.quantities.items()
            if isinstance(v, (int, float)) or (isinstance(v, list) and v and isinstance(v[-1], (int, float)))}
    print("quantities (time series: the last value):", {k: float(v) for k, v in last.items()})
