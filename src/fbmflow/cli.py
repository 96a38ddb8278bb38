"""The ``fbmflow`` command line::

    fbmflow scenes
    fbmflow run SCENE [--level L] [--set KEY=VALUE ...] [--out DIR] [--overwrite] [--estimate-error]
                      [--checkpoint-every N] [--fields-every N] [--fields-format xdmf|vtu] [--quiet]
                      [--no-plot]
    fbmflow resume DIR [--quiet] [--no-plot]
    fbmflow plot DIR

``run`` and ``resume`` started as several MPI processes (``mpiexec -n P fbmflow run ...``) divide
a particle scene's mesh among them (:class:`~fbmflow.simulation.Simulation`): the first process
writes the output and the progress and prints the errors, every process exits with the same
status; the scenes without particles run on one process and are refused.

User errors (and unusable checkpoints) exit with status 2 and one line on stderr; a run that fails
to converge, or leaves the physically possible, exits with status 1 and a message naming a remedy;
a run stopped by a signal exits with ``128 + signal`` (130 Ctrl-C, 143 SIGTERM, 129 SIGHUP) after
the step under way, with a checkpoint (:mod:`fbmflow.interrupt`).
"""
from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path

from . import __version__, interrupt
from .config import ParamError
from .parallel.comm import LaunchError, launched_processes, on_first, world
from .solvers import ConvergenceError

log = logging.getLogger("fbmflow")
#: the remedy of a failed solve that names none (a steady scene's Newton iteration)
STEADY_REMEDY = ("refine the mesh (--level) or lower the Reynolds number (a steady flow may not exist, "
                 "or Newton may not reach it from the Stokes start, above a few hundred at coarse levels)")


