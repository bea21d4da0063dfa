"""The collision geometry every rank replicates: one vertex index space for
the cloth and the kinematic triangle meshes of the colliders.

EG07 tutorial, Part 1 §5.8.2: each processor builds a BVH over its own
sub-mesh; the sub-trees are combined into a global hierarchy
replicated on every rank, and the tests between (sub-)hierarchies are the
top-level tasks.  Here the *objects* of that hierarchy are

* objects 0..P-1: the cloth triangles owned by rank r (a triangle belongs to
  the owner of its first vertex), one sub-BVH each;
* objects P..P+C-1: the triangles of each mesh collider (kinematic: their
  vertices have infinite mass, their motion is prescribed).

Vertex ids: the cloth's input numbering 0..N-1 first, then collider c's
vertices at ``vertex_off[c]``; triangles and edges likewise, so the
proximity, CCD and impulse kernels see one mesh.  The tree topologies are
built once from the rest shape (deterministic, so every rank builds the same
trees) and refitted at every collision phase; the top-level tree over the
objects' root boxes is rebuilt each phase (a handful of boxes).

Candidate primitive pairs come from triangle pairs: the vertex-face and
edge-edge pairs of two triangles whose swept, padded boxes overlap, kept if
the primitives' own boxes overlap too (Bridson et al. 2002 §4: every
vertex-face and edge-edge pair of nearby triangles).  Arrays in, arrays out;
no MPI (the distributed driver is distcloth/parallel/collide.py).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .bvh import BVH, build_bvh, combine_roots, refit
from .proximity import mesh_edges
from .traverse import unique_rows


class CollisionGeometry:
    def __init__(self, cloth_tri, n_cloth, tri_owner, n_ranks, colliders=(), rest=None,
                 leaf_size: int = 4):
        """``cloth_tri`` (M, 3) in input numbering; ``tri_owner`` (M,) rank of
        each triangle; ``colliders``: (n_vertices, triangles (m, 3)) per mesh
        collider; ``rest``: positions (N + sum n_c, 3) the topologies are built from."""
        cloth_tri = np.asarray(cloth_tri, dtype=np.int64).reshape(-1, 3)
        self.n_cloth = int(n_cloth)
        self.n_ranks = int(n_ranks)
        tris, offs = [cloth_tri], [self.n_cloth]
        self.object_tris = [np.flatnonzero(np.asarray(tri_owner) == r) for r in range(n_ranks)]
        start = cloth_tri.shape[0]
        for nv, tri in colliders:
            tri = np.asarray(tri, dtype=np.int64).reshape(-1, 3)
            tris.append(tri + offs[-1])
            self.object_tris.append(np.arange(start, start + tri.shape[0]))
            start += tri.shape[0]
            offs.append(offs[-1] + int(nv))
        self.vertex_off = np.array(offs, dtype=np.int64)     # collider c starts at vertex_off[c]
        self.n_vertices = int(offs[-1])
        self.n_cloth_tri = cloth_tri.shape[0]
        self.tri = np.ascontiguousarray(np.concatenate(tris))
        self.edges = mesh_edges(self.tri)
        self.tri_edges = _triangle_edges(self.tri, self.edges)
        # one incident triangle per vertex and per edge (the lowest id): a primitive's box
        # lies inside each of its triangles' boxes, so every primitive pair whose boxes
        # overlap comes with the pair of its owner triangles, and emitting it from that
        # pair alone yields each candidate once instead of once per incident triangle pair
        self.vertex_owner = _first_triangle(self.tri.reshape(-1), self.n_vertices)
        self.edge_owner = _first_triangle(self.tri_edges.reshape(-1), self.edges.shape[0])
        self.kinematic = np.zeros(self.n_vertices, dtype=bool)
        self.kinematic[self.n_cloth:] = True
        self.n_colliders = len(self.object_tris) - self.n_ranks
        self.leaf_size = leaf_size
        self._trees: list[BVH] | None = None
        if rest is not None:
            self.build(rest)

    @property
    def n_objects(self) -> int:
        return len(self.object_tris)

    def build(self, x) -> None:
        """Tree topologies from positions x (the rest shape): once, identically on every rank."""
        x = np.ascontiguousarray(x, dtype=np.float64)
        self._trees = [build_bvh(self.tri[ids], x, leaf_size=self.leaf_size)
                       for ids in self.object_tris]

    def trees(self, x0, x1=None, pad: float = 0.0, cloth_only: bool = False) -> list[BVH]:
        """Every object's tree refitted to the boxes swept over x0 -> x1, grown
        by pad (``cloth_only``: the cloth objects' only; the colliders' keep
        their last boxes and must not be tested)."""
        if self._trees is None:
            self.build(x0)
        x0 = np.ascontiguousarray(x0, dtype=np.float64)
        x1 = x0 if x1 is None else np.ascontiguousarray(x1, dtype=np.float64)
        objects = self.n_ranks if cloth_only else self.n_objects
        for ids, t in zip(self.object_tris[:objects], self._trees[:objects]):
            if ids.size:
                refit(t, self.tri[ids], x0, x1, pad)
        return self._trees

    def root_tests(self, trees, self_collision: bool, cloth_only: bool = False) -> np.ndarray:
        """Top-level tasks (obj1, 0, obj2, 0) whose root boxes overlap, in a
        fixed order: each rank's self test and the cross tests between ranks
        (only with self-collision), then each rank's sub-mesh against each
        collider (not with ``cloth_only``).  ``combine_roots`` builds the top
        of the replicated tree; the overlap of its leaves decides which pairs
        are tasks."""
        P = self.n_ranks
        lo = np.array([t.lo[0] if t.n_nodes else np.full(3, np.inf) for t in trees])
        hi = np.array([t.hi[0] if t.n_nodes else np.full(3, -np.inf) for t in trees])
        combine_roots(lo, hi)         # validates the boxes; the top tree is tiny
        tests = []
        for a in range(self.n_objects):
            for b in range(a, self.n_objects):
                if b >= P and (a >= P or cloth_only):
                    continue                         # collider against collider: never
                if b < P and not self_collision:
                    continue                         # cloth against cloth: self-collision only
                if not (trees[a].n_nodes and trees[b].n_nodes):
                    continue
                if np.any(lo[a] > hi[b]) or np.any(lo[b] > hi[a]):
                    continue
                tests.append((a, 0, b, 0))
        return np.array(tests, dtype=np.int64).reshape(-1, 4)

    def static_owner(self, tests: np.ndarray) -> np.ndarray:
        """The rank that runs each top-level task when work is assigned
        statically: a rank's own self and collider tasks; a cross task between
        ranks r < s alternates between them ((r + s) even: r) so neither
        rank takes all of its interface."""
        a, b = tests[:, 0], tests[:, 2]
        P = self.n_ranks
        owner = a.copy()
        cross = (b < P) & (a != b)
        owner[cross] = np.where((a[cross] + b[cross]) % 2 == 0, a[cross], b[cross])
        return owner

    def triangle_pairs(self, rows: np.ndarray) -> np.ndarray:
        """Traversal rows (obj1, p1, obj2, p2) as global triangle id pairs (k, 2)."""
        if rows.shape[0] == 0:
            return np.zeros((0, 2), dtype=np.int64)
        t1 = np.empty(rows.shape[0], dtype=np.int64)
        t2 = np.empty(rows.shape[0], dtype=np.int64)
        for o in np.unique(np.concatenate([rows[:, 0], rows[:, 2]])):
            ids = self.object_tris[o]
            m1, m2 = rows[:, 0] == o, rows[:, 2] == o
            t1[m1] = ids[rows[m1, 1]]
            t2[m2] = ids[rows[m2, 3]]
        return np.stack([t1, t2], axis=1)

    def primitive_pairs(self, tri_pairs, x0, x1=None, pad: float = 0.0):
        """Vertex-face (vertex, face) and edge-edge (edge a < edge b) pairs of
        the triangle pairs whose swept boxes (grown by pad) overlap, sorted
        unique; pairs sharing a vertex and pairs of kinematic primitives only
        are left out.  ``tri_pairs`` must hold every triangle pair whose
        boxes overlap (each once, in either order): a primitive pair is
        taken from the pair of its primitives' owner triangles only."""
        x0 = np.ascontiguousarray(x0, dtype=np.float64)
        x1 = x0 if x1 is None else np.ascontiguousarray(x1, dtype=np.float64)
        tp = np.ascontiguousarray(tri_pairs, dtype=np.int64).reshape(-1, 2)
        k = tp.shape[0]
        vf = np.empty((6 * k, 2), np.int64)
        ee = np.empty((9 * k, 2), np.int64)
        nvf, nee = _expand(tp, self.tri, self.tri_edges, self.edges, self.kinematic,
                           self.vertex_owner, self.edge_owner, x0, x1, float(pad), vf, ee)
        return unique_rows(vf[:nvf]), unique_rows(ee[:nee])


