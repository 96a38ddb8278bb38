"""The saddle-point operator ``K x`` on the GPU.

``K = [[A, B], [B^T, C]]`` is held as its blocks, CSR matrices on the device (CuPy's sparse
products: the issue's measurement, a 3D Q2 matrix of 135 M non-zeros in 0.57 ms on an H200,
2.9 TB/s). A velocity block stored once per scalar (:class:`~fbmflow.fem.velocity_block.VelocityBlock`:
``diag(S, ..., S)`` with some rows replaced) stays so: ``S`` applied to the ``d`` components at
once (one sparse-times-dense product, ``S`` read once), the replaced rows written over them; ``d``
times fewer bytes than the assembled block, to store and to stream. A Newton block that applies
its Newton terms without a matrix (the flow problem's ``NewtonBlock``: an assembled block plus
the reaction term ``s R(u)`` and the drift's convection ``s N(u - u0)``) keeps that form on the
device: its assembled part as above, the two terms by the matrix-free kernels
(:mod:`fbmflow.gpu.operators`) from its coefficient arrays, which :meth:`DeviceOperator.refresh`
copies again when the block has moved to another Newton iterate. The continuity rows and the
gradient are read from the level's divergence, which every set-up of the level shares and the
device holds once (:meth:`~fbmflow.gpu.device.Backend.kept`): the continuity rows as that
matrix with the rows that differ written over its products (a
:class:`~fbmflow.fem.continuity_block.ContinuityBlock`), the gradient as its transpose with the
constrained rows zeroed (a system with ``gradient_BT``); a set-up copies only what differs.
"""
from __future__ import annotations

import numpy as np

from ..fem.continuity_block import ContinuityBlock
from ..fem.velocity_block import VelocityBlock
from ..solvers.sparse import DivergenceProducts
from ..solvers.system import SaddlePointSystem, as_csr
from .colours import DeviceColours
from .device import Backend, launch_view, nbytes
from .operators import apply_cell_operator, apply_reaction, reaction_coefficients, velocity_coefficients
from .space import device_space


def kept_continuity(backend: Backend, BT):
    """The device's copy of a level's divergence ``BT (n_p, n_u)`` (CSR), made once and kept
    (:meth:`Backend.kept <fbmflow.gpu.device.Backend.kept>`): for the operators' continuity rows,
    the smoothers' and the flow problem's residuals."""
    return backend.kept(BT, "csr", backend.csr)


def kept_gradient(backend: Backend, BT):
    """The device's copy of ``BT``'s transpose (the gradient ``B``, CSR), made once and kept."""
    return backend.kept(BT, "transposed", lambda M: backend.csr(M.T))


class DeviceDivergenceProducts(DivergenceProducts):
    """The gradient ``B p`` and the continuity rows ``B^T u`` of a level's divergence ``BT``
    on the device of ``backend``, host arrays in and out, as
    :class:`~fbmflow.solvers.sparse.DivergenceProducts` on the CPU: the flow problem's residuals'
    products, from the copies the operators read (:func:`kept_gradient`,
    :func:`kept_continuity`), made at the first product. The sums run in CuPy's order, equal to
    the CPU's to rounding."""

    def __init__(self, space, BT, backend: Backend):
        super().__init__(space, BT)
        self.backend = backend

    def _times(self, M, x: np.ndarray) -> np.ndarray:
        backend = self.backend
        with backend.memory_guard("applying the divergence"):
            return backend.get(M(backend, self.BT) @ backend.put(x, np.float64))

    def gradient(self, p: np.ndarray) -> np.ndarray:
        """``B p`` for host pressures ``p (n_p,)`` -> host (n_u,) float64."""
        return self._times(kept_gradient, p)

    def continuity(self, u: np.ndarray) -> np.ndarray:
        """``B^T u`` for host velocities ``u (n_u,)`` -> host (n_p,) float64."""
        return self._times(kept_continuity, u)


def _matrix_free(A) -> bool:
    """Whether the velocity block ``A`` applies Newton terms without a matrix (duck-typed: the
    flow problem's ``NewtonBlock`` lives in a layer above)."""
    return hasattr(A, "base") and hasattr(A, "reacting") and hasattr(A, "drifting")


