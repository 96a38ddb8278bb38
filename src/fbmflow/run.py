"""The one run loop: steps a simulation to its end and keeps what a run must not lose.

:func:`run_loop` serves :meth:`fbmflow.simulation.Simulation.run`, the built-in scenes
(:class:`~fbmflow.scenes.base.SimulationScene`) and so the command line alike. Given an output
folder (:class:`RunFiles`) it writes

* ``run.h5``: one row per step (:class:`~fbmflow.io.rundata.RunData`: positions, velocities, forces,
  solver work), row 0 the state it starts from;
* ``checkpoint.h5`` every ``checkpoint_every`` steps, when a step fails (the last good state), and
  when the run is stopped by Ctrl-C, SIGTERM or SIGHUP (:class:`RunInterrupted`; a second signal
  aborts at once: :mod:`fbmflow.interrupt`); a run resumed from it repeats the uninterrupted
  run's iterations exactly, because the
  stored Newton factorisation is dropped at every checkpoint in both;
* ParaView output every ``fields_every`` steps (:class:`~fbmflow.io.fields.FieldWriter`).

Progress goes to stderr through :class:`Progress`: a tqdm bar on a terminal or in a notebook, else
plain lines (a log file), at most one every few seconds.
"""
from __future__ import annotations

import contextlib
import json
import logging
import os
import pickle
import shutil
import signal
import socket
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from . import interrupt
from .config import ParamError
from .io import FieldWriter, RunData, save_checkpoint
from .parallel import SerialComm, max_over, on_first
from .solvers import ConvergenceError

log = logging.getLogger(__name__)


@dataclass
class RunFiles:
    """Where a run keeps its files (``out`` None: no files) and how often it checkpoints.

    out : folder; checkpoint_every : steps between checkpoints (0: only on failure and stop);
    resume : the run continues from ``out/checkpoint.h5`` (``run.h5`` is cut after its step);
    fields_every : ParaView output every that many steps (0: none); fields_format : ``xdmf`` or
    ``vtu``; meta : what identifies the run in its files (scene, level, params, version); carry :
    what a resume does after the run as the run was asked to (a scene's ``estimate_error``),
    written to ``run.json`` beside ``meta``; setup : what makes a script's simulation again
    (:func:`write_run_info`).
    """

    out: Path | None = None
    checkpoint_every: int = 0
    resume: bool = False
    fields_every: int = 0
    fields_format: str = "xdmf"
    meta: dict = field(default_factory=dict)
    carry: dict = field(default_factory=dict)
    setup: dict | None = None  # a script's simulation arguments (setup.pickle; None for a scene)


@dataclass
class RunResult:
    """What :func:`run_loop` did: the steps' reports, the series of observed rows (the starting
    row first; from the run's start where it resumed), the Newton iterations of all its steps
    (the resumed run's before), and the error that ended it early, if it did
    (``stop_on_failure``)."""

    reports: list
    series: dict[str, list]
    newton_iterations: int
    failure: str | None = None


class RunInterrupted(RuntimeError):
    """A run stopped on request (Ctrl-C, SIGTERM, SIGHUP: the signal ``signum``) after a completed
    step, its state saved; ``exit_status`` is ``128 + signum``."""

    def __init__(self, step: int, out, signum: int = signal.SIGINT):
        self.step, self.out, self.signum = step, out, int(signum)
        where = f"; `fbmflow resume {out}` continues" if out is not None else ""
        super().__init__(f"interrupted at step {step}{where}")

    @property
    def exit_status(self) -> int:
        return 128 + self.signum


