"""The block sparsity pattern of this rank's rows, built once per run.

Rows are the owned vertices, columns local vertices (owned and ghosts), one
3x3 block per coupled pair.  Force terms get, once, the positions in the
value array where their blocks go; each step only scatters values there
(EG07 tutorial, Part 1 §5.7: blocked 3x3 storage).  No PETSc here: the same
arrays feed PETSc (through global column numbers) and the local products the
constraint filter needs.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp


class BlockPattern:
    def __init__(self, n_owned: int, n_local: int, stencils):
        self.n_owned, self.n_local = n_owned, n_local
        keys = [np.arange(n_owned, dtype=np.int64) * (n_local + 1)]   # diagonal blocks
        for elements in stencils:
            elements = np.asarray(elements, dtype=np.int64)
            nb = elements.shape[1]
            rows = np.repeat(elements, nb, axis=1).ravel()
            cols = np.tile(elements, (1, nb)).ravel()
            mine = rows < n_owned
            keys.append(rows[mine] * n_local + cols[mine])
        self.keys = np.unique(np.concatenate(keys))
        self.block_rows = self.keys // n_local
        self.block_cols = self.keys % n_local
        self.indptr = np.concatenate([[0], np.cumsum(np.bincount(self.block_rows, minlength=n_owned))])
        self.diag_slots = np.searchsorted(self.keys, np.arange(n_owned, dtype=np.int64) * (n_local + 1))
        self.nnzb = self.keys.shape[0]

    def slots_for(self, elements) -> np.ndarray:
        """(ne, nb*nb) value positions of each element's blocks, row-major over
        (a, b) pairs; -1 where the row vertex is a ghost."""
        elements = np.asarray(elements, dtype=np.int64)
        nb = elements.shape[1]
        rows = np.repeat(elements, nb, axis=1)
        cols = np.tile(elements, (1, nb))
        slots = np.searchsorted(self.keys, rows * self.n_local + cols)
        slots[rows >= self.n_owned] = -1
        return slots.astype(np.int64)

    def new_values(self) -> np.ndarray:
        return np.zeros((self.nnzb, 3, 3))

    def local_matrix(self, data: np.ndarray) -> sp.bsr_matrix:
        """The owned rows as a scipy BSR matrix over local columns (shares ``data``)."""
        return sp.bsr_matrix((data, self.block_cols, self.indptr),
                             shape=(3 * self.n_owned, 3 * self.n_local))

    def counts(self, is_owned_col: np.ndarray):
        """Blocks per row in the diagonal (owned columns) and off-diagonal parts."""
        d = np.bincount(self.block_rows[is_owned_col[self.block_cols]], minlength=self.n_owned)
        total = np.diff(self.indptr)
        return d.astype(np.int32), (total - d).astype(np.int32)
