"""Several processes on one mesh (issue "Past one machine"): the processes of a run and the
split of a structured mesh into slabs, one per process, with the sums over the nodes that two
slabs share. MPI (mpi4py) is imported only when a launcher started several processes."""
from .comm import (
                   LAUNCHER_VARIABLES,
                   SerialComm,
                   launched_processes,
                   max_over,
                   sum_over,
                   sum_replicated,
                   world,
)
from .slabs import SlabPartition

__all__ = ["LAUNCHER_VARIABLES", "SerialComm", "launched_processes", "max_over", "sum_over", "sum_replicated",
           "world", "SlabPartition"]