class Progress:
    """A progress display on stderr, called as ``progress(step, n, t, info)`` (``t`` None for a
    steady stage; ``info``: what the step did, e.g. Newton iterations). A tqdm bar where stderr
    is a terminal or a notebook; else one line at most every ``every`` seconds, and the last."""

    def __init__(self, every: float = 10.0, stream=None):
        self.stream = stream or sys.stderr
        self.every = every
        self.bar = None
        self._last = -np.inf
        self._tty = bool(getattr(self.stream, "isatty", lambda: False)()) or "ipykernel" in sys.modules

    def __call__(self, step: int, n: int, t: float | None, info: dict | None = None) -> None:
        where = f"t = {t:.4g}" if t is not None else "steady stage"
        extra = {k: (f"{v:.3g}" if isinstance(v, float) else v) for k, v in (info or {}).items()}
        if self._tty:
            if self.bar is None:
                from tqdm.auto import tqdm

                self.bar = tqdm(total=n, initial=step - 1, file=self.stream, unit="step", dynamic_ncols=True)
            self.bar.set_description(where, refresh=False)
            self.bar.set_postfix(extra, refresh=False)
            self.bar.update(step - self.bar.n)
            if step >= n:
                self.bar.close()
            return
        now = time.monotonic()
        if now - self._last >= self.every or step >= n:
            self._last = now
            pairs = "".join(f"  {k} {v}" for k, v in extra.items())
            self.stream.write(f"step {step}/{n}  {where}{pairs}\n")
            self.stream.flush()