def _say(text: str) -> None:
    """Write ``text`` to stderr from the first of several processes only (all meet the same
    error: one message)."""
    if launched_processes()[0] == 0:
        sys.stderr.write(text)


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, status 2, no usage dump
        _say(f"fbmflow: error: {message} (see 'fbmflow {self.prog.split()[-1]} --help')\n"
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
    run.add_argument("--out", default=None, help="output directory (default fbmflow-out/SCENE)")
    run.add_argument("--quiet", action="store_true", help="no progress output")
    run.add_argument("--no-plot", action="store_true", help="do not write the PNG plot")
    run.add_argument("--checkpoint-every", type=int, default=0, metavar="N",
                     help="time-dependent scenes: write DIR/checkpoint.h5 every N steps (0: never)")
    run.add_argument("--fields-every", type=int, default=0, metavar="N",
                     help="time-dependent scenes: ParaView output (fields.xdmf, particles.pvd) every N steps")
    run.add_argument("--estimate-error", action="store_true",
                     help="run the one or two coarser levels too and write the Richardson error estimate of "
                          "every quantity into summary.json and error_estimate.png")
    run.add_argument("--overwrite", action="store_true",
                     help="replace the results of an earlier run in --out (refused without it)")
    run.add_argument("--fields-format", choices=("xdmf", "vtu"), default="xdmf",
                     help="field output as one XDMF+HDF5 series (default) or one VTU per output")
    resume = sub.add_parser("resume", help="continue a stopped or killed run from its checkpoint")
    resume.add_argument("directory", type=Path, help="the --out directory of the run")
    resume.add_argument("--quiet", action="store_true", help="no progress output")
    resume.add_argument("--no-plot", action="store_true", help="do not write the PNG plot")
    plot = sub.add_parser("plot", help="redraw the plot of a finished run from its summary.json")
    plot.add_argument("directory", type=Path)
    return p


def main(argv: list[str] | None = None) -> int:
    """The command line; ``argv`` None: the process's own arguments (as the ``fbmflow`` program,
    which keeps its signal handlers to the end), else these (as from Python)."""
    args = _parser().parse_args(argv)
    first = launched_processes()[0] == 0  # the one of several processes that speaks
    level = logging.WARNING if getattr(args, "quiet", False) else logging.INFO
    logging.basicConfig(level=level if first else logging.ERROR, format="%(message)s", stream=sys.stderr)
    from .run import Progress

    progress = None if getattr(args, "quiet", False) or not first else Progress()
    with interrupt.handling(restore=argv is not None):
        status = _command(args, progress)
    if argv is None:  # the program: its work is done, a late signal must not kill its exit
        interrupt.ignore()
    return status


def _command(args, progress) -> int:
    """The command ``args`` under the signal handlers; its exit status."""
    from .io import CheckpointError
    from .run import OutputError, RunInterrupted, output_folder

    try:
        from .scenes import SCENES, get_scene, load_scene, resume, run_scene
        from .scenes.registry import check_estimate

        if args.command == "scenes":
            for name, scene in SCENES.items():
                print(f"{name}  {scene.description}")
            return 0
        if args.command == "plot":
            summary_path = args.directory / "summary.json"
            if not summary_path.is_file():
                raise ParamError(f"{summary_path} not found; give the --out directory of a finished run")
            try:
                summary = json.loads(summary_path.read_text())
                scene = get_scene(summary["scene"])
            except (json.JSONDecodeError, UnicodeDecodeError, KeyError, TypeError) as err:
                raise ParamError(f"{summary_path} is damaged ({err}); run the scene again") from None
            path = args.directory / f"{scene.name}.png"
            try:
                plotted = scene.plot(summary, path)
            except (KeyError, TypeError, ValueError, IndexError) as err:
                raise ParamError(f"{summary_path} does not hold what the {scene.name} plot needs ({err!r}); "
                                 "run the scene again") from None
            print(path if plotted else f"scene {scene.name} has no plot")
            return 0
        if args.command == "resume":
            world()  # every process joins before any can fail alone
            out = args.directory
            log.info("fbmflow %s: resuming %s", __version__, out)
            summary = resume(out, progress, plot=not args.no_plot)
            if not isinstance(summary, dict):  # a run of the Python API: no summary of its own
                log.info("done: t = %.6g after %d steps; run data in %s", summary.t, summary.step_count,
                         out / "run.h5")
                return 0
        else:
            if args.checkpoint_every < 0 or args.fields_every < 0:
                raise ParamError("--checkpoint-every and --fields-every must be >= 0")
            comm = world()  # every process joins before any can fail alone (a lone exit would hang the rest)
            scene, params, level = load_scene(args.scene, args.level, args.overrides)
            if args.estimate_error:
                check_estimate(scene, level)
            out = Path("fbmflow-out") / scene.name if args.out is None else \
                on_first(lambda: output_folder(args.out), comm) or Path(args.out)
            log.info("fbmflow %s: %s at level %d -> %s", __version__, scene.name, level, out)
            summary = run_scene(scene, params, level, out, progress, plot=not args.no_plot,
                                checkpoint_every=args.checkpoint_every, fields_every=args.fields_every,
                                fields_format=args.fields_format, overwrite=args.overwrite,
                                estimate_error=args.estimate_error)
        log.info("done in %.2f s: %d cells, %d unknowns, %d Newton iterations (%s); summary in %s",
                 summary["wall_time_s"], summary["n_cells"], summary["n_dofs"],
                 summary["newton_iterations"], summary.get("linear_solver") or "linear solver not recorded",
                 out / "summary.json")
        return 0
    except RunInterrupted as err:
        _say(f"fbmflow: {err}\n")
        return err.exit_status
    except interrupt.StopRequested as err:
        _say(f"fbmflow: {err}; nothing to resume from (no time loop had started)\n")
        return err.exit_status
    except KeyboardInterrupt:
        _say("fbmflow: aborted; the last checkpoint (if any) is in the output directory\n")
        return 130
    except (ParamError, CheckpointError, LaunchError) as err:
        _say(f"fbmflow: error: {err}\n")
        return 2
    except OutputError as err:
        _say(f"fbmflow: error: {err}\n")
        return 1
    except OSError as err:  # a file the run reads or writes, outside the guarded paths
        where = f"{err.filename}: " if err.filename else ""
        _say(f"fbmflow: error: {where}{err.strerror or err}\n")
        return 1
    except ConvergenceError as err:
        remedy = err.remedy or STEADY_REMEDY
        _say(f"fbmflow: run failed: {err}. Remedy: {remedy}.\n")
        return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
