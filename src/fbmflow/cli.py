"""The ``fbmflow`` command line.

    fbmflow scenes
    fbmflow run SCENE [--level L] [--set KEY=VALUE ...] [--out DIR] [--checkpoint-every N]
                      [--fields-every N] [--fields-format xdmf|vtu] [--quiet] [--no-plot]
    fbmflow resume DIR [--quiet] [--no-plot]
    fbmflow plot DIR

User errors (and unusable checkpoints) exit with status 2 and one line on stderr; a run that fails
to converge exits with status 1 and a message naming a remedy.
"""
from __future__ import annotations

import argparse
import json
import logging
import sys
import time
from pathlib import Path

from . import __version__
from .params import ParamError
from .solvers import ConvergenceError

log = logging.getLogger("fbmflow")


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, status 2, no usage dump
        sys.stderr.write(f"fbmflow: error: {message} (see 'fbmflow {self.prog.split()[-1]} --help')\n"
                         if " " in self.prog else f"fbmflow: error: {message} (see 'fbmflow --help')\n")
        sys.exit(2)


def _parser() -> argparse.ArgumentParser:
    p = _Parser(prog="fbmflow", description="Particulate flows with the FEM fictitious boundary method.")
    p.add_argument("--version", action="version", version=f"fbmflow {__version__}")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)
    sub.add_parser("scenes", help="list the built-in scenes")
    run = sub.add_parser("run", help="run a built-in scene or a TOML scene file")
    run.add_argument("scene", help="built-in scene name or path to a .toml scene file")
    run.add_argument("--level", type=int, default=None, help="mesh refinement level (each level halves h)")
    run.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                     help="override a scene parameter by its dotted key, e.g. fluid.viscosity=0.01")
    run.add_argument("--out", type=Path, default=None, help="output directory (default fbmflow-out/SCENE)")
    run.add_argument("--quiet", action="store_true", help="no progress output")
    run.add_argument("--no-plot", action="store_true", help="do not write the PNG plot")
    run.add_argument("--checkpoint-every", type=int, default=0, metavar="N",
                     help="time-dependent scenes: write DIR/checkpoint.h5 every N steps (0: never)")
    run.add_argument("--fields-every", type=int, default=0, metavar="N",
                     help="time-dependent scenes: ParaView output (fields.xdmf, particles.pvd) every N steps")
    run.add_argument("--fields-format", choices=("xdmf", "vtu"), default="xdmf",
                     help="field output as one XDMF+HDF5 series (default) or one VTU per output")
    resume = sub.add_parser("resume", help="continue a stopped or killed run from its checkpoint")
    resume.add_argument("directory", type=Path, help="the --out directory of the run")
    resume.add_argument("--quiet", action="store_true", help="no progress output")
    resume.add_argument("--no-plot", action="store_true", help="do not write the PNG plot")
    plot = sub.add_parser("plot", help="redraw the plot of a finished run from its summary.json")
    plot.add_argument("directory", type=Path)
    return p


def _progress(quiet: bool):
    """A one-line progress bar on stderr: step, simulated time, elapsed time and ETA, and what the
    scene reports about the step (Newton iterations, linear cycles, fastest particle)."""
    if quiet:
        return None
    start = time.perf_counter()
    width = 20

    def report(step: int, n: int, t: float | None, info: dict | None = None) -> None:
        elapsed = time.perf_counter() - start
        eta = elapsed / step * (n - step)
        done = int(width * step / n)
        where = f"t = {t:.4g}" if t is not None else "steady stage"
        extra = "".join(f"  {k} {v:.3g}" if isinstance(v, float) else f"  {k} {v}" for k, v in (info or {}).items())
        sys.stderr.write(f"\r  [{'#' * done}{'.' * (width - done)}] {step}/{n}  {where}{extra}  "
                         f"elapsed {elapsed:.1f} s  eta {eta:.1f} s ")
        if step == n:
            sys.stderr.write("\n")
        sys.stderr.flush()
    return report


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    logging.basicConfig(level=logging.WARNING if getattr(args, "quiet", False) else logging.INFO,
                        format="%(message)s", stream=sys.stderr)
    from .io import CheckpointError
    from .scenes import SCENES, get_scene, load_scene, resume_scene, run_scene

    try:
        if args.command == "scenes":
            for name, scene in SCENES.items():
                print(f"{name}  {scene.description}")
            return 0
        if args.command == "plot":
            summary_path = args.directory / "summary.json"
            if not summary_path.is_file():
                raise ParamError(f"{summary_path} not found; give the --out directory of a finished run")
            summary = json.loads(summary_path.read_text())
            scene = get_scene(summary.get("scene", ""))
            path = args.directory / f"{scene.name}.png"
            print(path if scene.plot(summary, path) else f"scene {scene.name} has no plot")
            return 0
        if args.command == "resume":
            out = args.directory
            log.info("fbmflow %s: resuming %s", __version__, out)
            summary = resume_scene(out, _progress(args.quiet), plot=not args.no_plot)
        else:
            if args.checkpoint_every < 0 or args.fields_every < 0:
                raise ParamError("--checkpoint-every and --fields-every must be >= 0")
            scene, params, level = load_scene(args.scene, args.level, args.overrides)
            out = args.out or Path("fbmflow-out") / scene.name
            log.info("fbmflow %s: %s at level %d -> %s", __version__, scene.name, level, out)
            summary = run_scene(scene, params, level, out, _progress(args.quiet), plot=not args.no_plot,
                                checkpoint_every=args.checkpoint_every, fields_every=args.fields_every,
                                fields_format=args.fields_format)
        log.info("done in %.2f s: %d cells, %d unknowns, %d Newton iterations (%s); summary in %s",
                 summary["wall_time_s"], summary["n_cells"], summary["n_dofs"],
                 summary["newton_iterations"], summary.get("linear_solver") or "linear solver not recorded",
                 out / "summary.json")
        return 0
    except (ParamError, CheckpointError) as err:
        sys.stderr.write(f"fbmflow: error: {err}\n")
        return 2
    except ConvergenceError as err:
        sys.stderr.write(f"fbmflow: run failed: {err}. Remedy: refine the mesh (--level), reduce the "
                         "time step, or relax solver.newton_rtol.\n")
        return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