def run_loop(sim, n_steps: int, dt: float | None, files: RunFiles | None = None, *,
             observe: Callable | None = None, until: Callable | None = None,
             progress: Callable | None = None, callback: Callable | None = None,
             resumed: dict | None = None, stop_on_failure: bool = False) -> RunResult:
    """Step ``sim`` from its step count to ``n_steps`` in steps of ``dt`` [s]; ``dt = None``: to
    ``sim.control.t_end`` in the adaptive steps of ``sim.control`` (:class:`~fbmflow.adaptive.StepControl`).

    ``sim``: a :class:`~fbmflow.simulation.Simulation` (``step``, ``state``, ``t``, ``step_count``,
    ``particles``, ``x``, ``flow``, ``owner``, ``force``). ``observe(sim) -> dict``: a row of named
    values after every step (and at the start), collected into the result's series and kept in
    the checkpoints; ``until(row) -> bool``: True ends the run after that step; ``callback(report)``
    after every step; ``progress(step, n, t, info)`` (:class:`Progress`). ``resumed``: what the
    checkpoint the state was restored from recorded (``series``, ``newton_iterations``). A step
    that fails (ConvergenceError) raises after saving the last good state (with files), or with
    ``stop_on_failure`` ends the run there, its error in the result. Ctrl-C or SIGTERM (with
    files) ends the run after the step with a checkpoint: :class:`RunInterrupted`
    (:mod:`fbmflow.interrupt`).
    """
    files = files or RunFiles()
    out = Path(files.out) if files.out is not None else None
    comm = getattr(sim, "comm", None) or SerialComm()  # the first process writes, all call
    series = {k: [v] for k, v in observe(sim).items()} if observe is not None else {}
    newton = 0
    if resumed is not None:
        series, newton = resumed.get("series", series), int(resumed.get("newton_iterations", 0))
    data = fields = state_bytes = None
    saved = {"step": sim.step_count if files.resume else None}  # the last checkpoint's step

    def guarded(path, action, nbytes: float = 0.0):
        """``action()``, a write of ``path`` by the first process (every process calls this): a
        full disk or any OS error an OutputError on every process naming the file, the cause and
        the last checkpoint, which stays intact."""
        def write():
            try:
                if nbytes:
                    room(out, nbytes, path.name)
                return action()
            except (OSError, OutputError) as err:
                cause = err.strerror if isinstance(err, OSError) and err.strerror else str(err)
                kept = "" if saved["step"] is None else \
                    f"; the last checkpoint (step {saved['step']}) in {out / 'checkpoint.h5'} is intact: " \
                    f"fix the cause and `fbmflow resume {out}`"
                raise OutputError(f"cannot write {path}: {cause}{kept}") from None
        return on_first(write, comm)

    def write_fields(step: int, force) -> None:
        x_owner = sim.field_data()  # the whole mesh's flow and node owner, on the first process
        guarded(out / "fields", lambda: fields.write(step, sim.t, *x_owner, sim.particles, force),
                4.0 * state_bytes)

    if out is not None:
        if not files.resume:  # written once the set-up has passed its checks: a refused run leaves nothing
            guarded(out / "run.json", lambda: write_run_info(files, files.setup))
        state_bytes = 8.0 * sim.n_dofs + 64.0 * sim.particles.n * sim.particles.dim * 8
        data = guarded(out / "run.h5", lambda: RunData(out / "run.h5", files.meta,
                                                       sim.step_count if files.resume else None,
                                                       particles=sim.particles.n))
        if not files.resume:
            guarded(out / "run.h5", lambda: data.append(_row(sim, None)))
        if files.fields_every:
            fields = on_first(lambda: FieldWriter(out, sim.field_space(), start_step=sim.step_count,
                                                  fmt=files.fields_format), comm)
            if not files.resume:
                write_fields(0, np.zeros_like(sim.particles.position))

    def checkpoint(step: int) -> None:
        state = sim.state()
        state["x"] = sim.whole(state["x"])  # the whole mesh's flow: a resume on any number of processes
        guarded(out / "checkpoint.h5", lambda: save_checkpoint(
            out / "checkpoint.h5", state, {**files.meta, "step": step},
            {"series": series, "newton_iterations": newton}), 2.0 * state_bytes)
        saved["step"] = step

    reports, failure = [], None
    with interrupt.handling(), interrupt.safe_point("step"):
        control = sim.control if dt is None else None
        k = sim.step_count
        while not control.finished(sim.t) if control else k < n_steps:
            k += 1
            if control:
                n_steps = k + control.remaining_steps(sim.t) - 1  # (for progress)
            try:
                report = sim.step(dt)
            except ConvergenceError as err:
                if out is not None:
                    checkpoint(sim.step_count)  # the last good state, for inspection or resumption
                    err = ConvergenceError(f"{err}; the last good state (step {sim.step_count}) is in "
                                           f"{out / 'checkpoint.h5'}", err.remedy)
                if not stop_on_failure:
                    raise err from None
                log.warning("run stopped early: %s", err)
                failure = str(err)
                break
            reports.append(report)
            newton += report.newton_iterations
            row = observe(sim) if observe is not None else {}
            for key, value in row.items():
                series.setdefault(key, []).append(value)  # (a key added since a checkpoint)
            if out is not None:
                guarded(out / "run.h5", lambda: data.append(_row(sim, report)))
            if out is not None and files.fields_every and k % files.fields_every == 0:
                write_fields(k, report.force)
            if callback is not None:
                callback(report)
            if progress is not None:
                speed = np.linalg.norm(sim.particles.velocity, axis=1).max(initial=0.0)
                progress(k, n_steps, report.t, {"newton": report.newton_iterations,
                                                "solves": report.linear.solves,
                                                "linear": report.linear.iterations, "max|U|": float(speed)})
            if until is not None and until(row):
                break
            signum = interrupt.requested()
            if comm.size > 1:  # all stop after the same step: a signal seen by any process
                signum = int(max_over(float(signum or 0), comm)) or None
            if signum is not None:
                if out is not None:
                    checkpoint(k)
                raise RunInterrupted(k, out, signum)
            if files.checkpoint_every and k % files.checkpoint_every == 0 and \
                    not (control.finished(sim.t) if control else k >= n_steps):
                sim.flow.forget_linearisation()
                if out is not None:
                    checkpoint(k)
    return RunResult(reports, series, newton, failure)


