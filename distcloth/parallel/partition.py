"""Vertex partition of the cloth and the per-rank layout built from it
(EG07 tutorial, Part 1 §5.4-5.5).

``partition_vertices`` splits the matrix graph with METIS k-way (§5.4).
``build_layout`` turns the partition vector into one rank's
:class:`LocalLayout`: owned vertices internal first then interface, ghosts
after, a global numbering contiguous per rank (§5.5).  Everything is a
handful of O(n + nnz) numpy passes, so every rank can compute its layout from
the replicated graph and ``part`` without communication.
"""
from __future__ import annotations

import numpy as np

from distcloth.parallel.layout import LocalLayout
from distcloth.parallel.metis import part_graph_kway

# Largest load imbalance (max / mean - 1) accepted from METIS before retrying.
MAX_IMBALANCE = 0.05
_STRICT_UFACTOR = 1     # 0.1 %: the retry when METIS's default 3 % is overshot


def _imbalance(counts: np.ndarray) -> float:
    return float(counts.max() / counts.mean() - 1.0) if counts.size else 0.0


def partition_vertices(xadj, adjncy, nparts: int, seed: int = 0) -> np.ndarray:
    """Owning rank (int32) of every vertex of the graph (xadj, adjncy).

    METIS k-way with its default 3 % imbalance allowance; if the result is
    more than 5 % out of balance (beyond what whole vertices allow) it retries
    with a 0.1 % allowance, and on graphs too small for METIS to balance (it
    can leave parts empty there) it falls back to contiguous blocks of input
    order, which is what a tiny grid needs anyway.
    """
    n = len(xadj) - 1
    if nparts == 1:
        return np.zeros(n, dtype=np.int32)
    if nparts > n:
        raise ValueError(f"cannot split {n} vertices over {nparts} ranks")
    # the best any split into whole vertices can do
    tolerance = max(MAX_IMBALANCE, -(-n // nparts) / (n / nparts) - 1.0) + 1e-12
    for ufactor in (None, _STRICT_UFACTOR):
        part, _ = part_graph_kway(xadj, adjncy, nparts, seed=seed, ufactor=ufactor)
        if _imbalance(np.bincount(part, minlength=nparts)) <= tolerance:
            return part
    return (np.arange(n, dtype=np.int64) * nparts // n).astype(np.int32)


def _adjacency_rows(xadj: np.ndarray) -> np.ndarray:
    """Row (source vertex) of every adjncy entry."""
    n = xadj.shape[0] - 1
    return np.repeat(np.arange(n, dtype=np.int64), np.diff(xadj))


def build_layout(xadj, adjncy, spring_vertices, part, rank: int, size: int) -> LocalLayout:
    """Rank ``rank``'s view of the partition ``part`` of the matrix graph.

    (xadj, adjncy) is the symmetric vertex graph of the system matrix
    (``Model.matrix_graph()``), ``spring_vertices`` the (ns, 2) spring ends in
    input numbering, ``part`` the (n,) owning rank of every vertex.  The result
    depends only on these, so all ranks agree on ``input_to_global``.
    """
    xadj = np.asarray(xadj, dtype=np.int64)
    adjncy = np.asarray(adjncy, dtype=np.int64)
    spring_vertices = np.asarray(spring_vertices, dtype=np.int64).reshape(-1, 2)
    part = np.asarray(part, dtype=np.int32)
    n = xadj.shape[0] - 1
    if part.shape != (n,):
        raise ValueError(f"part has shape {part.shape}, expected ({n},)")
    if not 0 <= rank < size:
        raise ValueError(f"rank {rank} outside 0..{size - 1}")
    if n and (part.min() < 0 or part.max() >= size):
        raise ValueError(f"part values must lie in 0..{size - 1}")

    rows = _adjacency_rows(xadj)
    row_part = part[rows]
    col_part = part[adjncy]
    crossing = row_part != col_part
    # interface: adjacent to a vertex of another rank (§5.5)
    is_interface = np.bincount(rows[crossing], minlength=n) > 0
    edge_cut = int(np.count_nonzero(crossing & (rows < adjncy)))

    # Global order: by rank, internal before interface, then input index.  A
    # stable sort on (rank, interface) keeps input order within each group,
    # which preserves the mesh's locality.
    counts = np.bincount(part, minlength=size).astype(np.int64)
    ownership = np.zeros(size + 1, dtype=np.int64)
    np.cumsum(counts, out=ownership[1:])
    group = part.astype(np.int64) * 2 + is_interface
    global_order = np.argsort(group, kind="stable")      # input index of each global row
    input_to_global = np.empty(n, dtype=np.int64)
    input_to_global[global_order] = np.arange(n, dtype=np.int64)

    start, stop = ownership[rank], ownership[rank + 1]
    owned_input = global_order[start:stop]
    n_internal = int(np.count_nonzero(~is_interface[owned_input]))

    # ghosts: off-rank neighbours of owned vertices; walking global_order
    # through a mask yields them already sorted by global index
    is_ghost = np.zeros(n, dtype=bool)
    is_ghost[adjncy[(row_part == rank) & crossing]] = True
    ghost_input = global_order[is_ghost[global_order]]

    input_to_local = np.full(n, -1, dtype=np.int64)
    input_to_local[owned_input] = np.arange(owned_input.shape[0], dtype=np.int64)
    input_to_local[ghost_input] = owned_input.shape[0] + np.arange(ghost_input.shape[0], dtype=np.int64)

    local_spring_ids = np.flatnonzero((part[spring_vertices] == rank).any(axis=1)).astype(np.int64)
    local_springs = input_to_local[spring_vertices[local_spring_ids]]
    if local_springs.size and local_springs.min() < 0:
        raise ValueError("a spring joins vertices that are not neighbours in the matrix graph")

    return LocalLayout(
        rank=rank,
        size=size,
        part=part,
        ownership=ownership,
        input_to_global=input_to_global,
        owned_input=owned_input,
        n_internal=n_internal,
        ghost_input=ghost_input,
        local_spring_ids=local_spring_ids,
        local_springs=local_springs,
        edge_cut=edge_cut,
        imbalance=_imbalance(counts),
    )


def describe_partition(layout: LocalLayout) -> str:
    """One log line: the whole partition, then this rank's share."""
    owned = np.diff(layout.ownership)
    return (f"partition: {layout.size} ranks, owned {owned.min()}..{owned.max()} "
            f"(imbalance {100 * layout.imbalance:.1f} %), edge cut {layout.edge_cut}; "
            f"rank {layout.rank}: {layout.n_internal} internal, "
            f"{layout.n_owned - layout.n_internal} interface, {layout.n_ghost} ghost")
