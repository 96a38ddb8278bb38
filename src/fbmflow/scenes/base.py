"""The scene contract: a named, validated set-up that runs and reports named quantities.

A scene defines its parameter dataclass, its mesh at refinement level 0 (each level halves h) and
its default level, a ``run`` that returns a :class:`SceneResult`, and optionally a ``plot`` of
its key curves. One scene library feeds the command line, the tests, the benchmarks and the
examples.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from ..run import RunFiles, run_loop

log = logging.getLogger(__name__)

# (step, n_steps, time or None if steady[, {name: value} about the step])
Progress = Callable[..., None]


@dataclass
class SceneResult:
    """What a scene run produced.

    Attributes
    ----------
    quantities : flat dict of named results (numbers or lists of numbers)
    linear_solver : the flow's linear solver in words
        (:attr:`~fbmflow.flow.navier_stokes.NavierStokesProblem.linear_solver_description`)
    """

    quantities: dict[str, Any]
    n_cells: int
    n_dofs: int
    steps: int = 0
    newton_iterations: int = 0
    extra: dict[str, Any] = field(default_factory=dict)
    linear_solver: str = ""


def pyplot():
    """``matplotlib.pyplot`` on the non-interactive Agg backend (scene plots are files)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig, path) -> bool:
    """Lay ``fig`` out, write it to ``path`` (PNG, 120 dpi) and close it; True: a plot was written."""
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    pyplot().close(fig)
    return True


class Scene:
    """Base class of the built-in scenes (subclasses set the class attributes)."""

    name: str = ""
    description: str = ""
    Params: type = object
    default_level: int = 0
    max_level: int = 8

    def run(self, params, level: int, progress: Progress | None = None) -> SceneResult:
        raise NotImplementedError

    def plot(self, summary: dict, path) -> bool:
        """Save a PNG of the key curves of a finished run; False when the scene has none."""
        return False


@dataclass
class Setup:
    """A built time-dependent scene: the simulation, its time step (None: adaptive) and number of
    steps (adaptive: at the first step's size)."""

    sim: Any
    dt: float | None
    n_steps: int


class SimulationScene(Scene):
    """A scene whose run is the time loop of a :class:`~fbmflow.simulation.Simulation`.

    Subclasses give :meth:`build`, :meth:`observe` (one row of named time series per step, and at
    ``t = 0``), :meth:`quantities` and optionally :meth:`stop`. The loop is the one every run
    takes (:func:`~fbmflow.run.run_loop`: ``run.h5``, fields, checkpoints, resume, signals); the
    scene's series travel in its checkpoints.
    """


    def build(self, params, level: int) -> Setup:
        raise NotImplementedError

    def observe(self, params, sim) -> dict[str, float]:
        raise NotImplementedError

    def stop(self, params, row: dict) -> bool:
        return False

    def _observe(self, params, sim) -> dict[str, float]:
        """:meth:`observe` and the Courant number of the last step, ``_courant``: the fastest
        particle's speed times the step over the finest cell (``courant_number``, the largest the
        run met)."""
        v = sim.particles.velocity
        dt = sim.control.last_dt if sim.control else sim.dt
        speed = float(np.sqrt((v**2).sum(axis=1)).max(initial=0.0))
        return {**self.observe(params, sim), "_courant": speed * dt / min(sim.mesh.finest_spacing)}

    def quantities(self, params, series: dict[str, list], sim) -> dict:
        raise NotImplementedError

    def run(self, params, level: int, progress: Progress | None = None, files: RunFiles | None = None,
            stop_on_failure: bool = False) -> SceneResult:
        """Run the time loop (:func:`~fbmflow.run.run_loop`). A step that fails (ConvergenceError)
        raises, after saving the last good state when writing files; with ``stop_on_failure`` the
        run ends at the last good step instead and the result carries the error in
        ``extra["failure"]`` (benchmarks: a run that fails in the last approach to a wall keeps the
        curve it computed)."""
        from ..config import ParamError

        files = files or RunFiles()
        try:
            setup = self.build(params, level)
        except ParamError:
            raise
        except ValueError as err:  # the simulation refused the scene it was given
            raise ParamError(f"{self.name}: {err}") from None
        sim = setup.sim
        resumed = None
        if files.resume:
            state, resumed = self._resume_checkpoint(Path(files.out) / "checkpoint.h5", params, files.meta)
            sim.set_state(state)
            log.info("resumed from step %d (t = %.6g)", sim.step_count, sim.t)
        done = run_loop(sim, setup.n_steps, setup.dt, files, observe=lambda s: self._observe(params, s),
                        until=lambda row: self.stop(params, row), progress=progress, resumed=resumed,
                        stop_on_failure=stop_on_failure)
        quantities = {**self.quantities(params, done.series, sim), **self._steps(setup, sim),
                      "courant_number": max(done.series.pop("_courant", []), default=0.0),
                      "force_estimator": sim.system.estimator.name}
        return SceneResult(quantities, sim.mesh.n_cells, sim.n_dofs,
                           steps=sim.step_count, newton_iterations=done.newton_iterations,
                           extra={} if done.failure is None else {"failure": done.failure},
                           linear_solver=sim.flow.linear_solver_description)

    @staticmethod
    def _steps(setup: Setup, sim) -> dict:
        """``time_step`` [s] (adaptive: the mean, with the smallest and the largest and the
        rejected steps)."""
        control = sim.control
        if control is None:
            return {"time_step": setup.dt}
        return {"time_step": sim.t / max(sim.step_count, 1), "time_step_smallest": control.smallest,
                "time_step_largest": control.largest, "rejected_steps": control.rejected}

    @staticmethod
    def _resume_checkpoint(path, params, meta: dict) -> tuple[dict, dict]:
        """``(state, extra)`` of the checkpoint at ``path`` if it belongs to the run described by
        ``meta`` (CheckpointError otherwise). Its parameters are compared resolved with today's
        defaults: a parameter added since it was written takes its default, which reproduces
        the behaviour of the code that wrote it."""
        from ..config import ParamError, from_dict, to_dict
        from ..io import CheckpointError, load_checkpoint
        from ..io.rundata import difference

        state, saved, extra = load_checkpoint(path, expect={k: v for k, v in meta.items() if k != "params"})
        if "params" in meta:
            try:
                resolved = to_dict(from_dict(type(params), saved.get("params")))
            except ParamError as err:
                resolved = f"<not valid today: {err}>"
            differs = difference(resolved, meta["params"], "params")
            if differs:
                raise CheckpointError(f"checkpoint {path} is for other parameters: {differs}; resume it with "
                                      "its own settings or start afresh")
        return state, extra
