"""The processes of a run: MPI's world communicator where a launcher (``mpiexec -n P``) started
several, a stand-in with the same calls for one process otherwise, so that the serial path
imports no MPI library."""
from __future__ import annotations

import os
import sys

import numpy as np

from .._jit import max_threads, set_threads
from ..cores import usable_cpus

#: the environment variables of the world size and rank that MPI launchers set in every process
#: (Open MPI's mpiexec; MPICH's and Intel MPI's Hydra, and Slurm's srun with PMI-2)
LAUNCHER_VARIABLES = (("OMPI_COMM_WORLD_SIZE", "OMPI_COMM_WORLD_RANK"), ("PMI_SIZE", "PMI_RANK"))


def launched_processes() -> tuple[int, int]:
    """``(rank, size)`` of this process among those an MPI launcher started, ``(0, 1)`` when none
    did (read from the launcher's environment variables, :data:`LAUNCHER_VARIABLES`; no MPI
    library is imported)."""
    for size, rank in LAUNCHER_VARIABLES:
        if os.environ.get(size, "").isdigit():
            n = int(os.environ[size])
            r = os.environ.get(rank, "0")
            return (int(r) if r.isdigit() else 0), max(n, 1)
    return 0, 1


class LaunchError(RuntimeError):
    """Several processes were started but cannot run together (mpi4py missing, or built against
    another MPI than the launcher's); the message names the remedy."""


class SerialComm:
    """One process: mpi4py's communicator calls that the slabs use, each the identity."""

    rank = 0
    size = 1

    def allreduce(self, value, op=None):
        return value

    def bcast(self, value, root: int = 0):
        return value

    def allgather(self, value):
        return [value]

    def gather(self, value, root: int = 0):
        return [value]


def world():
    """MPI's ``COMM_WORLD`` where a launcher started several processes, else a
    :class:`~fbmflow.parallel.comm.SerialComm`; :class:`LaunchError` naming the remedy where mpi4py is
    missing then, or where MPI sees another number of processes than the launcher started (each
    would think itself alone and repeat the whole run)."""
    size = launched_processes()[1]
    if size == 1:
        return SerialComm()
    try:
        from mpi4py import MPI
    except ImportError as err:
        raise LaunchError("several processes need mpi4py: pip install -e \".[mpi]\" (mpi4py and the "
                           "MPICH wheel, whose mpiexec then starts the run)") from err
    if MPI.COMM_WORLD.Get_size() != size:
        raise LaunchError(f"the launcher started {size} processes but MPI sees {MPI.COMM_WORLD.Get_size()}: "
                           "mpi4py was built against another MPI than this mpiexec's; use the mpiexec of "
                           "the MPI that mpi4py uses (mpi4py.get_config())")
    _share_cores(MPI.COMM_WORLD, MPI.COMM_TYPE_SHARED)
    _abort_on_uncaught(MPI.COMM_WORLD)
    return MPI.COMM_WORLD


_shared = False  # whether this process's Numba threads were set for its machine's processes
_aborting = False  # whether an uncaught exception ends every process (_abort_on_uncaught)


def _abort_on_uncaught(comm) -> None:
    """From the first call on, an exception that no code catches (a bug, in a script or in
    fbmflow) prints its traceback and then aborts every process (``comm.Abort(1)``): a process
    that ended alone would leave the others waiting for it in their next exchange, for ever
    (measured: a force rule that raised on one of two processes left the other in its next sum).
    The errors fbmflow expects stop every process together without this (each decides from
    reduced figures, docs/troubleshooting.md)."""
    global _aborting
    if _aborting:
        return
    _aborting = True
    previous = sys.excepthook

    def hook(kind, value, traceback):
        previous(kind, value, traceback)
        sys.stderr.flush()
        comm.Abort(1)

    sys.excepthook = hook


def _share_cores(comm, shared_type) -> None:
    """Numba's threads in this process: the CPUs it may run on (its affinity) shared evenly among
    the processes on its machine that may run on the same CPUs (MPI's shared-memory split and one
    ``allgather`` of the affinities, on the first call), at least one, unless
    ``NUMBA_NUM_THREADS`` chose them. A launcher that binds each process to its own CPUs (Slurm's
    ``--cpus-per-task``, Open MPI's binding) leaves each its own; MPICH's ``mpiexec`` binds none,
    and each process's default would be every core: on two cores ``mpiexec -n 2`` ran 4 threads,
    and a ten Cate level-0 step took 2.9 times as long as with one thread each
    (docs/validation/several-processes.md)."""
    global _shared
    if _shared:
        return
    _shared = True
    cpus = tuple(usable_cpus())
    sharing = sum(other == cpus for other in comm.Split_type(shared_type).allgather(cpus))
    if "NUMBA_NUM_THREADS" not in os.environ:
        set_threads(max(1, min(max_threads(), len(cpus) // sharing)))


def sum_over(v, comm):
    """The elementwise sum of every process's array ``v`` (float64), the same on all (one
    ``Allreduce``); ``v`` itself for one process."""
    if comm.size == 1:
        return v
    from mpi4py import MPI

    out = np.empty_like(v)
    comm.Allreduce(np.ascontiguousarray(v), out, op=MPI.SUM)
    return out


def sum_replicated(v, comm):
    """The sum of every process's array ``v`` taken in rank order on every process, so that all
    hold the same bits whatever the MPI library's reduction order (the particles' forces, which
    every process integrates alike); ``v`` itself for one process. For small arrays: one
    ``allgather``."""
    if comm.size == 1:
        return v
    parts = comm.allgather(np.ascontiguousarray(v))
    out = parts[0].copy()
    for part in parts[1:]:
        out += part
    return out


def max_over(value: float, comm) -> float:
    """The largest of every process's ``value`` (one ``allgather``)."""
    return value if comm.size == 1 else float(max(comm.allgather(float(value))))


def on_first(action, comm):
    """``action()`` on the first process of ``comm`` only (a file written once), its exception
    raised on every process (one ``bcast``), so that all stop together with the same error;
    returns the action's result on the first process, None on the others."""
    if comm.size == 1:
        return action()
    result = error = None
    if comm.rank == 0:
        try:
            result = action()
        except Exception as err:  # noqa: BLE001 (every process raises it below)
            error = err
    error = comm.bcast(error)
    if error is not None:
        raise error
    return result
