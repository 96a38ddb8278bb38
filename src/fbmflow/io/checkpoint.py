"""Checkpoints: one HDF5 file with a run's state, written atomically and checked on reading.

Layout: a dataset per state entry (arrays and scalars), and attributes ``meta`` (JSON: scene,
level, resolved parameters, ``fbmflow`` version, step) and ``extra`` (JSON: what the scene has
recorded so far), and ``sha256``, a digest of all of it. The file is written to ``path + ".tmp"``
and renamed over ``path``, so a run killed while writing leaves the previous checkpoint intact.
Reading refuses, with :class:`CheckpointError`, a file that is missing, unreadable, fails its
digest, or belongs to another scene, level or parameter set.
"""
from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import numpy as np


class CheckpointError(ValueError):
    """A checkpoint that cannot be used (the message says why)."""


def _digest(arrays: dict, meta: str, extra: str) -> str:
    h = hashlib.sha256()
    for key in sorted(arrays):
        a = np.ascontiguousarray(arrays[key])
        h.update(key.encode())
        h.update(str(a.dtype).encode() + str(a.shape).encode())
        h.update(a.tobytes())
    h.update(meta.encode())
    h.update(extra.encode())
    return h.hexdigest()


def save_checkpoint(path, state: dict, meta: dict, extra: dict) -> None:
    """Write ``state`` (name -> array or number), ``meta`` and ``extra`` (JSON-serialisable) to
    the HDF5 file ``path`` atomically."""
    import h5py

    path = Path(path)
    arrays = {k: np.asarray(v) for k, v in state.items()}
    meta_s, extra_s = json.dumps(meta, sort_keys=True), json.dumps(extra)
    tmp = path.with_name(path.name + ".tmp")
    try:
        with h5py.File(tmp, "w") as f:
            for key, a in arrays.items():
                f.create_dataset(key, data=a)
            f.attrs["meta"] = meta_s
            f.attrs["extra"] = extra_s
            f.attrs["sha256"] = _digest(arrays, meta_s, extra_s)
        os.replace(tmp, path)
    finally:  # a write that failed (a full disk) leaves no temporary file behind
        tmp.unlink(missing_ok=True)


def load_checkpoint(path, expect: dict | None = None) -> tuple[dict, dict, dict]:
    """``(state, meta, extra)`` from ``path``; CheckpointError when it is missing, corrupt, or its
    ``meta`` differs from ``expect`` in any key ``expect`` gives (e.g. scene, level, params)."""
    import h5py

    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"no checkpoint at {path}; the run stopped before its first checkpoint "
                              "(start it again with 'fbmflow run')")
    try:
        with h5py.File(path, "r") as f:
            state = {k: f[k][()] for k in f.keys()}
            meta_s, extra_s, digest = (str(f.attrs[k]) for k in ("meta", "extra", "sha256"))
    except (OSError, KeyError) as err:
        raise CheckpointError(f"checkpoint {path} is unreadable ({err}); it is corrupt or not a "
                              "checkpoint: delete it and start the run again") from None
    if _digest({k: np.asarray(v) for k, v in state.items()}, meta_s, extra_s) != digest:
        raise CheckpointError(f"checkpoint {path} fails its checksum (corrupt); delete it and start "
                              "the run again")
    meta = json.loads(meta_s)
    for key, want in (expect or {}).items():
        if meta.get(key) != want:
            raise CheckpointError(f"checkpoint {path} is for another {key} ({meta.get(key)!r}, this run "
                                  f"has {want!r}); resume it with its own settings or start afresh")
    return state, meta, json.loads(extra_s)
