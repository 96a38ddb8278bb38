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
    """Appends rows to ``path`` (created with ``meta`` attributes unless ``resume_step`` is given,
    in which case rows after that step are dropped; CheckpointError when the file is missing or
    damaged then)."""

    def __init__(self, path, meta: dict, resume_step: int | None = None):
        import h5py

        self.path = Path(path)
        if resume_step is None:
            with h5py.File(self.path, "w") as f:
                for key, value in meta.items():
                    f.attrs[key] = value if isinstance(value, (int, float, str)) else json.dumps(value)
        else:
            try:
                with h5py.File(self.path, "r+") as f:
                    if "step" in f:
                        keep = int(np.searchsorted(f["step"][()], resume_step, side="right"))
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
