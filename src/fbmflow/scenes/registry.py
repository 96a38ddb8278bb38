"""Scene lookup, scene files and the run that writes ``summary.json``."""
from __future__ import annotations

import json
import logging
import math
import os
import time
import tomllib
from pathlib import Path

import numpy as np

from .. import __version__
from ..config import ParamError, from_dict, parse_value, set_dotted, to_dict
from ..io import export_csv
from ..parallel import on_first, world
from ..run import OutputError, RunFiles, claim_once, output_folder, read_run_info
from ..simulation import Simulation
from ..solvers.choice import peak_resident_memory
from . import richardson
from .base import Scene, SimulationScene
from .cavity import Cavity2D
from .channel import Channel2D, Channel3D
from .dfg import DFG2D1, DFG3D1Z
from .dkt import DKT2D
from .glowinski import GlowinskiFreeFall
from .sedimentation import FluidizedBed2D, Sedimentation2D, Sedimentation3D
from .suspension import Suspension2D, Suspension3D
from .taylor_green import TaylorGreen2D
from .tencate import TenCate

log = logging.getLogger(__name__)

#: the built-in scenes by name
SCENES: dict[str, Scene] = {s.name: s for s in (Cavity2D(), Channel2D(), Channel3D(), TaylorGreen2D(),
                                                DFG2D1(), DFG3D1Z(), GlowinskiFreeFall(), TenCate(), DKT2D(),
                                                Sedimentation2D(), Sedimentation3D(), FluidizedBed2D(),
                                                Suspension2D(), Suspension3D())}


def get_scene(name: str) -> Scene:
    """A built-in scene by name; ParamError listing the names otherwise."""
    try:
        return SCENES[name]
    except KeyError:
        raise ParamError(f"unknown scene {name!r}; built-in scenes: {', '.join(SCENES)} "
                         "(or give a path to a .toml scene file)") from None


def memory_figures(n_dofs: int) -> dict:
    """``peak_memory_gb`` (the process's peak resident memory, interpreter and compiled kernels
    included) and ``bytes_per_unknown`` (that over the finest level's unknowns) for a summary;
    empty where the platform does not report the peak."""
    peak = peak_resident_memory()
    if peak is None:
        return {}
    return {"peak_memory_gb": peak / 1e9, "bytes_per_unknown": peak / max(n_dofs, 1)}


def load_scene(spec: str, level: int | None = None, overrides: list[str] = ()):
    """Resolve a scene name or TOML file plus ``KEY=VALUE`` overrides.

    A scene file names its base scene and may set the level and any parameter section::

        scene = "cavity-2d"
        level = 4
        [fluid]
        re = 400

    Returns ``(scene, params, level)``; raises ParamError on any bad input.
    """
    data: dict = {}
    if spec.endswith(".toml") or (spec not in SCENES and Path(spec).is_file()):  # a built-in name wins
        path = Path(spec)
        if not path.is_file():
            raise ParamError(f"scene file {spec!r} not found")
        try:
            data = tomllib.loads(path.read_text())
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as err:
            raise ParamError(f"scene file {spec!r} is not valid TOML: {err}") from None
        if "scene" not in data:
            raise ParamError(f"scene file {spec!r} lacks the key 'scene' naming a built-in scene")
        name = data.pop("scene")
        if not isinstance(name, str):
            raise ParamError(f"scene file {spec!r}: 'scene' must be a string, got {name!r}")
        file_level = data.pop("level", None)
        if file_level is not None and level is None:
            level = file_level
    else:
        name = spec
    scene = get_scene(name)
    for item in overrides:
        key, sep, value = item.partition("=")
        if not sep:
            raise ParamError(f"--set expects KEY=VALUE, got {item!r}")
        set_dotted(data, key.strip(), parse_value(value.strip()))
    params = from_dict(scene.Params, data)
    return scene, params, check_level(scene, scene.default_level if level is None else level)


def check_level(scene: Scene, level) -> int:
    """``level`` if it is an integer from 0 to the scene's ``max_level``, else ParamError."""
    if isinstance(level, bool) or not isinstance(level, int) or not 0 <= level <= scene.max_level:
        raise ParamError(f"level must be an integer from 0 to {scene.max_level} for {scene.name}, "
                         f"got {level!r}")
    return level