def _row(sim, report) -> dict:
    """One row of ``run.h5`` (:data:`~fbmflow.io.rundata.SCALARS` and ``ARRAYS``)."""
    p = sim.particles
    n, dim = p.position.shape
    work = report.linear if report is not None else None
    return {"step": sim.step_count, "t": sim.t, "position": p.position, "velocity": p.velocity,
            "orientation": p.orientation, "angular_velocity": p.angular_velocity,
            "force": report.force if report is not None else np.zeros((n, dim)),
            "torque": report.torque if report is not None else np.zeros((n, 3)),
            "newton_iterations": report.newton_iterations if report is not None else 0,
            "linear_iterations": work.iterations if work is not None else 0,
            "flow_solves": report.flow_solves if report is not None else 0,
            "linear_solves": work.solves if work is not None else 0,
            "linear_sweeps": work.sweeps if work is not None else 0,
            "linear_time_s": work.time_s if work is not None else 0.0,
            "contacts": report.contact.contacts if report is not None and report.contact is not None else 0}


def output_folder(out) -> Path:
    """``out`` as a folder, made if missing; ParamError when it is empty, names a file, lies below
    a file or cannot be made or written."""
    if str(out).strip() == "":
        raise ParamError("the output directory is empty; give --out DIR")
    out = Path(out)
    try:
        if out.exists() and not out.is_dir():
            raise ParamError(f"output directory {out} is a file; give another --out")
        out.mkdir(parents=True, exist_ok=True)
        probe = out / ".fbmflow-write-test"
        probe.touch()
        probe.unlink()
    except OSError as err:
        raise ParamError(f"cannot write to output directory {out}: {err.strerror or err}; "
                         "give another --out") from None
    return out


def write_run_info(files: RunFiles, setup: dict | None = None) -> None:
    """Write ``run.json`` (``files.meta`` and the file settings: what a resume needs) and, for a
    run of the Python API, its set-up ``setup`` (the simulation's arguments) as ``setup.pickle``.
    A set-up that cannot be pickled (a lambda as a boundary value) is left out with a warning:
    the run then resumes only from a simulation made again by its script."""
    (files.out / "run.json").write_text(json.dumps({**files.meta, **files.carry,
                                                    "checkpoint_every": files.checkpoint_every,
                                                    "fields_every": files.fields_every,
                                                    "fields_format": files.fields_format}, indent=1))
    if setup is None:
        return
    (files.out / "setup.pickle").unlink(missing_ok=True)
    try:
        blob = pickle.dumps(setup, protocol=pickle.HIGHEST_PROTOCOL)
    except (pickle.PicklingError, TypeError, AttributeError) as err:
        log.warning("the run's set-up cannot be stored (%s); fbmflow.resume cannot continue it, but "
                    "sim.run(out, resume=True) on a simulation made again by the same script can", err)
        return
    (files.out / "setup.pickle").write_bytes(blob)


def read_run_info(out) -> tuple[dict, dict | None]:
    """``(run.json's content, the set-up or None)`` of the run in the folder ``out``; ParamError
    when there is no readable ``run.json``. The set-up is unpickled: read only folders you trust."""
    out = Path(out)
    path = out / "run.json"
    if not path.is_file():
        raise ParamError(f"{path} not found; give the --out directory of a run started with "
                         "'fbmflow run ... --checkpoint-every N' or sim.run(out, ...)")
    try:
        info = json.loads(path.read_text())
        if not isinstance(info, dict):
            raise ValueError("not a table")
    except (ValueError, UnicodeDecodeError, OSError) as err:
        raise ParamError(f"{path} is damaged ({err}); start the run again") from None
    setup_path = out / "setup.pickle"
    setup = pickle.loads(setup_path.read_bytes()) if setup_path.is_file() else None
    return info, setup


class OutputError(RuntimeError):
    """A file of a run could not be written; the message names it, the cause, and what is intact."""


#: the files a run leaves in its folder (glob patterns), which ``overwrite`` replaces
RUN_FILES = ("run.json", "run.h5", "checkpoint.h5", "checkpoint.h5.tmp", "summary.json", "setup.pickle",
             "particles.csv", "fields*.xdmf", "fields*.h5", "fields_*.vtu", "fields.pvd", "particles_*.vtu",
             "particles.pvd")