def _triangle_edges(tri, edges) -> np.ndarray:
    """(m, 3) edge id of each triangle side (v0v1, v1v2, v2v0)."""
    n = int(tri.max()) + 1 if tri.size else 0
    key = edges[:, 0] * n + edges[:, 1]
    out = np.empty(tri.shape, dtype=np.int64)
    for s, (i, j) in enumerate(((0, 1), (1, 2), (2, 0))):
        a = np.minimum(tri[:, i], tri[:, j])
        b = np.maximum(tri[:, i], tri[:, j])
        out[:, s] = np.searchsorted(key, a * n + b)
    return out


def _first_triangle(corner_ids: np.ndarray, n: int) -> np.ndarray:
    """(n,) the lowest triangle id whose three entries of ``corner_ids``
    (triangle-major, 3 per triangle) hold each id; -1 for ids in none."""
    none = np.iinfo(np.int64).max
    owner = np.full(n, none, dtype=np.int64)
    np.minimum.at(owner, corner_ids, np.repeat(np.arange(corner_ids.size // 3, dtype=np.int64), 3))
    owner[owner == none] = -1
    return owner


@njit(cache=True)
def _box_overlap(ids1, ids2, x0, x1, pad):
    for a in range(3):
        lo1 = np.inf
        hi1 = -np.inf
        for v in ids1:
            lo1 = min(lo1, x0[v, a], x1[v, a])
            hi1 = max(hi1, x0[v, a], x1[v, a])
        lo2 = np.inf
        hi2 = -np.inf
        for v in ids2:
            lo2 = min(lo2, x0[v, a], x1[v, a])
            hi2 = max(hi2, x0[v, a], x1[v, a])
        if lo1 - pad > hi2 + pad or lo2 - pad > hi1 + pad:
            return False
    return True


@njit(cache=True)
def _expand(tp, tri, tri_edges, edges, kinematic, vertex_owner, edge_owner, x0, x1, pad,
            vf, ee):
    nvf = 0
    nee = 0
    one = np.empty(1, np.int64)
    for k in range(tp.shape[0]):
        for side in range(2):
            ta = tp[k, side]
            tb = tp[k, 1 - side]
            fb = tri[tb]
            for i in range(3):
                v = tri[ta, i]
                if vertex_owner[v] != ta:
                    continue
                if v == fb[0] or v == fb[1] or v == fb[2]:
                    continue
                if kinematic[v] and kinematic[fb[0]] and kinematic[fb[1]] and kinematic[fb[2]]:
                    continue
                one[0] = v
                if _box_overlap(one, fb, x0, x1, pad):
                    vf[nvf, 0] = v
                    vf[nvf, 1] = tb
                    nvf += 1
        for i in range(3):
            ea = tri_edges[tp[k, 0], i]
            if edge_owner[ea] != tp[k, 0]:
                continue
            for j in range(3):
                eb = tri_edges[tp[k, 1], j]
                if edge_owner[eb] != tp[k, 1]:
                    continue
                a0 = edges[ea, 0]
                a1 = edges[ea, 1]
                b0 = edges[eb, 0]
                b1 = edges[eb, 1]
                if ea == eb or a0 == b0 or a0 == b1 or a1 == b0 or a1 == b1:
                    continue
                if kinematic[a0] and kinematic[a1] and kinematic[b0] and kinematic[b1]:
                    continue
                if _box_overlap(edges[ea], edges[eb], x0, x1, pad):
                    ee[nee, 0] = min(ea, eb)
                    ee[nee, 1] = max(ea, eb)
                    nee += 1
    return nvf, nee
