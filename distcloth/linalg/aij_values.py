"""Block values written straight into an assembled AIJ matrix's storage.

PETSc's blocked CSR call on AIJ inserts one scalar at a time (a search along
the row for each): 141 ms a call at 100k vertices on 2 ranks, for what is a
copy of 40 MB a rank.  Its COO interface does the copy in 11 ms but keeps a map of
two 8-byte integers per scalar (0.6 GiB a rank at 1M vertices).  The
pattern is frozen after the first fill, so where each block's nine values sit
in the diagonal and off-diagonal CSR arrays of the rank's rows follows from
the pattern alone: each block's first slot and its row's width in that part,
two integers a block.  The values go there through PETSc's
``MatSeqAIJGetArray`` (public API), then the usual assembly, which also
marks cached diagonals stale and raises the matrix's state (so a
preconditioner sees the change).
"""
from __future__ import annotations

import ctypes

import numpy as np
from numba import njit

from .petsc import check_call


@njit(cache=True)
def _scatter_blocks(data, part, base, width, out_diag, out_off):
    """Block k's (a, b) value goes to slot base[k] + a * width[k] + b of the
    diagonal (part 0) or off-diagonal (part 1) values array."""
    for k in range(data.shape[0]):
        out = out_diag if part[k] == 0 else out_off
        s, w = base[k], width[k]
        for a in range(3):
            for b in range(3):
                out[s + a * w + b] = data[k, a, b]


def block_slots(block_rows: np.ndarray, block_cols: np.ndarray, n_owned: int,
                local_to_global: np.ndarray):
    """Where the blocks of a pattern (block ``k`` at owned row ``block_rows[k]``
    and local column ``block_cols[k]``) sit in PETSc's MPIAIJ storage of
    those rows with block size 3: the part (0 diagonal: owned columns; 1
    off-diagonal: ghosts), the slot of the block's (0, 0) value, and the
    scalar width of its row in that part.  Within a row PETSc stores each
    part's columns in increasing global order (the off-diagonal part by its
    sorted column map)."""
    nnzb = block_rows.shape[0]
    part = (block_cols >= n_owned).astype(np.int8)
    gcol = local_to_global[block_cols]
    order = np.lexsort((gcol, part, block_rows))
    counts = np.zeros((n_owned, 2), dtype=np.int64)
    np.add.at(counts, (block_rows, part), 1)
    # each block's ordinal within its row's part
    group = block_rows[order] * 2 + part[order]
    starts = np.flatnonzero(np.r_[True, group[1:] != group[:-1]])
    run = np.repeat(starts, np.diff(np.r_[starts, nnzb]))
    ordinal = np.empty(nnzb, dtype=np.int64)
    ordinal[order] = np.arange(nnzb) - run
    before = np.cumsum(counts, axis=0) - counts          # blocks of each part in earlier rows
    base = 9 * before[block_rows, part] + 3 * ordinal
    width = 3 * counts[block_rows, part]
    nnz = 9 * counts.sum(axis=0)
    return part, base, width, nnz


class AIJBlockWriter:
    """Writes (nnzb, 3, 3) block arrays of one pattern into assembled AIJ
    matrix ``A`` (MPIAIJ, or SeqAIJ on one rank) whose nonzero structure is
    exactly that pattern's."""

    def __init__(self, lib, A, block_rows, block_cols, n_owned, local_to_global):
        self.lib, self.A = lib, A
        self.mpi = A.getType() != "seqaij"
        self.part, self.base, self.width, self.nnz = block_slots(
            block_rows, block_cols, n_owned, local_to_global)
        # the structure PETSc holds is the pattern's, part by part (local
        # figures, no communication; the caller agrees on it over the ranks)
        local = A.getInfo(1)["nz_used"]      # MAT_LOCAL
        diag = A.getDiagonalBlock().getInfo(1)["nz_used"] if self.mpi else local
        self.matches = (int(diag), int(local - diag)) == (int(self.nnz[0]), int(self.nnz[1]))

    def _parts(self):
        if not self.mpi:
            return ctypes.c_void_p(self.A.handle), None
        ad, ao, colmap = ctypes.c_void_p(), ctypes.c_void_p(), ctypes.c_void_p()
        check_call(self.lib.MatMPIAIJGetSeqAIJ(ctypes.c_void_p(self.A.handle), ctypes.byref(ad),
                                           ctypes.byref(ao), ctypes.byref(colmap)),
               "MatMPIAIJGetSeqAIJ")
        return ad, ao

    def write(self, data: np.ndarray) -> None:
        ad, ao = self._parts()
        pointers, arrays = [], []
        for mat, nnz in ((ad, self.nnz[0]), (ao, self.nnz[1])):
            if mat is None:
                arrays.append(np.empty(0))
                continue
            p = ctypes.POINTER(ctypes.c_double)()
            check_call(self.lib.MatSeqAIJGetArray(mat, ctypes.byref(p)), "MatSeqAIJGetArray")
            pointers.append((mat, p))
            arrays.append(np.ctypeslib.as_array(p, shape=(int(nnz),)) if nnz else np.empty(0))
        try:
            _scatter_blocks(data, self.part, self.base, self.width, arrays[0], arrays[1])
        finally:
            for mat, p in pointers:
                check_call(self.lib.MatSeqAIJRestoreArray(mat, ctypes.byref(p)), "MatSeqAIJRestoreArray")
        self.A.assemble()
