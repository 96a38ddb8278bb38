"""A :class:`~fbmflow.fem.space.FlowSpace`'s cell geometry on the device, one copy per space and
backend (:func:`~fbmflow.gpu.space.device_space`), for everything that applies its matrix-free
operators there: the flow problem's residuals and time-step right-hand sides
(:meth:`~fbmflow.gpu.space.DeviceSpace.apply_mass_laplace`, what
:func:`fbmflow.fem.assembly.apply_mass_laplace` computes on the CPU) and a Newton block's terms
(:class:`~fbmflow.gpu.operator.DeviceOperator`)."""
from __future__ import annotations

import numpy as np

from .colours import DeviceColours
from .device import Backend, launch_views
from .operators import apply_cell_operator, cell_colours


class DeviceSpace:
    """The arrays of ``space``'s cells on the device of ``backend``: ``detJw (n_cells, nq)``,
    ``Jinv (n_cells, nq, d, d)``, ``cell_dofs (n_cells, nl)``, ``phi (nq, nl)``, ``dphi (nq, nl, d)``
    (the CPU's; nothing but the kernels reads them, so on a GPU they are held as the launches pass
    them, :func:`~fbmflow.gpu.device.launch_view`), and the cells in ``colours`` that share no
    node (:class:`~fbmflow.gpu.colours.DeviceColours` of
    :func:`~fbmflow.gpu.operators.cell_colours`; the host's list in ``host_colours``). ``nbytes``:
    the device memory they take [bytes]."""

    def __init__(self, space, backend: Backend):
        put = backend.put
        self.backend = backend
        self.dim, self.n_v = space.dim, space.n_v
        self.detJw, self.Jinv, self.cell_dofs, self.phi, self.dphi = launch_views(*(
            put(a) for a in (space.detJw, space.Jinv, space.V.cell_dofs, space.phi, space.dphi)))
        self.host_colours = cell_colours(space.V.cell_dofs)
        self.colours = DeviceColours(self.host_colours, put)
        self.nbytes = self.colours.nbytes + sum(int(a.nbytes) for a in self.geometry)

    @property
    def geometry(self) -> tuple:
        """``(detJw, Jinv, cell_dofs, phi, dphi)``, in the order the kernels take them."""
        return self.detJw, self.Jinv, self.cell_dofs, self.phi, self.dphi

    def apply_mass_laplace(self, alpha: float, beta: float, u: np.ndarray, convection: float = 0.0
                           ) -> np.ndarray:
        """``(alpha M + beta L + convection N(u)) u`` for a host velocity ``u (d * n_v,)`` ->
        host ``(d * n_v,)`` float64, computed on the device: as
        :func:`fbmflow.fem.assembly.apply_mass_laplace` (the same arguments but the space), the cells'
        sums in colours instead of the CPU's groups (equal to the rounding of the order)."""
        backend = self.backend
        with backend.memory_guard("applying the flow's operator"):
            w = backend.put(np.reshape(u, (self.dim, self.n_v)), np.float64)
            out = backend.xp.zeros((self.dim, self.n_v))
            apply_cell_operator(self.colours, *self.geometry, alpha, beta, convection, None, w, out,
                                threads=backend.threads)
            return backend.get(out).reshape(-1)


def device_space(space, backend: Backend) -> DeviceSpace:
    """``space``'s :class:`DeviceSpace` on ``backend``, copied at the first call and kept as long
    as ``space`` lives (:meth:`Backend.kept <fbmflow.gpu.device.Backend.kept>`)."""
    return backend.kept(space, "cells", lambda host: DeviceSpace(host, backend))
