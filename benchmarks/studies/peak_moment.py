"""Where in a time step the process's resident memory peaks.

Question: at which call does a ten Cate step reach its largest resident memory, so that a cut
of memory aims at what is alive then?
Answer: level 2, one step after the build, 2 threads: 2.91-2.97 GB in six processes, where
the step holds its hierarchy and system and makes a few vectors of the size of the solution: in
the Newton iteration's residual evaluations (``NavierStokesProblem.residual``; three processes),
in the coupling's sub-iteration, at the flow's drift (``ImplicitCoupling.advance``; two), or at
the Krylov method's true residual (``fgmres``; one). 0.83 GB after the build, 2.45-2.55 GB after
the step.
Measured: 2026-11-29, commit 06d603e; quoted in
docs/validation/multigrid-with-fictitious-boundaries.md, "Memory"
Run: python -m fbmbench peak_moment --scene ten-cate --level 2

A thread reads ``/proc/self/statm`` every 2 ms; whenever the resident memory is larger than
before, it sends the process SIGUSR1, whose handler (in the main thread, at its next Python
instruction) keeps the main thread's stack. Prints the
resident memory after the build and after the steps, the peak, and the innermost frames of
the stack at the peak; writes nothing. Linux only.
"""
from __future__ import annotations

import os
import signal
import threading
import time
import traceback


def _resident() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def run(*, scene: str = "ten-cate", level: int = 2, steps: int = 1, frames: int = 12,
        set: list[str] = ()) -> None:
    """Build ``scene`` at ``level``, take ``steps`` steps, print the stack at the peak.

    Parameters
    ----------
    scene : a scene name (``fbmflow scenes``)
    level : the mesh level
    steps : time steps to take (>= 1)
    frames : innermost frames of the stack to print
    set : scene parameters (KEY=VALUE), as ``fbmflow run --set``
    """
    if steps < 1:
        raise SystemExit(f"--steps must be at least 1, got {steps}")
    from fbmflow.scenes.registry import load_scene

    found, params, lvl = load_scene(scene, level, list(set))
    setup = found.build(params, lvl)
    state = {"largest": 0, "stack": None, "stop": False}

    def keep_stack(signum, frame):
        state["stack"] = traceback.extract_stack(frame)

    def watch():
        while not state["stop"]:
            now = _resident()
            if now > state["largest"]:
                state["largest"] = now
                os.kill(os.getpid(), signal.SIGUSR1)
            time.sleep(0.002)

    previous = signal.signal(signal.SIGUSR1, keep_stack)

    print(f"after the build: {_resident() / 1e9:.3f} GB resident", flush=True)
    watcher = threading.Thread(target=watch, daemon=True)
    watcher.start()
    for _ in range(steps):
        setup.sim.step(setup.dt)
    state["stop"] = True
    watcher.join()
    signal.signal(signal.SIGUSR1, previous)
    print(f"after {steps} step(s): {_resident() / 1e9:.3f} GB resident; the peak "
          f"{state['largest'] / 1e9:.3f} GB ({setup.sim.flow.n_dofs} unknowns), at:")
    for f in (state["stack"] or [])[-frames:]:
        print(f"  {'/'.join(f.filename.split('/')[-2:])}:{f.lineno} {f.name}")
