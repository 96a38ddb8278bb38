"""The factored Vanka smoother's sweeps on the GPU.

:class:`DeviceVanka` takes a :class:`~fbmflow.solvers.vanka.FactoredVankaSmoother` set up on the
CPU in colour order (``order="colours"``: its patches, its copy of the operator and its phases,
every phase a colour whose patches touch nothing of each other), computes the patches' local
factors on the device where the CPU left them out (``factor=False``: one thread per patch, each
running the body the CPU's set-up runs, ``fbmflow.solvers._kernels.factor_patch``) and sweeps
with them on the device: one kernel launch per sweep, its colours in turn with the whole grid
synchronised between them (a cooperative launch, :class:`~fbmflow.gpu.colours.DeviceColours`; or
one launch per colour), ``lanes`` threads (a warp) per patch running the body the CPU's sweeps run
(``fbmflow.solvers._kernels.vanka_patch``'s parts: the threads take the patch's residual rows in
turn, the first solves, they add the update in turn). The result is the CPU
smoother's in the same order, to the rounding of the sums' order (the sweeps' kernel is compiled
with fastmath, the CPU's triangular solves too; the factors are the CPU's to the last bits under
the simulator, and may differ in the last bits on a GPU, whose compiler fuses multiply-adds).
"""
from __future__ import annotations

import time

import numpy as np

from ..solvers.vanka import FactoredVankaSmoother
from .colours import DeviceColours
from .device import Backend, launch_view, launch_views

#: the most device memory the factors' kernel takes for its threads' work arrays [bytes]: a
#: launch factors as many patches as their work fits (a 3D cell patch, 85 unknowns: 86 kB each)
FACTOR_SCRATCH = 2**30


