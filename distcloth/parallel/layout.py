"""Per-rank view of the partitioned cloth (EG07 tutorial, Part 1 §5.4-5.5).

Owned vertices are numbered internal first, then interface (adjacent through
the matrix graph to a vertex of another rank); ghosts (non-owned vertices that
share a spring with an owned one) come after, sorted by global index.  The
global (PETSc) numbering is contiguous per rank: rank r owns global indices
``ownership[r]:ownership[r+1]`` in its local order.

Computed identically on every rank from the global model and the partition
vector, so it needs no communication beyond the broadcast of ``part``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class LocalLayout:
    rank: int
    size: int
    part: np.ndarray             # (n,) int32: owning rank of every input vertex
    ownership: np.ndarray        # (size+1,) int64 global offsets of each rank's block of rows
    input_to_global: np.ndarray  # (n,) int64: global index of every input vertex
    owned_input: np.ndarray      # (n_owned,) int64: input index of each owned vertex, local order
    n_internal: int              # owned_input[:n_internal] are internal, the rest interface
    ghost_input: np.ndarray      # (n_ghost,) int64: input index of each ghost, by global index
    local_spring_ids: np.ndarray  # (ns_local,) int64: model springs with >= 1 owned end
    local_springs: np.ndarray    # (ns_local, 2) int64: their ends in local numbering
    edge_cut: int                # matrix-graph edges between ranks (counted once)
    imbalance: float             # max owned / mean owned - 1

    @property
    def n_owned(self) -> int:
        return self.owned_input.shape[0]

    @property
    def n_interface(self) -> int:
        return self.n_owned - self.n_internal

    @property
    def n_ghost(self) -> int:
        return self.ghost_input.shape[0]

    @property
    def n_local(self) -> int:
        return self.n_owned + self.n_ghost

    @property
    def local_input(self) -> np.ndarray:
        """Input index of every local vertex (owned then ghosts)."""
        return np.concatenate([self.owned_input, self.ghost_input])

    @property
    def local_to_global(self) -> np.ndarray:
        return self.input_to_global[self.local_input]

    @property
    def global_start(self) -> int:
        return int(self.ownership[self.rank])

    @property
    def global_stop(self) -> int:
        return int(self.ownership[self.rank + 1])

    def input_to_local(self) -> np.ndarray:
        """(n,) int64: local index of every input vertex, -1 if not local."""
        mapping = np.full(self.part.shape[0], -1, dtype=np.int64)
        mapping[self.local_input] = np.arange(self.n_local, dtype=np.int64)
        return mapping
