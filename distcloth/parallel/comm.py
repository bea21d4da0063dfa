"""The few collective operations the driver needs, so nothing else imports MPI.

Errors are agreed collectively: every rank reports (ok, message) and all
ranks learn the first failure in rank order, so they stop together and no
rank waits forever in a collective the others have left.
"""
from __future__ import annotations

import os
import sys

import numpy as np


class Comm:
    def __init__(self):
        from mpi4py import MPI
        self.MPI = MPI
        self.comm = MPI.COMM_WORLD
        self.rank = self.comm.Get_rank()
        self.size = self.comm.Get_size()

    @property
    def under_mpiexec(self) -> bool:
        return "OMPI_COMM_WORLD_SIZE" in os.environ or "PMIX_RANK" in os.environ

    @property
    def mpi_comm(self):
        return self.comm

    def bcast(self, obj, root=0):
        return self.comm.bcast(obj, root=root)

    def barrier(self):
        self.comm.Barrier()

    def agree(self, error: str | None) -> tuple[int, str] | None:
        """Collective: (rank, message) of the lowest failing rank, or None if all are fine."""
        errors = self.comm.allgather(error)
        for r, e in enumerate(errors):
            if e is not None:
                return r, e
        return None

    def sum(self, values: np.ndarray) -> np.ndarray:
        out = np.empty_like(values)
        self.comm.Allreduce(values, out, op=self.MPI.SUM)
        return out

    def max(self, values: np.ndarray) -> np.ndarray:
        out = np.empty_like(values)
        self.comm.Allreduce(values, out, op=self.MPI.MAX)
        return out

    def abort(self, code: int = 1):
        sys.stderr.flush()
        sys.stdout.flush()
        self.comm.Abort(code)


def partition_on_root(comm: Comm, xadj, adjncy, seed: int = 0) -> np.ndarray:
    """METIS on rank 0 (it is serial), the partition vector broadcast to all."""
    from .partition import partition_vertices
    part = None
    if comm.rank == 0:
        part = partition_vertices(xadj, adjncy, comm.size, seed=seed).astype(np.int32)
    n = xadj.shape[0] - 1
    if comm.rank != 0:
        part = np.empty(n, dtype=np.int32)
    comm.comm.Bcast(part, root=0)
    return part
