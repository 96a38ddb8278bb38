"""Work in colours on the GPU: items (cells, smoother patches) in colours, no two items of a colour
writing what another reads, and the launches of a kernel over them
(:class:`~fbmflow.gpu.colours.DeviceColours`): every colour in one cooperative launch, the whole
grid synchronised between colours, or one launch per colour.

numba-cuda prepares a launch's arguments on the host, asynchronously to the GPU's work but taking
the host tens of microseconds and more for a kernel of many array arguments (the Vanka sweep's
has 23): a V-cycle in 3D sweeps 27 colours four times on every level. One launch per sweep leaves
one launch where there were 27. A cooperative launch needs all its blocks resident at once (at
most ``max_cooperative_grid_blocks``, asked once per kernel and item set: its threads then take
several items of a colour each) and the CUDA device runtime linked (numba-cuda links it for a
kernel that synchronises its grid); where the device cannot launch it, the kernels launch once per
colour, with a warning.
"""
from __future__ import annotations

import logging

import numpy as np

from .device import launch_views

log = logging.getLogger(__name__)

#: every colour in one cooperative launch (the default); False: one launch per colour (the
#: launches' cost, measured apart: ``gpu_solver``'s row ``gpu-colours``)
ONE_LAUNCH = True

#: the sweep kernels that could not be launched cooperatively in this process (not asked again)
_REFUSED: set = set()


class DeviceColours:
    """``groups``, a list of (k,) integer host arrays (the colours' items), on the device as
    ``order``, the items one colour after the other, and ``starts (colours + 1,)``: colour ``c``
    is ``order[starts[c]:starts[c + 1]]`` (both int64; ``host_starts`` the host's copy). ``put``:
    a host array and its dtype -> a device copy (:meth:`Backend.put
    <fbmflow.gpu.device.Backend.put>`). ``nbytes``: the device memory they take [bytes]."""

    def __init__(self, groups: list, put):
        sizes = [int(np.size(g)) for g in groups]
        self.host_starts = np.cumsum([0] + sizes, dtype=np.int64)
        self.order = put(np.concatenate(groups) if groups else np.zeros(0), np.int64)
        self.starts = put(self.host_starts, np.int64)
        self._order, self._starts = launch_views(self.order, self.starts)  # as the launches pass them
        #: the most items of a colour
        self.largest = max(sizes, default=0)
        self.nbytes = int(self.order.nbytes + self.starts.nbytes)
        self._most: dict = {}  # sweep kernel's name -> the most blocks of a cooperative launch

    def __len__(self) -> int:
        """The number of colours."""
        return self.host_starts.size - 1

    def launch(self, each: str, sweep: str, threads: int, *args, per_block: int | None = None) -> None:
        """Run a kernel of ``fbmflow.gpu._kernels`` over every colour in turn: ``sweep(order,
        starts, *args)`` in one cooperative launch of ``threads`` per block (where
        :data:`ONE_LAUNCH`), else ``each(order, first, last, *args)`` once per colour, ``first``
        and ``last`` its bounds in ``order``; a block takes ``per_block`` items at once (default
        ``threads``: one per thread). The kernels are looked up at each call (so that
        :func:`~fbmflow.gpu.launches.count_launches` counts them); ``args`` pass as
        :func:`~fbmflow.gpu.device.launch_view` makes them (a caller that launches often with the
        same arrays passes their views, made once)."""
        from . import _kernels

        if not self.largest:
            return
        args = launch_views(*args)
        per_block = per_block or threads
        blocks = -(-self.largest // per_block)
        most = self._cooperative_blocks(sweep, threads, args) if ONE_LAUNCH and sweep not in _REFUSED else 0
        if most:
            getattr(_kernels, sweep)[min(blocks, most), threads](self._order, self._starts, *args)
            return
        kernel = getattr(_kernels, each)
        for first, last in zip(self.host_starts[:-1].tolist(), self.host_starts[1:].tolist()):
            if last > first:
                kernel[-(-(last - first) // per_block), threads](self._order, first, last, *args)

    def _cooperative_blocks(self, sweep: str, threads: int, args: tuple) -> int:
        """The most blocks of ``threads`` the kernel ``sweep`` can launch cooperatively with these
        arguments on this device (asked once per kernel: compiled for the arguments' types); 1
        under Numba's CUDA simulator, which synchronises a grid of one block only; 0 where the
        device or numba-cuda cannot launch it (the CUDA device runtime missing, say): logged, and
        the kernel not asked again in this process."""
        most = self._most.get(sweep)
        if most is None:
            from .._jit import cuda_simulated
            from . import _kernels

            most, why = 1, ""
            if not cuda_simulated():
                kernel = getattr(_kernels, sweep)
                try:
                    types = tuple(kernel.typeof_pyval(a) for a in (self._order, self._starts, *args))
                    most = int(kernel.compile(types).max_cooperative_grid_blocks(threads))
                    why = f"no block of {threads} threads fits" if most < 1 else ""
                except Exception as err:  # numba-cuda's errors have no common base
                    most, why = 0, f"{type(err).__name__}: {err}"
            if why:
                most = 0
                _REFUSED.add(sweep)
                log.warning("GPU: %s launches once per colour, not once per sweep: the device cannot "
                            "launch it cooperatively (%s)", sweep, why)
            self._most[sweep] = most
        return most
