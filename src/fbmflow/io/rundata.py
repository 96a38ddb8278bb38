"""Run data: every step's particle state, forces and solver work in one HDF5 file per run.

``run.h5`` holds extendable datasets with one row per step (row 0: the initial state):
``step (k,)``, ``t (k,)``, ``position``, ``velocity`` ``(k, n, dim)``, ``orientation``
(``(k, n)`` angles in 2D, ``(k, n, 4)`` quaternions in 3D), ``angular_velocity``
(``(k, n)`` / ``(k, n, 3)``), ``force (k, n, dim)``, ``torque (k, n, 3)``,
``newton_iterations``, ``flow_solves`` (coupling iterations), ``linear_solves``,
``linear_iterations`` (multigrid: cycles), ``linear_sweeps`` (smoothing sweeps on all levels),
``linear_time_s``, ``contacts`` ``(k,)``; and the
attributes ``scene``, ``level``, ``params`` (JSON of the resolved scene) and ``fbmflow_version``.
The file is opened for each appended row and closed again, so a killed run loses at most the
row being written; a resumed run cuts the rows after its checkpoint before appending.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .checkpoint import CheckpointError

#: the per-step scalars of ``run.h5``, one ``(k,)`` dataset each
SCALARS = ("step", "t", "newton_iterations", "flow_solves", "linear_solves", "linear_iterations",
           "linear_sweeps", "linear_time_s", "contacts")
#: the per-step particle arrays of ``run.h5``, ``(k, n, ...)`` datasets
ARRAYS = ("position", "velocity", "orientation", "angular_velocity", "force", "torque")


class RunData:
    """Appends rows to ``path``: created with ``meta`` attributes, or with ``resume_step`` the
    file of the run being resumed, whose rows after that step are dropped. CheckpointError when
    that file is missing, damaged, another run's (its ``meta`` differs, naming the key), holds
    another number of particles (``particles``) or stops short of ``resume_step``."""

    def __init__(self, path, meta: dict, resume_step: int | None = None, particles: int | None = None):
        import h5py

        self.path = Path(path)
        if resume_step is None:
            with h5py.File(self.path, "w") as f:
                for key, value in meta.items():
                    f.attrs[key] = _attribute(value)
            return
        try:
            with h5py.File(self.path, "r+") as f:
                for key, value in meta.items():
                    differs = difference(_value(f.attrs.get(key)), value, key)
                    if differs:
                        raise CheckpointError(f"{self.path} belongs to another run: {differs}; restore the "
                                              "run's own file or start the run again")
                steps = f["step"][()] if "step" in f else np.zeros(0, dtype=np.int64)
                if steps.size == 0 or steps.max() < resume_step:
                    last = int(steps.max()) if steps.size else "none"
                    raise CheckpointError(f"{self.path} ends at step {last}, before the checkpoint's step "
                                          f"{resume_step}; restore the run's own file or start the run again")
                if particles is not None and f["position"].shape[1] != particles:
                    raise CheckpointError(f"{self.path} holds {f['position'].shape[1]} particles, the run "
                                          f"{particles}; restore the run's own file or start the run again")
                keep = int(np.searchsorted(steps, resume_step, side="right"))
                for key in f.keys():
                    f[key].resize(keep, axis=0)
        except (OSError, KeyError) as err:
            raise CheckpointError(f"{self.path} cannot be read ({err}); restore it or start the run "
                                  "again") from None

    def append(self, row: dict) -> None:
        """One row: the keys of :data:`SCALARS` and :data:`ARRAYS`."""
        import h5py

        with h5py.File(self.path, "a") as f:
            for key in SCALARS + ARRAYS:
                value = np.asarray(row[key], dtype=float if key not in ("step",) else np.int64)
                if key not in f:
                    f.create_dataset(key, data=value[None], maxshape=(None,) + value.shape, chunks=True)
                else:
                    d = f[key]
                    d.resize(d.shape[0] + 1, axis=0)
                    d[-1] = value


def _attribute(value):
    """A ``meta`` value as stored in the file's attributes: numbers and strings as they are, the
    rest as JSON."""
    return value if isinstance(value, (int, float, str)) else json.dumps(value)


def _value(stored):
    """An attribute read back: JSON parsed where it is JSON of a table or list."""
    if isinstance(stored, bytes):
        stored = stored.decode()
    if isinstance(stored, str) and stored[:1] in "{[":
        try:
            return json.loads(stored)
        except ValueError:
            return stored
    return stored.item() if isinstance(stored, np.generic) else stored


def difference(have, want, key: str) -> str | None:
    """The first dotted key under which ``have`` (what a file holds) and ``want`` (this run's)
    differ, in words (``"params.fluid.viscosity is 0.1 there, 0.2 here"``), None where they
    agree (tuples and lists alike)."""
    if isinstance(have, dict) and isinstance(want, dict):
        for k in sorted(set(have) | set(want), key=str):
            if k not in have or k not in want:
                return f"{key}.{k} is {'missing' if k not in have else 'unknown'} there"
            found = difference(have[k], want[k], f"{key}.{k}")
            if found:
                return found
        return None
    if isinstance(have, (list, tuple)) and isinstance(want, (list, tuple)) and len(have) == len(want):
        for i, (a, b) in enumerate(zip(have, want)):
            found = difference(a, b, f"{key}[{i}]")
            if found:
                return found
        return None
    return None if have == want else f"{key} is {have!r} there, {want!r} here"


def export_csv(h5_path, csv_path) -> Path:
    """Particle trajectories of ``run.h5`` as CSV (one line per step and particle: step, t,
    particle, position, velocity, angular velocity, force components)."""
    import h5py

    with h5py.File(h5_path, "r") as f:
        step, t = f["step"][()], f["t"][()]
        X, V, F = f["position"][()], f["velocity"][()], f["force"][()]
        W = f["angular_velocity"][()]
    k, n, dim = X.shape
    W = W.reshape(k, n, -1)
    axes = "xyz"[:dim]
    wnames = ["omega_z"] if W.shape[2] == 1 else ["omega_x", "omega_y", "omega_z"]
    header = (["step", "t", "particle"] + list(axes) + [f"u_{a}" for a in axes] + wnames
              + [f"F_{a}" for a in axes])
    cols = [np.repeat(step, n), np.repeat(t, n), np.tile(np.arange(n), k), *X.reshape(-1, dim).T,
            *V.reshape(-1, dim).T, *W.reshape(k * n, -1).T, *F.reshape(-1, dim).T]
    csv_path = Path(csv_path)
    np.savetxt(csv_path, np.column_stack(cols), delimiter=",", header=",".join(header), comments="",
               fmt=["%d", "%.10g", "%d"] + ["%.10g"] * (len(header) - 3))
    return csv_path
