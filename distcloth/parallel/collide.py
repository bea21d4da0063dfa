"""Distributed collision detection over the replicated global BVH.

EG07 tutorial, Part 1 §5.8.2: every rank holds the
whole hierarchy (its own sub-mesh tree plus everybody else's, combined at
the top), so one all-gather of positions per collision phase is all the
communication detection needs before each copy is refitted; the top-level
tests (a rank's self-collision, sub-mesh pairs of different ranks whose
volumes overlap, a sub-mesh against each collider) are the tasks.  Each
starts on the rank CollisionGeometry.static_owner gives it; with
``stealing`` (the default) the ranks then balance the traversal by task
creation and receiver-initiated round-robin work stealing
(distcloth/parallel/steal.py, EG07 tutorial, Part 1 §5.8.2), otherwise every rank
runs exactly its own tasks.

Each rank runs its tasks, turns the triangle pairs into vertex-face and
edge-edge candidates (the narrow phase runs where the task ran) and the
candidates are all-gathered, sorted and de-duplicated, so every rank
holds the same canonical set: the response that follows is computed from
identical data on every rank and never depends on which rank found a pair
or in which order (so the same rank count gives bitwise identical
results, docs/collisions.md).
"""
from __future__ import annotations

import time

import numpy as np

from ..collision.geometry import CollisionGeometry
from ..collision.impulses import collisions
from ..collision.proximity import edge_edge_contacts, vertex_face_contacts
from ..collision.traverse import unique_rows
from ..collision.tritri import CROSSING_COPLANAR_TOL, tri_tri_batch
from .steal import run_tasks


class DistributedCollisions:
    """Collective collision queries of one cloth partition (every method is
    collective: all ranks call it in the same order with the same arguments
    apart from their own rows).

    Load balancing of the traversal (distcloth/parallel/steal.py):
    ``stealing`` (default True) turns on task creation (threshold
    tau = a * sigma + b) and work stealing, ``chunk`` tests run between two
    polls; ``steal_options``: further keywords of ``run_tasks`` (delay,
    delay_prob, seed, timeout: test modes).  ``last_phase_stats`` holds this
    rank's statistics of the latest traversal (run_tasks' stats dict);
    ``counters`` accumulates tests, tasks_created, tasks_stolen,
    steals_refused, busy_time and traverse_time (wall) over the phases."""

    def __init__(self, comm, layout, geometry: CollisionGeometry, self_collision: bool,
                 stealing: bool = True, a: float = 2.0, b: float = 8, chunk: int = 256,
                 steal_options: dict | None = None):
        self.comm = comm
        self.stealing = bool(stealing)
        self.a, self.b, self.chunk = float(a), b, int(chunk)
        self.steal_options = dict(steal_options or {})
        self.last_phase_stats: dict = {}
        self.mpi = comm.mpi_comm
        self.geometry = geometry
        self.self_collision = bool(self_collision)
        # the vertex each combined-space vertex is welded into (collision.impulses.clean_pairs)
        self.same = None
        # who owns which cloth vertex, in all-gather order
        counts = np.array(self.mpi.allgather(int(layout.n_owned)), dtype=np.int64)
        self._counts = counts
        self._displs = np.concatenate([[0], np.cumsum(counts)[:-1]])
        order = np.empty(int(counts.sum()), dtype=np.int64)
        self.mpi.Allgatherv(np.ascontiguousarray(layout.owned_input, dtype=np.int64),
                            [order, counts, self._displs, _mpi_type(self.comm, np.int64)])
        self._order = order          # input index of each all-gathered row
        self.counters = {"phases": 0, "refits": 0, "tasks": 0, "tests": 0, "tri_pairs": 0,
                         "candidates": 0, "detect_time": 0.0, "tasks_created": 0,
                         "tasks_stolen": 0, "steals_refused": 0, "busy_time": 0.0,
                         "traverse_time": 0.0}
        self.step_stats = self._zero_step_stats()

    @staticmethod
    def _zero_step_stats() -> dict:
        return {"busy": 0.0, "wall": 0.0, "idle": 0.0, "tests": 0, "tasks_created": 0,
                "tasks_stolen": 0, "steals_refused": 0, "msgs_sent": 0,
                "latency_max": 0.0, "phases": 0}

    def take_step_stats(self) -> dict:
        """This rank's traversal statistics summed over the phases since the
        last call (busy: CPU time inside traversal chunks; wall: the phases'
        wall time; latency_max: the slowest steal answer), then reset."""
        out, self.step_stats = self.step_stats, self._zero_step_stats()
        return out

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

    def _allgather_rows(self, rows: np.ndarray, k: int | None = None,
                        dtype=np.int64) -> np.ndarray:
        """Every rank's rows (k columns of ``dtype``), concatenated in rank order."""
        k = rows.shape[1] if k is None else k
        rows = np.ascontiguousarray(rows, dtype=dtype).reshape(-1, k)
        counts = np.array(self.mpi.allgather(rows.shape[0]), dtype=np.int64)
        displs = np.concatenate([[0], np.cumsum(counts)[:-1]])
        flat = np.empty(int(counts.sum()) * k, dtype=dtype)
        self.mpi.Allgatherv(rows.reshape(-1), [flat, counts * k, displs * k,
                                               _mpi_type(self.comm, dtype)])
        return flat.reshape(-1, k)

    # ----------------------------------------------------------- detection
    def my_triangle_pairs(self, x0, x1=None, pad: float = 0.0,
                          cloth_only: bool = False) -> np.ndarray:
        """Triangle pairs (global ids) whose boxes overlap, found on this
        rank: the union over the ranks is every overlapping pair, each on one
        rank (``cloth_only``: cloth triangle pairs only, the colliders neither
        refitted nor traversed).  Collective with ``stealing`` (the ranks
        exchange tasks); without it each rank runs its statically assigned
        top-level tasks alone."""
        g = self.geometry
        trees = g.trees(x0, x1, pad, cloth_only)
        tests = g.root_tests(trees, self.self_collision, cloth_only)
        owner = g.static_owner(tests) if tests.size else np.zeros(0, np.int64)
        rows, stats = run_tasks(self.comm, trees, tests, owner, stealing=self.stealing,
                                a=self.a, b=self.b, chunk=self.chunk, **self.steal_options)
        self.last_phase_stats = stats
        c = self.counters
        c["refits"] += 1
        c["tasks"] += int(stats["tasks_run"])
        c["tests"] += int(stats["tests"])
        c["tasks_created"] += int(stats["tasks_created"])
        c["tasks_stolen"] += int(stats["tasks_stolen"])
        c["steals_refused"] += int(stats["steals_refused"])
        c["busy_time"] += float(stats["busy"])
        c["traverse_time"] += float(stats["wall"])
        c["tri_pairs"] += int(rows.shape[0])
        st = self.step_stats
        st["phases"] += 1
        for k in ("busy", "wall", "idle"):
            st[k] += float(stats[k])
        for k in ("tests", "tasks_created", "tasks_stolen", "steals_refused", "msgs_sent"):
            st[k] += int(stats[k])
        st["latency_max"] = max(st["latency_max"], float(stats["steal_latency_max"]))
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

    def shared_hits(self, x0, x1, tri, edges, vf, ee, eta):
        """Collective drop-in for ``impulses.collisions``: every rank runs the
        CCD narrow phase on every P-th of the (replicated, canonical)
        candidate rows (strided, so a crowded stretch of rows is shared, not
        handed to one rank) and the hits are all-gathered with their row
        numbers and put back in row order: every rank gets the serial
        result, bitwise, for 1/P of the work (the narrow phase was two thirds
        of a pile-up step when every rank ran it all)."""
        p, r = self.comm.size, self.comm.rank
        if p == 1:
            return collisions(x0, x1, tri, edges, vf, ee, eta)
        vf_mine, ee_mine = np.arange(r, vf.shape[0], p), np.arange(r, ee.shape[0], p)
        ids, coef, nrm, vf_hit, ee_hit = collisions(x0, x1, tri, edges, vf[vf_mine], ee[ee_mine],
                                                    eta, with_rows=True)
        # the serial position (vf rows, then ee rows) and the ids: < 2^53, exact as float64
        key = np.concatenate([vf_mine[vf_hit], vf.shape[0] + ee_mine[ee_hit]])
        packed = np.hstack([key[:, None].astype(np.float64), ids.astype(np.float64), coef, nrm])
        got = self._allgather_rows(packed, 12, np.float64)
        got = got[np.argsort(got[:, 0], kind="stable")]
        return (got[:, 1:5].astype(np.int64), np.ascontiguousarray(got[:, 5:9]),
                np.ascontiguousarray(got[:, 9:12]))

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
        """Collective: cloth triangle pairs that cross (Guigue-Devillers on
        the pairs whose boxes overlap, pairs coplanar to 1e-9 of an edge by
        the 2D test; pairs sharing a vertex are not counted), summed over the
        tasks of all ranks."""
        tp = self.my_triangle_pairs(x, x, 0.0, cloth_only=True)
        g = self.geometry
        if tp.shape[0]:
            a, b = g.tri[tp[:, 0]], g.tri[tp[:, 1]]
            if self.same is not None:      # stitched vertices count as one
                a, b = self.same[a], self.same[b]
            shared = (a[:, :, None] == b[:, None, :]).any(axis=(1, 2))
            tp = tp[~shared & (tp[:, 0] < g.n_cloth_tri) & (tp[:, 1] < g.n_cloth_tri)]
        hits = 0
        if tp.shape[0]:
            P = x[g.tri[tp[:, 0]]]
            Q = x[g.tri[tp[:, 1]]]
            hits = int(np.count_nonzero(tri_tri_batch(P, Q, CROSSING_COPLANAR_TOL)))
        return int(self.comm.sum(np.array([float(hits)]))[0])


