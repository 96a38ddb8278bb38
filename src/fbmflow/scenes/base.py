"""The scene contract: a named, validated set-up that runs and reports named quantities.

A scene defines its parameter dataclass, its mesh at refinement level 0 (each level halves h) and
its default level, a ``run`` that returns a :class:`SceneResult`, and optionally a ``plot`` of
its key curves. One scene library feeds the command line, the tests, the benchmarks and the
examples.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

log = logging.getLogger(__name__)

# (step, n_steps, time or None if steady[, {name: value} about the step])
Progress = Callable[..., None]


@dataclass
class SceneResult:
    """What a scene run produced.

    quantities : flat dict of named results (numbers or lists of numbers)
    linear_solver : the flow's linear solver in words
        (:attr:`~fbmflow.flow.NavierStokesProblem.linear_solver_description`)
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
    """A built time-dependent scene: the simulation, its time step and number of steps."""

    sim: Any
    dt: float
    n_steps: int


@dataclass
class RunFiles:
    """Where a time-dependent run keeps its files (None: no files) and how often it checkpoints."""

    out: Any = None
    checkpoint_every: int = 0
    resume: bool = False
    fields_every: int = 0  # ParaView output every that many steps (0: none)
    fields_format: str = "xdmf"  # or "vtu"
    meta: dict = field(default_factory=dict)  # scene, level, params, fbmflow_version
    stop: Callable[[], bool] | None = None  # asked after every step: True ends the run (RunInterrupted)


class RunInterrupted(RuntimeError):
    """A run stopped on request (``RunFiles.stop``) after a completed step, its state saved."""

    def __init__(self, step: int, out):
        self.step, self.out = step, out
        where = f"; `fbmflow resume {out}` continues" if out is not None else ""
        super().__init__(f"interrupted at step {step}{where}")


