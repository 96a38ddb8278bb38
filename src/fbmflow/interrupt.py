"""Stopping a run on request: Ctrl-C (SIGINT), SIGTERM and SIGHUP, at a point where nothing is lost.

The handlers (:func:`handling`) only record a signal while a *safe point* lies ahead: the run loop
(:func:`fbmflow.run.run_loop`) ends the run after the step under way, with a checkpoint, and a
Newton iteration outside a run loop (a steady scene's solve, :func:`fbmflow.solvers.newton.solve_newton`)
stops after the iteration under way (:func:`check`). Where none lies ahead (a scene's set-up) the
first signal interrupts at once (:class:`StopRequested`). A second signal aborts at once, wherever
the run is, with one line on stderr: checkpoints and run files are written whole or not at all,
so the last checkpoint stays usable. The exit status of a stopped run is ``128 + signal``
(130 for Ctrl-C, 143 for SIGTERM, 129 for SIGHUP).

This module sits at the bottom of the package (it imports nothing of fbmflow), so that every
floor can offer a safe point.
"""
from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading

#: the signals that ask a run to stop
SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name))

_received: list[int] = []  # the signals received since the handlers were installed
_points: list[str] = []  # the safe points ahead, innermost last: "step" (run loop), "iteration" (Newton)


class StopRequested(KeyboardInterrupt):
    """A run stopped on request (a signal) at a safe point or, during set-up, at once."""

    def __init__(self, signum: int, where: str):
        self.signum, self.where = signum, where
        super().__init__(f"{signal.Signals(signum).name}: stopped {where}")

    @property
    def exit_status(self) -> int:
        return 128 + self.signum


def _handler(signum, frame) -> None:
    name = signal.Signals(signum).name
    if _received:
        sys.stderr.write(f"fbmflow: {name}: aborted at once; the last checkpoint (if any) is usable\n")
        sys.stderr.flush()
        os._exit(128 + signum)
    _received.append(signum)
    if not _points:
        raise StopRequested(signum, "during set-up")
    point = "this step" if "step" in _points else "this Newton iteration"
    sys.stderr.write(f"fbmflow: {name}: stopping after {point} (again to abort at once)\n")
    sys.stderr.flush()


@contextlib.contextmanager
def handling(restore: bool = True):
    """Install the handlers for :data:`SIGNALS` for the block (in the main thread; nested blocks
    keep the outer installation) and restore the previous ones after it; ``restore`` False keeps
    them for the rest of the process (the command line's: a second signal while it winds down
    still aborts cleanly)."""
    if threading.current_thread() is not threading.main_thread() or \
            signal.getsignal(SIGNALS[0]) is _handler:
        yield
        return
    previous = {sig: signal.signal(sig, _handler) for sig in SIGNALS}
    _received.clear()
    try:
        yield
    finally:
        if restore:
            for sig, old in previous.items():
                signal.signal(sig, old)
            _received.clear()


@contextlib.contextmanager
def safe_point(kind: str):
    """A block with a safe point ahead of kind ``"step"`` (the run loop: it asks :func:`requested`
    after each step) or ``"iteration"`` (a Newton solve: :func:`check` after each iteration, only
    where no run loop encloses it)."""
    _points.append(kind)
    try:
        yield
    finally:
        _points.pop()


def ignore() -> None:
    """Ignore :data:`SIGNALS` from now on: a program that has finished its work and only exits
    (where Python restores the default handlers while it shuts down, and a late second signal
    would kill it)."""
    if threading.current_thread() is threading.main_thread():
        for sig in SIGNALS:
            signal.signal(sig, signal.SIG_IGN)


def requested() -> int | None:
    """The signal received (its number), None while none was."""
    return _received[0] if _received else None


def check() -> None:
    """At a Newton iteration's end: StopRequested when a signal came and no run loop will stop
    the run after its step instead."""
    if _received and "step" not in _points:
        raise StopRequested(_received[0], "after a Newton iteration")