def run_scene(scene: Scene, params, level: int, out: Path, progress=None, plot: bool = True,
              checkpoint_every: int = 0, resume: bool = False, fields_every: int = 0,
              fields_format: str = "xdmf", overwrite: bool = False, estimate_error: bool = False) -> dict:
    """Run ``scene`` and write ``out/summary.json`` (and ``out/<scene>.png``); returns the summary.

    Time-dependent scenes (:class:`~fbmflow.scenes.base.SimulationScene`) also write ``run.json``
    (what :func:`resume_scene` needs), the per-step particle data ``run.h5`` and its CSV export
    ``particles.csv``, with ``checkpoint_every > 0`` a checkpoint every that many steps and with
    ``fields_every > 0`` ParaView output (:func:`~fbmflow.run.run_loop`); ``resume`` continues
    from the checkpoint in ``out``. Ctrl-C and SIGTERM end such a run after the step under way
    with a checkpoint (:class:`~fbmflow.run.RunInterrupted`). The run owns ``out`` while it
    writes (:func:`~fbmflow.run.claim`): a folder that holds another run's results is refused
    unless ``overwrite``. ``summary.json`` is written before the plot, which only warns when it
    fails.

    With ``estimate_error`` the scene then runs at the one or two coarser levels too (in
    ``out/coarser/level-K``, the time step following the mesh where the scene's does), and
    ``summary.json`` gets ``error_estimate``: per quantity the Richardson estimate of its error,
    the extrapolated value and the observed order, or why the levels are not yet in the
    asymptotic range (:mod:`fbmflow.scenes.richardson`); ``out/error_estimate.png`` draws them.
    """
    if estimate_error:
        check_estimate(scene, level)
    comm = world()  # the processes an MPI launcher started: the first writes, all compute
    out = on_first(lambda: output_folder(out), comm) or Path(out)
    if not isinstance(scene, SimulationScene) and (checkpoint_every or resume or fields_every):
        raise ParamError(f"scene {scene.name} has no time loop to checkpoint, resume or write fields of")
    meta = {"scene": scene.name, "level": level, "params": to_dict(params), "fbmflow_version": __version__}
    with claim_once(out, resume, overwrite, comm):
        t0 = time.perf_counter()
        if isinstance(scene, SimulationScene):
            files = RunFiles(out, checkpoint_every, resume, fields_every, fields_format, meta,
                             carry={"estimate_error": True} if estimate_error else {})
            result = scene.run(params, level, progress, files)
            on_first(lambda: _write(out / "particles.csv",
                                    lambda: export_csv(out / "run.h5", out / "particles.csv")), comm)
        else:
            result = scene.run(params, level, progress)
        wall = time.perf_counter() - t0
        summary = {"scene": scene.name, "fbmflow_version": __version__, "params": to_dict(params),
                   "level": level, "n_cells": result.n_cells, "n_dofs": result.n_dofs,
                   "steps": result.steps, "wall_time_s": wall, "linear_solver": result.linear_solver,
                   "newton_iterations": result.newton_iterations, **memory_figures(result.n_dofs),
                   "quantities": finite(result.quantities), "processes": comm.size}
        on_first(lambda: _save_summary(out, summary), comm)
    if estimate_error:
        summary = _estimate_error(scene, params, level, out, progress, plot, summary)
    if plot and comm.rank == 0:
        try:
            if scene.plot(summary, out / f"{scene.name}.png"):
                log.info("plot written to %s", out / f"{scene.name}.png")
        except Exception as err:  # the results are written; a plot that fails loses nothing
            log.warning("the plot %s could not be drawn (%s: %s); the results are in %s",
                        out / f"{scene.name}.png", type(err).__name__, err, out / "summary.json")
    return summary


def _save_summary(out: Path, summary: dict) -> None:
    """Write ``out/summary.json`` whole (strict JSON) or raise OutputError."""
    text = json.dumps(summary, indent=1, allow_nan=False)
    _write(out / "summary.json", lambda: _replace(out / "summary.json", text))


def check_estimate(scene: Scene, level: int) -> None:
    """ParamError unless an error estimate of ``scene`` at ``level`` has a coarser level to run."""
    if level == 0:
        raise ParamError(f"--estimate-error needs a coarser level than {level}: run {scene.name} at level 1 "
                         "or more")


