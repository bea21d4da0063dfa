"""The communicator wrapper: the collectives the driver, the writer and the
studies need, on the communicator it was given (MPI_COMM_WORLD by default),
so that nothing outside ``distcloth/parallel/`` imports MPI or calls a raw
collective and a run can live on a sub-communicator.

Errors are agreed collectively: every rank reports (ok, message) and all
ranks learn the first failure in rank order, so they stop together and no
rank waits forever in a collective the others have left.
"""
from __future__ import annotations

import os
import sys

import numpy as np
from mpi4py import MPI

from .partition import partition_vertices


class Comm:
    def __init__(self, mpi_comm=None):
        self.mpi_comm = MPI.COMM_WORLD if mpi_comm is None else mpi_comm
        self.MPI = MPI
        self.rank = self.mpi_comm.Get_rank()
        self.size = self.mpi_comm.Get_size()

    @property
    def under_mpiexec(self) -> bool:
        """Started by mpiexec (Debian's h5py then loads its MPI build)."""
        return "OMPI_COMM_WORLD_SIZE" in os.environ or "PMIX_RANK" in os.environ

    def broadcast(self, obj, root: int = 0):
        """Rank ``root``'s Python object on every rank."""
        return self.mpi_comm.bcast(obj, root=root)

    def synchronize(self) -> None:
        """Wait until every rank got here."""
        self.mpi_comm.Barrier()

    def agree(self, error: str | None) -> tuple[int, str] | None:
        """(rank, message) of the lowest failing rank, or None if all are fine."""
        errors = self.mpi_comm.allgather(error)
        for r, e in enumerate(errors):
            if e is not None:
                return r, e
        return None

    def sum(self, values: np.ndarray) -> np.ndarray:
        """Elementwise sum over the ranks."""
        out = np.empty_like(values)
        self.mpi_comm.Allreduce(values, out, op=MPI.SUM)
        return out

    def max(self, values: np.ndarray) -> np.ndarray:
        """Elementwise maximum over the ranks."""
        out = np.empty_like(values)
        self.mpi_comm.Allreduce(values, out, op=MPI.MAX)
        return out

    def gather_objects(self, obj) -> list:
        """Every rank's Python object, in rank order, on every rank."""
        return self.mpi_comm.allgather(obj)

    def allgather_rows(self, owned_input: np.ndarray, rows: np.ndarray, n: int) -> np.ndarray:
        """(n, k) global array in input order from every rank's owned rows
        (``owned_input``: their input indices) on every rank: for the one
        moment the whole state must be known everywhere (a garment's weld
        changes the topology and every rank builds the same new model)."""
        rows = np.ascontiguousarray(rows, dtype=np.float64).reshape(len(owned_input), -1)
        k = rows.shape[1]
        counts = np.array(self.mpi_comm.allgather(int(rows.shape[0])), dtype=np.int64)
        displs = np.concatenate([[0], np.cumsum(counts)[:-1]])
        index = np.empty(int(counts.sum()), dtype=np.int64)
        self.mpi_comm.Allgatherv(np.ascontiguousarray(owned_input, dtype=np.int64),
                                 [index, counts, displs, MPI.INT64_T])
        values = np.empty((int(counts.sum()), k))
        self.mpi_comm.Allgatherv(rows, [values, counts * k, displs * k, MPI.DOUBLE])
        out = np.full((n, k), np.nan)
        out[index] = values
        return out

    def abort_with(self, line: str, code: int):
        """Print ``line`` and abort the job: for an error found on some ranks only,
        which the others cannot agree on (they may be waiting in a collective)."""
        print(line, file=sys.stderr, flush=True)
        self.abort(code)

    def abort(self, code: int = 1):
        sys.stderr.flush()
        sys.stdout.flush()
        self.mpi_comm.Abort(code)


def partition_on_root(comm: Comm, xadj, adjncy, seed: int = 0) -> np.ndarray:
    """METIS on rank 0 (it is serial), the partition vector broadcast to all."""
    n = xadj.shape[0] - 1
    if comm.rank == 0:
        part = partition_vertices(xadj, adjncy, comm.size, seed=seed).astype(np.int32)
    else:
        part = np.empty(n, dtype=np.int32)
    comm.mpi_comm.Bcast(part, root=0)
    return part
