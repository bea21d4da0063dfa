"""Owned -> ghost copies between neighbouring ranks (EG07 tutorial, Part 1
§5.5: interface values travel only to the ranks that hold them as ghosts).

The exchange plan is built once from the layout: each rank tells every owner
which of its vertices it holds as ghosts (one all-to-all of counts and one of
global indices); afterwards an update is one non-blocking send and receive
per neighbour, of all the arrays' rows packed side by side, so x and v travel
in one message.
"""
from __future__ import annotations

import numpy as np
from mpi4py import MPI


class GhostExchange:
    def __init__(self, layout, comm):
        self.mpi = comm.mpi_comm
        self.n_owned = layout.n_owned
        size = comm.size
        owners = np.asarray(layout.part)[layout.ghost_input].astype(np.int64)
        ghost_globals = layout.input_to_global[layout.ghost_input].astype(np.int64)
        # ghosts are sorted by global index and every rank's globals are contiguous,
        # so the ghosts of each owner form one contiguous run
        order = np.argsort(owners, kind="stable")
        if np.any(order != np.arange(order.size)):
            raise RuntimeError("ghosts are not grouped by owner: the layout's numbering changed")
        recv_counts = np.bincount(owners, minlength=size).astype(np.int64)
        send_counts = np.empty(size, dtype=np.int64)
        self.mpi.Alltoall(recv_counts, send_counts)
        recv_displs = np.concatenate([[0], np.cumsum(recv_counts)[:-1]])
        send_displs = np.concatenate([[0], np.cumsum(send_counts)[:-1]])
        wanted = np.empty(int(send_counts.sum()), dtype=np.int64)
        self.mpi.Alltoallv([ghost_globals, recv_counts, recv_displs, MPI.INT64_T],
                           [wanted, send_counts, send_displs, MPI.INT64_T])
        # the owned rows each neighbour wants, in the order it keeps its ghosts
        self.send_rows = (wanted - layout.global_start).astype(np.int64)
        if self.send_rows.size and (self.send_rows.min() < 0 or self.send_rows.max() >= self.n_owned):
            raise RuntimeError("a rank asked for a ghost this rank does not own")
        self.sends = [(r, int(send_displs[r]), int(send_counts[r])) for r in range(size)
                      if send_counts[r] and r != comm.rank]
        self.recvs = [(r, int(recv_displs[r]), int(recv_counts[r])) for r in range(size)
                      if recv_counts[r] and r != comm.rank]
        self.n_ghost = int(recv_counts.sum())

    def update(self, *arrays: np.ndarray) -> None:
        """Fill the ghost rows of each (n_local, k) float array from their owners, in place."""
        if not self.sends and not self.recvs:
            return
        widths = [a.shape[1] for a in arrays]
        n = self.n_owned
        out = np.ascontiguousarray(np.hstack([a[:n] for a in arrays])[self.send_rows],
                                   dtype=np.float64)
        inbox = np.empty((self.n_ghost, sum(widths)))
        requests = [self.mpi.Irecv(inbox[start:start + count], source=r, tag=7)
                    for r, start, count in self.recvs]
        requests += [self.mpi.Isend(out[start:start + count], dest=r, tag=7)
                     for r, start, count in self.sends]
        MPI.Request.Waitall(requests)
        col = 0
        for a, w in zip(arrays, widths):
            a[n:] = inbox[:, col:col + w]
            col += w