class _Blocks:
    """The assembled blocks of ``system`` on the device, ``A`` its velocity block (or a Newton
    block's assembled part): ``A`` as ``S`` and its replaced rows where it is a
    :class:`~fbmflow.fem.velocity_block.VelocityBlock` (its values copied, the space's pattern
    kept), else as a CSR matrix; the gradient
    ``B`` (the transpose of ``gradient_BT``, kept, its rows ``zero`` zeroed in the product; else
    a CSR matrix), the continuity rows ``D`` (a continuity block's divergence, kept, its rows
    ``changed`` those of ``changed_rows``; else a CSR matrix), the pressure block ``C`` (None
    where there is none). ``nbytes``: the device memory of what is not kept [bytes]; ``kept``:
    the kept device matrices read."""

    def __init__(self, system: SaddlePointSystem, A, backend: Backend):
        csr, put, self.xp = backend.csr, backend.put, backend.xp
        self.n_u = system.n_u
        self.S = self.A = None
        #: the host values of the velocity matrix held (``S``'s or ``A``'s)
        self.values = getattr(A, "data", None)
        self.kept = []
        if isinstance(A, VelocityBlock):  # the values copied, the space's pattern kept
            space = A.space
            pattern = backend.kept(space, "scalar pattern",
                                   lambda s: (put(s.indices, np.int32), put(s.indptr, np.int32)))
            self.kept.append(pattern)
            self.S = backend.sparse.csr_matrix((put(A.data), *pattern), shape=(space.n_v, space.n_v))
            self.R = csr(A.rows)
            self.replaced = backend.put(A.dofs)
            self.d, self.n_v = space.dim, space.n_v
            own = [self.S.data, self.R, self.replaced]
        else:
            self.A = csr(A)
            own = [self.A]
        self.zero = None
        if system.gradient_BT is not None:
            self.B = kept_gradient(backend, system.gradient_BT)
            self.kept.append(self.B)
            zero = system.gradient_zero
            if zero is not None and zero.size:
                self.zero = put(zero)
                own.append(self.zero)
        else:
            self.B = csr(system.gradient)
            own.append(self.B)
        D = system.BT
        #: the host matrix whose device copy ``D`` is, kept (a continuity block's divergence) or None
        self.divergence = D.base if isinstance(D, ContinuityBlock) else None
        self.changed = self.changed_rows = None
        if self.divergence is not None:
            self.D = kept_continuity(backend, D.base)
            self.kept.append(self.D)
            if D.dofs.size:
                self.changed, self.changed_rows = put(D.dofs), csr(D.rows)
                own += [self.changed, self.changed_rows]
        else:
            self.D = csr(as_csr(D))
            own.append(self.D)
        C = system.pressure_block
        self.C = None if C is None else csr(C)
        self.nbytes = nbytes(*own, self.C)

    def apply(self, x):
        """``K x`` of the assembled blocks for a device vector ``x`` (n_u + n_p,)."""
        xp, n_u = self.xp, self.n_u
        u, p = x[:n_u], x[n_u:]
        if self.S is not None:  # S on the d components at once, then the replaced rows
            U = self.S @ xp.ascontiguousarray(u.reshape(self.d, self.n_v).T)
            yu = xp.ascontiguousarray(U.T).reshape(-1)
            if self.replaced.shape[0]:
                yu[self.replaced] = self.R @ u
        else:
            yu = self.A @ u
        gradient = self.B @ p
        if self.zero is not None:
            gradient[self.zero] = 0.0
        yu += gradient
        yp = self.D @ u
        if self.changed is not None:
            yp[self.changed] = self.changed_rows @ u
        if self.C is not None:
            yp += self.C @ p
        return xp.concatenate([yu, yp])


