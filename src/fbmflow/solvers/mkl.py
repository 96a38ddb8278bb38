"""A small ctypes binding to Intel MKL's ``pardiso`` (the optional ``pardiso`` extra: the ``mkl``
wheel), which the direct solver's PARDISO backend calls (:mod:`fbmflow.solvers.direct`).

MKL's runtime ``libmkl_rt`` is looked for where ``FBMFLOW_MKL_RT`` names it, then in the Python
environment's library folders (where the ``mkl`` wheel puts it), then on the system's library
path. Nothing is loaded until a solver is made. A :class:`Pardiso` holds one MKL handle and its
settings; :meth:`Pardiso.call` runs one phase of ``pardiso`` (analysis 11, factorisation 22,
both 12, solve 33, release -1) on a CSR matrix given 1-based, and the handle's memory is released
when the object goes (or by :meth:`Pardiso.release`).
"""
from __future__ import annotations

import ctypes
import ctypes.util
import functools
import glob
import os
import sys
import weakref
from pathlib import Path

import numpy as np

#: MKL's matrix type for real unsymmetric matrices
REAL_UNSYMMETRIC = 11


@functools.cache
def library_path() -> str | None:
    """Where MKL's runtime library is (None: not installed)."""
    named = os.environ.get("FBMFLOW_MKL_RT")
    if named:
        return named if Path(named).is_file() else None
    patterns = ("libmkl_rt.so*", "libmkl_rt*.dylib", "mkl_rt*.dll")
    for folder in {sys.prefix, sys.base_prefix, os.path.dirname(sys.executable)}:
        for sub in ("lib", "Library/bin", "bin"):
            for pattern in patterns:
                found = sorted(glob.glob(os.path.join(folder, sub, pattern)))
                if found:
                    return found[0]
    return ctypes.util.find_library("mkl_rt")


@functools.cache
def _library() -> ctypes.CDLL:
    path = library_path()
    if path is None:
        raise OSError("MKL's runtime (libmkl_rt) was not found; pip install 'fbmflow[pardiso]' or set "
                      "FBMFLOW_MKL_RT to its path")
    lib = ctypes.CDLL(path)
    int_p = ctypes.POINTER(ctypes.c_int32)
    lib.pardiso.restype = None
    lib.pardiso.argtypes = [ctypes.POINTER(ctypes.c_int64), int_p, int_p, int_p, int_p, int_p,
                            ctypes.POINTER(ctypes.c_double), int_p, int_p, int_p, int_p, int_p, int_p,
                            ctypes.POINTER(ctypes.c_double), ctypes.POINTER(ctypes.c_double), int_p]
    return lib


def available() -> bool:
    """True when MKL's runtime can be found (the ``pardiso`` extra is installed)."""
    return library_path() is not None


def _int(value: int):
    return ctypes.byref(ctypes.c_int32(value))


class Pardiso:
    """One MKL ``pardiso`` handle with its settings: ``iparm`` (1-based keys, as in MKL's
    documentation; every entry not given is 0, MKL's default where ``iparm[1] = 1``)."""

    def __init__(self, iparm: dict[int, int] | None = None, mtype: int = REAL_UNSYMMETRIC):
        _library()  # loaded now: a missing runtime fails here, not in the first factorisation
        self.mtype = mtype
        self.pt = np.zeros(64, dtype=np.int64)  # MKL's internal handle
        self.iparm = np.zeros(64, dtype=np.int32)
        for key, value in (iparm or {}).items():
            self.iparm[key - 1] = value
        weakref.finalize(self, _release, self.pt, self.iparm, mtype)

    def call(self, phase: int, data: np.ndarray, ia: np.ndarray, ja: np.ndarray,
             B: np.ndarray) -> np.ndarray:
        """Run ``phase`` on the CSR matrix ``(data, ia, ja)`` (1-based int32 ``ia``, ``ja``) with
        the right-hand sides ``B (n, k)``; returns the solutions ``X (n, k)`` (zeros for the
        phases that solve nothing). LinAlgError naming MKL's error code when it fails."""
        n = ia.size - 1
        B = np.asfortranarray(B, dtype=float)
        X = np.zeros_like(B)
        error = ctypes.c_int32(0)
        int_p, float_p = ctypes.POINTER(ctypes.c_int32), ctypes.POINTER(ctypes.c_double)
        perm = np.zeros(n, dtype=np.int32)
        _library().pardiso(self.pt.ctypes.data_as(ctypes.POINTER(ctypes.c_int64)), _int(1), _int(1),
                           _int(self.mtype), _int(phase), _int(n), data.ctypes.data_as(float_p),
                           ia.ctypes.data_as(int_p), ja.ctypes.data_as(int_p), perm.ctypes.data_as(int_p),
                           _int(B.shape[1]), self.iparm.ctypes.data_as(int_p), _int(0),
                           B.ctypes.data_as(float_p), X.ctypes.data_as(float_p), ctypes.byref(error))
        if error.value != 0:
            raise np.linalg.LinAlgError(f"PARDISO phase {phase} failed with MKL error {error.value}")
        return X

    def release(self) -> None:
        """Free MKL's memory of this handle (phase -1)."""
        _release(self.pt, self.iparm, self.mtype)


def _release(pt: np.ndarray, iparm: np.ndarray, mtype: int) -> None:
    """Phase -1 on the handle ``pt`` (nothing when it holds nothing)."""
    if not pt.any():
        return
    error = ctypes.c_int32(0)
    int_p, float_p = ctypes.POINTER(ctypes.c_int32), ctypes.POINTER(ctypes.c_double)
    dummy_i, dummy_f = np.zeros(1, dtype=np.int32), np.zeros(1)
    _library().pardiso(pt.ctypes.data_as(ctypes.POINTER(ctypes.c_int64)), _int(1), _int(1), _int(mtype),
                       _int(-1), _int(0), dummy_f.ctypes.data_as(float_p), dummy_i.ctypes.data_as(int_p),
                       dummy_i.ctypes.data_as(int_p), dummy_i.ctypes.data_as(int_p), _int(1),
                       iparm.ctypes.data_as(int_p), _int(0), dummy_f.ctypes.data_as(float_p),
                       dummy_f.ctypes.data_as(float_p), ctypes.byref(error))
    pt[:] = 0
