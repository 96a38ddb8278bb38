"""Several processes on one mesh (issue "Past one machine"): the processes of a run and the
split of a structured mesh into slabs, one per process, with one halo cell layer towards each
neighbour. MPI (mpi4py) is imported only when a launcher started several processes."""
from .blocks import BlockPartition
from .comm import (
    LAUNCHER_VARIABLES,
    SerialComm,
    launched_processes,
    max_over,
    on_first,
    sum_over,
    sum_replicated,
    world,
)

__all__ = ["LAUNCHER_VARIABLES", "SerialComm", "launched_processes", "max_over", "on_first", "sum_over",
    "sum_replicated", "world", "BlockPartition"]