class DeviceOperator:
    """``K x`` of ``system`` on the device of ``backend`` (device vectors (n_u + n_p,)).
    ``shared``: a device operator whose blocks are this one's assembled part (a Newton
    system's preconditioner, whose blocks it shares): used, not copied again; ``nbytes``
    counts only what this one adds; ``kept``: what it reads of the copies the backend keeps
    (:meth:`Backend.kept <fbmflow.gpu.device.Backend.kept>`), shared by every set-up."""

    def __init__(self, system: SaddlePointSystem, backend: Backend, shared: "DeviceOperator | None" = None):
        self.system, self.backend = system, backend
        self.n_u = system.n_u
        A = system.A
        self.free = _matrix_free(A)
        self.shares = shared is not None
        self.blocks = shared.blocks if self.shares else _Blocks(system, A.base if self.free else A, backend)
        if self.free:
            #: the space's cells on the device, kept, shared with whatever else applies its
            #: operators there (the flow problem's residuals)
            self.space = device_space(A.space, backend)
            self.d, self.n_v = self.space.dim, self.space.n_v
            self.constrained = backend.put(A.constrained)
            #: the Newton block's :attr:`~fbmflow.flow.levels.NewtonBlock.moves` when its
            #: coefficients were computed here
            self.moves = None
            self.refresh()

    @property
    def kept(self) -> list:
        """The kept device objects this operator reads (its blocks', the space's cells)."""
        return self.blocks.kept + ([self.space] if self.free else [])

    @property
    def nbytes(self) -> int:
        """The device memory this operator adds [bytes]: its blocks (unless shared), and a Newton
        block's constrained rows and coefficients."""
        own = 0 if self.shares else self.blocks.nbytes
        if self.free:
            own += nbytes(self.constrained, self.react, self.drift, self.drift_colours)
        return own

    def velocity_rows(self, values):
        """The device's velocity matrix (``S``, or ``A`` where the block is assembled) where its
        host values are the array ``values`` itself (a smoother that reads its rows from the same
        matrix), else None."""
        blocks = self.blocks
        if values is None or values is not blocks.values:
            return None
        return blocks.S if blocks.S is not None else blocks.A

    def divergence_rows(self, values):
        """The device's copy of the level's divergence (kept) where its host values hold the
        array ``values`` (a smoother that reads the gradient and continuity rows from the same
        matrix), else None."""
        host = self.blocks.divergence
        if host is None or not np.shares_memory(values, host.data):
            return None
        return self.blocks.D

    def refresh(self) -> None:
        """Compute the Newton block's coefficients on the device (after it moved to another
        iterate: :attr:`NewtonBlock.moves <fbmflow.flow.levels.NewtonBlock.moves>`), from the
        velocities it holds (``reacting``, ``drifting``) by the kernels whose threads run the
        CPU's per-cell bodies (:func:`~fbmflow.gpu.operators.reaction_coefficients`,
        :func:`~fbmflow.gpu.operators.velocity_coefficients`): a copy of each velocity, not of
        the coefficients (about four times their bytes in 3D), and the CPU computes none of
        them; the coefficients are held as the launches that read them pass them
        (:func:`~fbmflow.gpu.device.launch_view`). Nothing for an assembled block."""
        if not self.free or self.moves == self.system.A.moves:
            return
        A, put, xp, space = self.system.A, self.backend.put, self.backend.xp, self.space
        threads = self.backend.threads
        self.react = self.drift = self.drift_colours = None  # the old go before the new are made
        n_cells, nq = space.detJw.shape
        d, n_v = self.d, self.n_v
        if A.reacting is not None:
            self.react = launch_view(xp.empty((n_cells, nq, d, d), dtype=np.float32))
            reaction_coefficients(put(A.reacting.reshape(d, n_v)), space.cell_dofs, space.phi, space.dphi,
                                  space.detJw, space.Jinv, self.react, threads=threads)
        if A.drifting is not None:
            self.drift = launch_view(xp.empty((n_cells, nq, d)))
            velocity_coefficients(put(A.drifting.reshape(d, n_v)), space.cell_dofs, space.phi, space.detJw,
                                  self.drift, threads=threads)
            self.drift_colours = DeviceColours([c[A.drift_cells[c]] for c in space.host_colours
                                                if A.drift_cells[c].any()], put)
        self.scale = float(A.scale)
        self.moves = A.moves

    def apply(self, x):
        """``K x`` for a device vector ``x`` (n_u + n_p,)."""
        y = self.blocks.apply(x)
        if self.free:
            space = self.space
            v = x[:self.n_u].reshape(self.d, self.n_v)
            extra = self.backend.xp.zeros((self.d, self.n_v))
            if self.react is not None:
                apply_reaction(space.colours, self.react, space.cell_dofs, space.phi, v, self.scale, extra,
                               threads=self.backend.threads)
            if self.drift is not None:
                apply_cell_operator(self.drift_colours, *space.geometry, 0.0, 0.0, self.scale, self.drift, v,
                                    extra, threads=self.backend.threads)
            extra = extra.reshape(-1)
            extra[self.constrained] = 0.0
            y[:self.n_u] += extra
        return y