def _estimate_error(scene: Scene, params, level: int, out: Path, progress, plot: bool, summary: dict) -> dict:
    """Run ``scene`` at the (up to) two levels below ``level`` and add the Richardson estimates
    to ``summary`` and ``out/summary.json`` (:func:`run_scene`)."""
    from ..solvers import ConvergenceError

    levels, coarser, failed = [], [], {}
    for k in range(max(level - 2, 0), level):
        log.info("error estimate: %s at level %d", scene.name, k)
        try:
            coarser.append(run_scene(scene, params, k, out / "coarser" / f"level-{k}", progress, plot=False,
                                     overwrite=True))
            levels.append(k)
        except ConvergenceError as err:  # a level too coarse to solve: the estimate does without it
            log.warning("error estimate: level %d failed (%s); it is left out", k, err)
            failed[k] = str(err)
    if not coarser or levels[-1] != level - 1:
        coarser, levels = [], []  # the levels must be consecutive
    estimates = richardson.estimate([*coarser, summary]) if coarser else {}
    summary["error_estimate"] = {"levels": [*levels, level], "quantities": finite(estimates),
                                 "failed_levels": failed,
                                 "wall_time_s": sum(s["wall_time_s"] for s in coarser)}
    comm = world()
    on_first(lambda: _save_summary(out, summary), comm)
    log.info("error estimates (levels %s):\n%s", ", ".join(map(str, [*levels, level])),
             richardson.table(estimates))
    if plot and comm.rank == 0:
        try:
            richardson.plot(estimates, [*levels, level], out / "error_estimate.png",
                            f"{scene.name}: Richardson error estimate at level {level}")
        except Exception as err:  # the estimates are written; a plot that fails loses nothing
            log.warning("the plot %s could not be drawn (%s: %s)", out / "error_estimate.png",
                        type(err).__name__, err)
    return summary


def finite(value):
    """``value`` (nested dicts and lists of numbers) with what JSON cannot hold as a number made
    ``None``: NaN, infinities and complex numbers (a quantity that could not be computed)."""
    if isinstance(value, dict):
        return {k: finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [finite(v) for v in value]
    if isinstance(value, (complex, np.complexfloating)):
        return None
    if isinstance(value, (float, np.floating)) and not math.isfinite(value):
        return None
    return value.item() if isinstance(value, np.generic) else value


def _replace(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` whole or not at all (a temporary file renamed over it)."""
    tmp = path.with_name(path.name + ".tmp")
    try:
        tmp.write_text(text)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def _write(path: Path, action) -> None:
    """``action()``, a write of ``path``; an OS error an OutputError naming the file and the cause."""
    try:
        action()
    except OSError as err:
        raise OutputError(f"cannot write {path}: {err.strerror or err}") from None


def resume_scene(out: Path, progress=None, plot: bool = True) -> dict:
    """Continue the scene run in ``out`` (written by :func:`run_scene`) from its checkpoint, and
    then, where the run was asked for it, estimate its error (the coarser levels run whole);
    ParamError (CheckpointError) when there is nothing usable to resume."""
    out = Path(out)
    info, _ = read_run_info(out)
    try:
        scene = get_scene(info["scene"])
        params = from_dict(scene.Params, info["params"])
        level, every, fields = info["level"], int(info["checkpoint_every"]), int(info.get("fields_every", 0))
        fmt, estimate = str(info.get("fields_format", "xdmf")), bool(info.get("estimate_error", False))
    except (KeyError, TypeError, ValueError) as err:
        raise ParamError(f"{out / 'run.json'} is damaged ({err!r}); start the run again") from None
    level = check_level(scene, level)
    if not (out / "run.h5").is_file():
        raise ParamError(f"{out / 'run.h5'} is missing: the resumed run would keep only the steps after its "
                         "checkpoint; restore the file or start the run again")
    return run_scene(scene, params, level, out, progress, plot, checkpoint_every=every, resume=True,
                     fields_every=fields, fields_format=fmt, estimate_error=estimate)


def resume(out, progress=None, plot: bool = True):
    """Continue the run in the folder ``out`` from its checkpoint to its end, whichever made it:
    a scene (:func:`resume_scene`; returns the summary) or :meth:`Simulation.run
    <fbmflow.simulation.Simulation.run>` (the simulation made again from the run's set-up;
    returns the simulation, advanced to its end). ParamError when ``out`` holds no run to resume."""
    info, setup = read_run_info(out)
    if info.get("kind") != "simulation":
        return resume_scene(out, progress, plot)
    if setup is None:
        raise ParamError(f"{Path(out) / 'setup.pickle'} is missing (the run's set-up could not be stored); "
                         "make the simulation again as the run's script did and call "
                         f"sim.run({str(out)!r}, resume=True)")
    sim = Simulation(**setup)
    sim.run(out, checkpoint_every=int(info["checkpoint_every"]), fields_every=int(info["fields_every"]),
            fields_format=str(info["fields_format"]), resume=True, progress=progress is not None)
    return sim
