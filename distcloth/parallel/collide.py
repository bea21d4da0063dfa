"""Distributed collision detection over the replicated global BVH.

Seed 000 (000_f60be85aa292bde2.txt) Part 1 §5.8.2: every rank holds the
whole hierarchy (its own sub-mesh tree plus everybody else's, combined at
the top), so one all-gather of positions per collision phase is all the
communication detection needs before each copy is refitted; the top-level
tests (a rank's self-collision, sub-mesh pairs of different ranks whose
volumes overlap, a sub-mesh against each collider) are the tasks, assigned
here statically (distcloth.collision.geometry.CollisionGeometry.static_owner;
work stealing replaces that assignment later).

Each rank runs its tasks, turns the triangle pairs into vertex-face and
edge-edge candidates (the narrow phase runs where the task ran) and the
candidates are all-gathered, sorted and de-duplicated, so every rank
holds the same canonical set: the response that follows is computed from
identical data on every rank and never depends on which rank found a pair
or in which order (determinism, issue 4 §5).
"""
from __future__ import annotations

import time

import numpy as np

from ..collision.geometry import CollisionGeometry
from ..collision.proximity import edge_edge_contacts, vertex_face_contacts
from ..collision.traverse import run_tests, unique_rows
from ..collision.tritri import tri_tri_batch