#: the lock a run holds on its folder while it writes there
LOCK = ".fbmflow.lock"


def claim_once(out: Path, resume: bool, overwrite: bool, comm):
    """:func:`claim` of ``out`` by the first process of ``comm`` for all of them (a refusal
    raised on every process); the plain claim on one process."""
    if comm.size == 1:
        return claim(out, resume, overwrite)
    stack = contextlib.ExitStack()
    on_first(lambda: stack.enter_context(claim(out, resume, overwrite)), comm)
    return _holding(stack, out)


@contextlib.contextmanager
def _holding(stack: contextlib.ExitStack, out: Path):
    with stack:
        yield out


@contextlib.contextmanager
def claim(out: Path, resume: bool = False, overwrite: bool = False):
    """Own the folder ``out`` for the block: a lock file with this process's id and host, so that a
    second run or resume into it refuses while this one writes (a lock whose process is gone
    from this host is taken over). A new run (not ``resume``) refuses a folder holding another
    run's results unless ``overwrite``, which deletes them first (:data:`RUN_FILES`).
    ParamError naming the owner, or the results and the ways on."""
    out = Path(out)
    lock = out / LOCK
    me = {"pid": os.getpid(), "host": socket.gethostname(), "since": time.strftime("%Y-%m-%d %H:%M:%S")}
    for _ in range(2):
        try:
            fd = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
        except FileExistsError:
            owner = _owner(lock)
            if owner is not None and not _alive(owner):
                log.warning("taking over %s from process %s on %s, which is gone", out, owner.get("pid"),
                            owner.get("host"))
                lock.unlink(missing_ok=True)
                continue
            who = "another process" if owner is None else \
                f"process {owner.get('pid')} on {owner.get('host')} (since {owner.get('since')})"
            raise ParamError(f"{out} is being written by {who}; wait for it to end or give another --out "
                             f"(delete {lock} if that process is gone)") from None
        except OSError as err:
            raise ParamError(f"cannot write to output directory {out}: {err.strerror or err}; give another "
                             "--out") from None
        with os.fdopen(fd, "w") as f:
            json.dump(me, f)
        break
    try:
        if not resume:
            found = sorted({p.name for pattern in RUN_FILES for p in out.glob(pattern)})
            if found and not overwrite:
                raise ParamError(f"{out} holds another run's results ({', '.join(found[:3])}"
                                 f"{', ...' if len(found) > 3 else ''}); give --overwrite to replace them, "
                                 f"`fbmflow resume {out}` to continue that run, or another --out")
            for name in found:
                (out / name).unlink(missing_ok=True)
        yield out
    finally:
        lock.unlink(missing_ok=True)


def _owner(lock: Path) -> dict | None:
    try:
        owner = json.loads(lock.read_text())
        return owner if isinstance(owner, dict) else None
    except (OSError, ValueError):
        return None


def _alive(owner: dict) -> bool:
    """Whether the lock's process may still run: on another host always (it cannot be asked)."""
    if owner.get("host") != socket.gethostname():
        return True
    try:
        os.kill(int(owner.get("pid", -1)), 0)
    except ProcessLookupError:
        return False
    except (PermissionError, ValueError, TypeError, OverflowError):
        return True
    return True


def room(out: Path, nbytes: float, what: str) -> None:
    """OutputError when the disk holding ``out`` has less than twice ``nbytes`` (and 16 MB) free:
    a write stopped by a full disk can leave a broken file, or worse (HDF5)."""
    try:
        free = shutil.disk_usage(out).free
    except OSError:
        return
    if free < 2.0 * nbytes + 16e6:
        raise OutputError(f"the disk holding {out} is full: {free / 1e6:.0f} MB free, {what} needs about "
                          f"{nbytes / 1e6:.0f} MB")