class DeviceVanka:
    """``smoother``'s sweeps on the device of ``backend``.

    Parameters
    ----------
    smoother : FactoredVankaSmoother with ``order == "colours"``, its factors computed
        (copied to the device) or not (``factor=False``: computed on the device)
    backend : Backend, where the arrays go
    rows : device CSR matrix or None
        The matrix whose rows the smoother reads as its scalar rows (its operator's velocity
        block or scalar block, the same host arrays) where the device holds it already (the
        level's :class:`~fbmflow.gpu.operator.DeviceOperator`): read there, not copied again.
    divergence : device CSR matrix or None
        The same for the divergence whose values the smoother reads as its gradient rows, and
        whose column indices as its continuity rows' (the level's, which the device keeps,
        :meth:`DeviceOperator.divergence_rows <fbmflow.gpu.operator.DeviceOperator.divergence_rows>`).
    """

    def __init__(self, smoother: FactoredVankaSmoother, backend: Backend, rows=None, divergence=None):
        if smoother.order != "colours":
            raise ValueError("the GPU sweeps a factored Vanka smoother set up in colours (order='colours'), "
                             f"not {smoother.order!r}")
        put = backend.put
        nl, d, width, n_v, n_u = smoother.shape
        s = smoother
        xp = backend.xp
        self.threads = backend.threads
        #: threads per patch in the sweeps (dividing ``threads``): they share its residual's rows
        self.lanes = backend.lanes
        if s.store is None:
            store = xp.empty(int(s.lu_ptr[-1]), dtype=s.dtype)
            piv = xp.zeros(int(s.ptr[-1]), dtype=np.int32)
        else:
            store, piv = put(s.store), put(s.piv)
        self.patches = (put(s.ptr), put(s.dofs), put(s.lu_ptr), store, piv, put(s.blocks), put(s.d_read),
                        nl, d, n_v, n_u)
        # the operator's arrays (the kernels' "op": held, s_ptr, s_idx, s_val, nc_ptr, nc_cell,
        # nc_rank, gt, d_pos, d_ptr, d_idx, d_val, b_idx, the other rows), read where the device
        # holds them already
        held = {}
        if rows is not None:
            held.update({1: rows.indptr, 2: rows.indices, 3: rows.data})
        if divergence is not None:
            held[7] = divergence.data.reshape(s.op[7].shape)
            if s.op[12].size:
                held[12] = divergence.indices
        own = tuple(put(a) for k, a in enumerate(s.op) if k not in held)
        mine = iter(own)
        self.op = tuple(held[k] if k in held else next(mine) for k in range(len(s.op)))
        #: seconds the device took for the local factors (0 where the CPU computed them)
        self.factor_time_s = 0.0
        if s.store is None:
            t0 = time.perf_counter()
            self._factor(s.ptr, s.dofs, s.schur_tol, backend)
            backend.synchronize()
            self.factor_time_s = time.perf_counter() - t0
        self.omega = smoother.omega
        self.interface_sweeps = smoother.interface_sweeps

        def colours(phases):  # a sweep's colours, one after the other
            return DeviceColours([order[gptr[0]:gptr[-1]] for gptr, order in phases], put)

        self.sweeps = [colours(phases) for phases, _ in smoother.sweeps]
        self.interface = colours(smoother.interface_phases + smoother.interface_merged_phases)
        self.merged = colours(smoother.merged_phases)
        largest = max(max(c.largest for c in self.sweeps + [self.interface, self.merged]), 1)
        self.work = (xp.empty((largest, width)), xp.empty((largest, width), dtype=s.dtype),
                     xp.empty((largest, width)), xp.empty((largest, width)))
        self.nbytes = int(sum(a.nbytes for a in self.patches[:7] + own + self.work)
                          + sum(c.nbytes for c in self.sweeps + [self.interface, self.merged]))
        #: the sweeps' arguments but the vectors, as their launches pass them (made once:
        #: :func:`~fbmflow.gpu.device.launch_view`)
        self._args = launch_views(*self.patches, *self.op, *self.work)

    def _factor(self, ptr: np.ndarray, dofs: np.ndarray, schur_tol: float, backend: Backend) -> None:
        """The local factors of the patches ``dofs[ptr[k]:ptr[k + 1]]`` (each ascending: the
        kernel finds an unknown's place by bisection) into ``store`` and ``piv`` on the device:
        the patches of one size at a time, as many per launch as :data:`FACTOR_SCRATCH` holds
        their work arrays."""
        from ._kernels import vanka_factors

        starts = np.zeros(dofs.size, dtype=bool)
        starts[ptr[:-1][np.diff(ptr) > 0]] = True  # a patch's first unknown follows no other of it
        if not (starts[1:] | (np.diff(dofs) > 0)).all():
            raise ValueError("the device factors patches whose unknowns ascend; these do not")
        sizes = np.diff(ptr)
        xp = backend.xp
        nl, d = self.patches[7], self.patches[8]
        arrays = launch_views(*self.patches, *self.op)
        npl = d + 1
        for width in np.unique(sizes):
            patches = np.flatnonzero(sizes == width)
            per_patch = 8 * (width * width + (d + 1) * nl * nl + d * nl * npl + 2 * npl * npl + 2 * width) \
                + 4 * width
            chunk = int(min(patches.size, max(1, FACTOR_SCRATCH // per_patch)))
            work = (xp.empty((chunk, width, width)), xp.empty((chunk, nl, nl)), xp.empty((chunk, d, nl, nl)),
                    xp.empty((chunk, d * nl, npl)), xp.empty((chunk, npl, npl)), xp.empty((chunk, npl, npl)),
                    xp.empty((chunk, width), dtype=np.int32), xp.empty((chunk, width)),
                    xp.empty((chunk, width)))
            for first in range(0, patches.size, chunk):
                part = backend.put(patches[first:first + chunk])
                launch = vanka_factors[max(1, -(-part.shape[0] // self.threads)), self.threads]
                launch(launch_view(part), float(schur_tol), *arrays, *launch_views(*work))

    def sweep_colours(self, colours, b, x) -> None:
        """The patches of every colour of ``colours`` (:class:`~fbmflow.gpu.colours.DeviceColours`)
        in turn, a colour's at once: ``x`` updated in place. One launch for all colours, the grid
        synchronised between them, or one per colour
        (:meth:`DeviceColours.launch <fbmflow.gpu.colours.DeviceColours.launch>`); the launch's
        threads take a colour's patches, each with its rows of the work arrays."""
        lanes = self.lanes
        colours.launch("vanka_patches", "vanka_sweep", self.threads, lanes, b, x, float(self.omega),
                       *self._args, per_block=self.threads // lanes)

    def smooth(self, b, x, sweeps: int, first: int = 0) -> None:
        """``sweeps`` sweeps on ``K x = b`` (device arrays), as
        :meth:`FactoredVankaSmoother.smooth <fbmflow.solvers.vanka.FactoredVankaSmoother.smooth>`
        does them: each sweep's colours, the interface's ``interface_sweeps`` times, then the
        agglomerated patches' colours; ``first``: the number of the first sweep (its direction
        in symmetric sweeps)."""
        for k in range(first, first + sweeps):
            self.sweep_colours(self.sweeps[k % len(self.sweeps)], b, x)
            for _ in range(self.interface_sweeps):
                self.sweep_colours(self.interface, b, x)
            self.sweep_colours(self.merged, b, x)

