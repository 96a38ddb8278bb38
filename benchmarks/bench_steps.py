"""Wall time of a few time steps continued from a run's checkpoint.

Run:  python benchmarks/bench_steps.py RUN_DIR [--steps 3] [--set KEY=VALUE ...]

For comparing two versions of the code on the same state, mid-run, where the first steps from
rest are not representative: run the same command from each checkout (one at a time; a level-1
ten-cate step needs 10-15 GB). ``RUN_DIR`` is a folder with ``checkpoint.h5`` and ``run.h5``,
written by ``fbmflow run ... --checkpoint-every N`` or by ``bench_tencate.py`` (its ``--runs``
folders). Both files are copied to a temporary folder; ``RUN_DIR`` is left as it is. The JIT
compilation is done first by a two-step run of the scene at level 0 and not timed.

Prints the steps, wall time, Newton iterations, linear factorisations (and how many of them
analysed afresh), PARDISO's triangular solves (refinement steps included), the peak memory of
the process and the scene's quantities (the time series' last values; full precision, to check
that two versions compute the same).
``--set`` overrides a scene parameter for the timed steps, as ``fbmflow run --set`` does (e.g.
``solver.linear_rtol=1e-12``, PARDISO's refinement target in Newton steps).
"""
from __future__ import annotations

import argparse
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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run_dir", type=Path, help="folder with checkpoint.h5 and run.h5")
    ap.add_argument("--steps", type=int, default=3, help="steps to run from the checkpoint (>= 1)")
    ap.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                    help="override a scene parameter for the timed steps, e.g. solver.linear_rtol=1e-12")
    args = ap.parse_args()
    if args.steps < 1:
        ap.error(f"--steps must be at least 1, got {args.steps}")
    state, meta, _ = load_checkpoint(args.run_dir / "checkpoint.h5")
    scene = get_scene(meta["scene"])
    dt, step = from_dict(scene.Params, meta["params"]).time.dt, int(state["step_count"])

    def with_end(t_end: float):
        data = json.loads(json.dumps(meta["params"]))
        for item in args.overrides:
            key, _, value = item.partition("=")
            set_dotted(data, key.strip(), parse_value(value.strip()))
        data["time"]["t_end"] = t_end
        return from_dict(scene.Params, data)

    params = with_end((step + args.steps) * dt)
    scene.run(with_end(2 * dt), 0)  # JIT compilation, not timed

    factorisations, lu_solves, analyses = [], [], []
    factor, lu_solve, factorise = DirectSolver.factor, PardisoAnalysis.solve, PardisoAnalysis._factorise

    DirectSolver.factor = lambda self, system: factorisations.append(1) or factor(self, system)
    PardisoAnalysis.solve = lambda self, M, B: lu_solves.append(1) or lu_solve(self, M, B)
    PardisoAnalysis._factorise = (lambda self, phase, M:
                                  analyses.append(phase == 12) or factorise(self, phase, M))
    with tempfile.TemporaryDirectory() as tmp:
        for name in ("checkpoint.h5", "run.h5"):
            shutil.copy(args.run_dir / name, Path(tmp) / name)
        t0 = time.perf_counter()
        result = scene.run(params, meta["level"], None, RunFiles(tmp, 10**9, True, meta=meta))
        wall = time.perf_counter() - t0
    DirectSolver.factor, PardisoAnalysis.solve, PardisoAnalysis._factorise = factor, lu_solve, factorise
    print(f"{meta['scene']} level {meta['level']}: steps {step} -> {result.steps} (dt {dt:g} s), "
          f"{wall:.1f} s ({wall / args.steps:.1f} s per step), Newton iterations "
          f"{result.newton_iterations} (whole run), factorisations {len(factorisations)} "
          f"({sum(analyses)} with a new PARDISO analysis), "
          f"PARDISO triangular solves {len(lu_solves)}, overrides {args.overrides}, "
          f"peak memory {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6:.1f} GB")
    last = {k: (v[-1] if isinstance(v, list) else v) for k, v in result.quantities.items()
            if isinstance(v, (int, float)) or (isinstance(v, list) and v and isinstance(v[-1], (int, float)))}
    print("quantities (time series: the last value):", {k: float(v) for k, v in last.items()})


if __name__ == "__main__":
    main()