def _mpi_type(comm, dtype):
    MPI = comm.MPI
    return MPI.INT64_T if np.dtype(dtype) == np.int64 else MPI.DOUBLE


def build_collisions(comm, model, layout, mesh_colliders=(), self_collision: bool = True,
                     t0: float = 0.0, **detector_options) -> DistributedCollisions:
    """The collision geometry of a partitioned model (a cloth triangle goes
    to the owner of its first vertex) and its distributed detector.
    ``mesh_colliders``: MeshCollider objects (kinematic objects after the ranks);
    ``detector_options``: stealing, a, b, chunk, steal_options of
    DistributedCollisions."""
    tri = np.asarray(model.triangles, dtype=np.int64)
    owner = np.asarray(layout.part)[tri[:, 0]] if tri.size else np.zeros(0, np.int64)
    rest = [np.asarray(model.rest_positions, dtype=np.float64)]
    rest += [c.vertices(t0) for c in mesh_colliders]
    geometry = CollisionGeometry(tri, model.num_vertices, owner, comm.size,
                                 [(c.n_vertices, c.triangles) for c in mesh_colliders],
                                 rest=np.concatenate(rest))
    # pinned cloth vertices (pins, grips, skin-following regions) move as prescribed: a
    # pair of them and collider primitives has no free vertex, and no impulse can act on it
    geometry.kinematic[model.pinned] = True
    detector = DistributedCollisions(comm, layout, geometry, self_collision, **detector_options)
    if model.same_vertex is not None:
        detector.same = np.concatenate([model.same_vertex,
                                        np.arange(model.num_vertices, geometry.n_vertices)])
    return detector
