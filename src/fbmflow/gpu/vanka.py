"""The factored Vanka smoother's sweeps on the GPU.

:class:`DeviceVanka` takes a :class:`~fbmflow.solvers.vanka.FactoredVankaSmoother` set up on the
CPU in colour order (``order="colours"``: its local factors, its copy of the operator and its
phases, every phase a colour whose patches touch nothing of each other) and sweeps with them on
the device: one kernel launch per colour, one thread per patch, each thread running the body the
CPU's sweeps run (``fbmflow.solvers._kernels.vanka_patch``). The result is the CPU smoother's in
the same order, to the rounding of the sums' order (the kernel is compiled with fastmath, the
CPU's triangular solves too).
"""
from __future__ import annotations

from ..solvers.vanka import FactoredVankaSmoother
from .device import Backend


class DeviceVanka:
    """``smoother``'s sweeps on the device of ``backend``.

    Parameters
    ----------
    smoother : FactoredVankaSmoother with ``order == "colours"``
    backend : Backend, where the arrays go
    """

    def __init__(self, smoother: FactoredVankaSmoother, backend: Backend):
        if smoother.order != "colours":
            raise ValueError("the GPU sweeps a factored Vanka smoother set up in colours (order='colours'), "
                             f"not {smoother.order!r}")
        put = backend.put
        nl, d, width, n_v, n_u = smoother.shape
        s = smoother
        self.patches = tuple(put(a) for a in (s.ptr, s.dofs, s.lu_ptr, s.store, s.piv, s.blocks, s.d_read))
        self.patches += (nl, d, n_v, n_u)
        self.op = tuple(put(a) for a in s.op)
        self.omega = smoother.omega
        self.threads = backend.threads
        self.interface_sweeps = smoother.interface_sweeps

        def colours(phases):
            return [put(order[gptr[0]:gptr[-1]]) for gptr, order in phases]

        self.sweeps = [colours(phases) for phases, _ in smoother.sweeps]
        self.interface = colours(smoother.interface_phases) + colours(smoother.interface_merged_phases)
        self.merged = colours(smoother.merged_phases)
        largest = max((c.shape[0] for c in self.sweeps[0] + self.interface + self.merged), default=1)
        xp = backend.xp
        self.work = (xp.empty((largest, width)), xp.empty((largest, width), dtype=s.store.dtype),
                     xp.empty((largest, width)), xp.empty((largest, width)))
        self.nbytes = int(sum(a.nbytes for a in self.patches[:7] + self.op + self.work)
                          + sum(c.nbytes for c in self.interface + self.merged)
                          + sum(c.nbytes for sweep in self.sweeps for c in sweep))

    def sweep_colours(self, colours: list, b, x) -> None:
        """The patches of every colour in turn, a colour's at once: ``x`` updated in place."""
        from ._kernels import vanka_patches

        for patches in colours:
            blocks = max(1, -(-patches.shape[0] // self.threads))
            vanka_patches[blocks, self.threads](patches, b, x, float(self.omega), *self.patches, *self.op,
                                                *self.work)

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