class SimulationScene(Scene):
    """A scene whose run is the time loop of a :class:`~fbmflow.simulation.Simulation`.

    Subclasses give :meth:`build`, :meth:`observe` (one row of named time series per step, and at
    ``t = 0``), :meth:`quantities` and optionally :meth:`stop`. The loop here writes the run data
    (``run.h5``), the ParaView output every ``fields_every`` steps, checkpoints every
    ``checkpoint_every`` steps (``checkpoint.h5``; also the last good state when a step fails),
    and resumes from the checkpoint: the resumed run repeats the uninterrupted one's iterations,
    because the stored Newton factorisation is dropped at every checkpoint in both.
    """

    def build(self, params, level: int) -> Setup:
        raise NotImplementedError

    def observe(self, params, sim) -> dict[str, float]:
        raise NotImplementedError

    def stop(self, params, row: dict) -> bool:
        return False

    def quantities(self, params, series: dict[str, list], sim) -> dict:
        raise NotImplementedError

    def run(self, params, level: int, progress: Progress | None = None, files: RunFiles | None = None,
            stop_on_failure: bool = False) -> SceneResult:
        """Run the time loop. A step that fails (ConvergenceError) raises, after saving the last
        good state when writing files; with ``stop_on_failure`` the run ends at the last good step
        instead and the result carries the error in ``extra["failure"]`` (benchmarks: a run that
        fails in the last approach to a wall keeps the curve it computed)."""
        from pathlib import Path

        from ..config import ParamError
        from ..io import FieldWriter, RunData, save_checkpoint
        from ..solvers import ConvergenceError

        files = files or RunFiles()
        try:
            setup = self.build(params, level)
        except ParamError:
            raise
        except ValueError as err:  # the simulation refused the scene it was given
            raise ParamError(f"{self.name}: {err}") from None
        sim = setup.sim
        series = {k: [v] for k, v in self.observe(params, sim).items()}
        newton_its = 0
        out = Path(files.out) if files.out is not None else None
        data = None
        if files.resume:
            state, extra = self._resume_checkpoint(out / "checkpoint.h5", params, files.meta)
            sim.set_state(state)
            series, newton_its = extra["series"], extra["newton_iterations"]
            log.info("resumed from step %d (t = %.6g)", sim.step_count, sim.t)
        fields = None
        if out is not None:
            data = RunData(out / "run.h5", files.meta, resume_step=sim.step_count if files.resume else None)
            if not files.resume:
                data.append(self._row(sim, None))
            if files.fields_every:
                fields = FieldWriter(out, sim.flow.space, start_step=sim.step_count, fmt=files.fields_format)
                if not files.resume:
                    fields.write(0, sim.t, sim.x, sim.owner(), sim.particles,
                                 np.zeros_like(sim.particles.position))

        def checkpoint(step):
            save_checkpoint(out / "checkpoint.h5", sim.state(), {**files.meta, "step": step},
                            {"series": series, "newton_iterations": newton_its})

        failure = None
        for k in range(sim.step_count + 1, setup.n_steps + 1):
            try:
                rep = sim.step(setup.dt)
            except ConvergenceError as err:
                if out is not None:
                    checkpoint(sim.step_count)  # the last good state, for inspection or resumption
                    err = ConvergenceError(f"{err}; the last good state (step {sim.step_count}) is in "
                                           f"{out / 'checkpoint.h5'}")
                if not stop_on_failure:
                    raise err from None
                log.warning("run stopped early: %s", err)
                failure = str(err)
                break
            newton_its += rep.newton_iterations
            row = self.observe(params, sim)
            for key, value in row.items():
                series[key].append(value)
            if data is not None:
                data.append(self._row(sim, rep))
            if fields is not None and k % files.fields_every == 0:
                fields.write(k, sim.t, sim.x, sim.owner(), sim.particles, rep.force)
            if progress:
                speed = np.linalg.norm(sim.particles.velocity, axis=1).max(initial=0.0)
                progress(k, setup.n_steps, rep.t, {"newton": rep.newton_iterations,
                                                   "solves": rep.linear.solves,
                                                   "linear": rep.linear.iterations, "max|U|": float(speed)})
            if self.stop(params, row):
                break
            if files.stop is not None and files.stop():
                if out is not None:
                    checkpoint(k)
                raise RunInterrupted(k, out)
            if files.checkpoint_every and k % files.checkpoint_every == 0 and k < setup.n_steps:
                sim.flow.forget_linearisation()
                if out is not None:
                    checkpoint(k)
        return SceneResult(self.quantities(params, series, sim), sim.flow.mesh.n_cells, sim.flow.n_dofs,
                           steps=sim.step_count, newton_iterations=newton_its,
                           extra={} if failure is None else {"failure": failure},
                           linear_solver=sim.flow.linear_solver_description)

    @staticmethod
    def _resume_checkpoint(path, params, meta: dict) -> tuple[dict, dict]:
        """``(state, extra)`` of the checkpoint at ``path`` if it belongs to the run described by
        ``meta`` (CheckpointError otherwise). Its parameters are compared resolved with today's
        defaults: a parameter added since it was written takes its default, which reproduces
        the behaviour of the code that wrote it."""
        from ..config import ParamError, from_dict, to_dict
        from ..io import CheckpointError, load_checkpoint

        state, saved, extra = load_checkpoint(path, expect={k: v for k, v in meta.items() if k != "params"})
        if "params" in meta:
            try:
                resolved = to_dict(from_dict(type(params), saved.get("params")))
            except ParamError as err:
                resolved = f"<not valid today: {err}>"
            if resolved != meta["params"]:
                raise CheckpointError(f"checkpoint {path} is for another params ({resolved!r}, this run has "
                                      f"{meta['params']!r}); resume it with its own settings or start afresh")
        return state, extra

    @staticmethod
    def _row(sim, rep) -> dict:
        p = sim.particles
        n, dim = p.position.shape
        zero = np.zeros((n, dim)), np.zeros((n, 3))
        return {"step": sim.step_count, "t": sim.t, "position": p.position, "velocity": p.velocity,
                "orientation": p.orientation, "angular_velocity": p.angular_velocity,
                "force": rep.force if rep is not None else zero[0],
                "torque": rep.torque if rep is not None else zero[1],
                "newton_iterations": rep.newton_iterations if rep is not None else 0,
                "linear_iterations": rep.linear.iterations if rep is not None else 0,
                "flow_solves": rep.flow_solves if rep is not None else 0,
                "linear_solves": rep.linear.solves if rep is not None else 0,
                "linear_sweeps": rep.linear.sweeps if rep is not None else 0,
                "linear_time_s": rep.linear.time_s if rep is not None else 0.0,
                "contacts": rep.contact.contacts if rep is not None and rep.contact is not None else 0}