class DistributedCollisions:
    """Collective collision queries of one cloth partition (every method is
    collective: all ranks call it in the same order with the same arguments
    apart from their own rows)."""

    def __init__(self, comm, layout, geometry: CollisionGeometry, self_collision: bool):
        self.comm = comm
        self.mpi = comm.mpi_comm
        self.geometry = geometry
        self.self_collision = bool(self_collision)
        # who owns which cloth vertex, in all-gather order
        counts = np.array(self.mpi.allgather(int(layout.n_owned)), dtype=np.int64)
        self._counts = counts
        self._displs = np.concatenate([[0], np.cumsum(counts)[:-1]])
        order = np.empty(int(counts.sum()), dtype=np.int64)
        self.mpi.Allgatherv(np.ascontiguousarray(layout.owned_input, dtype=np.int64),
                            [order, counts, self._displs, _mpi_type(self.comm, np.int64)])
        self._order = order          # input index of each all-gathered row
        self.counters = {"phases": 0, "refits": 0, "tasks": 0, "tests": 0, "tri_pairs": 0,
                         "candidates": 0, "detect_time": 0.0}

    # ---------------------------------------------------------------- data
    def gather(self, owned_rows: np.ndarray) -> np.ndarray:
        """(N, k) rows of every cloth vertex in input numbering from each
        rank's (n_owned, k) owned rows: one Allgatherv."""
        rows = np.ascontiguousarray(owned_rows, dtype=np.float64)
        k = rows.shape[1]
        flat = np.empty(self._order.size * k)
        self.mpi.Allgatherv(rows.reshape(-1), [flat, self._counts * k, self._displs * k,
                                               _mpi_type(self.comm, np.float64)])
        out = np.empty((self._order.size, k))
        out[self._order] = flat.reshape(-1, k)
        return out

    def _allgather_rows(self, rows: np.ndarray) -> np.ndarray:
        rows = np.ascontiguousarray(rows, dtype=np.int64).reshape(-1, rows.shape[1])
        k = rows.shape[1]
        counts = np.array(self.mpi.allgather(rows.shape[0]), dtype=np.int64)
        displs = np.concatenate([[0], np.cumsum(counts)[:-1]])
        flat = np.empty(int(counts.sum()) * k, dtype=np.int64)
        self.mpi.Allgatherv(rows.reshape(-1), [flat, counts * k, displs * k,
                                               _mpi_type(self.comm, np.int64)])
        return flat.reshape(-1, k)

    # ----------------------------------------------------------- detection
    def my_triangle_pairs(self, x0, x1=None, pad: float = 0.0) -> np.ndarray:
        """Triangle pairs (global ids) whose boxes overlap, from this rank's
        statically assigned top-level tasks (not collective: positions are
        replicated)."""
        g = self.geometry
        trees = g.trees(x0, x1, pad)
        tests = g.root_tests(trees, self.self_collision)
        mine = tests[g.static_owner(tests) == self.comm.rank] if tests.size else tests
        rows = run_tests(trees, mine) if mine.shape[0] else np.zeros((0, 4), np.int64)
        self.counters["refits"] += 1
        self.counters["tasks"] += int(mine.shape[0])
        self.counters["tri_pairs"] += int(rows.shape[0])
        return g.triangle_pairs(rows)

    def candidates(self, x0, x1, pad: float):
        """Collective: the vertex-face and edge-edge pairs whose boxes swept
        over x0 -> x1 and grown by pad overlap, on every rank, sorted unique."""
        t0 = time.perf_counter()
        self.counters["phases"] += 1
        tp = self.my_triangle_pairs(x0, x1, pad)
        vf, ee = self.geometry.primitive_pairs(tp, x0, x1, pad)
        vf = unique_rows(self._allgather_rows(vf))
        ee = unique_rows(self._allgather_rows(ee))
        self.counters["candidates"] += int(vf.shape[0] + ee.shape[0])
        self.counters["detect_time"] += time.perf_counter() - t0
        return vf, ee

    def proximity_pairs(self, x, thickness: float):
        """Collective: every vertex-face and edge-edge pair closer than
        ``thickness`` at positions x (the combined vertex space), as the sorted
        (vertex, face) and (edge a, edge b) rows every rank agrees on."""
        vf, ee = self.candidates(x, x, thickness)
        vfc = vertex_face_contacts(x, self.geometry.tri, vf, thickness)
        eec = edge_edge_contacts(x, self.geometry.edges, ee, thickness)
        return (np.stack([vfc.vertex, vfc.face], axis=1).reshape(-1, 2),
                np.stack([eec.edge_a, eec.edge_b], axis=1).reshape(-1, 2))

    def count_intersections(self, x) -> int:
        """Collective: cloth triangle pairs that intersect (exact
        Guigue-Devillers test on the pairs whose boxes overlap; pairs sharing
        a vertex are not counted), summed over the tasks of all ranks."""
        tp = self.my_triangle_pairs(x, x, 0.0)
        g = self.geometry
        if tp.shape[0]:
            a, b = g.tri[tp[:, 0]], g.tri[tp[:, 1]]
            shared = (a[:, :, None] == b[:, None, :]).any(axis=(1, 2))
            tp = tp[~shared & (tp[:, 0] < g.n_cloth_tri) & (tp[:, 1] < g.n_cloth_tri)]
        hits = 0
        if tp.shape[0]:
            P = x[g.tri[tp[:, 0]]]
            Q = x[g.tri[tp[:, 1]]]
            hits = int(np.count_nonzero(tri_tri_batch(P, Q)))
        return int(self.comm.sum(np.array([float(hits)]))[0])


def _mpi_type(comm, dtype):
    MPI = comm.MPI
    return MPI.INT64_T if np.dtype(dtype) == np.int64 else MPI.DOUBLE


def build_collisions(comm, model, layout, mesh_colliders=(), self_collision: bool = True,
                     t0: float = 0.0) -> DistributedCollisions:
    """The collision geometry of a partitioned model (a cloth triangle goes
    to the owner of its first vertex) and its distributed detector.
    ``mesh_colliders``: MeshCollider objects (kinematic objects after the ranks)."""
    tri = np.asarray(model.triangles, dtype=np.int64)
    owner = np.asarray(layout.part)[tri[:, 0]] if tri.size else np.zeros(0, np.int64)
    rest = [np.asarray(model.rest_positions, dtype=np.float64)]
    rest += [c.vertices(t0) for c in mesh_colliders]
    geometry = CollisionGeometry(tri, model.num_vertices, owner, comm.size,
                                 [(c.n_vertices, c.triangles) for c in mesh_colliders],
                                 rest=np.concatenate(rest))
    return DistributedCollisions(comm, layout, geometry, self_collision)
