"""Counting the GPU kernels' launches (for studies:
:func:`~fbmflow.gpu.launches.count_launches`). numba-cuda prepares a launch's arguments on the
host, asynchronously to the GPU's work: where the host's seconds in the launches approach a
cycle's, the cycles are bound by the launches, not by the GPU."""
from __future__ import annotations

import time

from . import _kernels

#: the kernels of ``fbmflow.gpu._kernels``
KERNELS = ("apply_cells", "apply_cells_sweep", "apply_reaction_cells", "apply_reaction_sweep",
           "velocity_rows", "reaction_rows", "vanka_patches", "vanka_sweep", "vanka_factors")


class _Counted:
    """A kernel whose launches add to ``counts``."""

    def __init__(self, kernel, counts: dict):
        self.kernel, self.counts = kernel, counts

    def __getitem__(self, config):
        launch = self.kernel[config]

        def call(*args):
            t0 = time.perf_counter()
            launch(*args)
            self.counts["launches"] += 1
            self.counts["launch_s"] += time.perf_counter() - t0
        return call

    def __getattr__(self, name):  # the kernel's other attributes (``compile``, ``py_func``)
        return getattr(self.kernel, name)


def count_launches() -> dict:
    """From now on in this process, count every GPU kernel's launches: returns the counts, kept up
    to date, ``{"launches": int, "launch_s": float}`` (the host's seconds in them)."""
    counts = {"launches": 0, "launch_s": 0.0}
    for name in KERNELS:
        setattr(_kernels, name, _Counted(getattr(_kernels, name), counts))
    return counts
