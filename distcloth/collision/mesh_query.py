"""Closest-point and signed-distance queries of arbitrary points against a
triangle-mesh collider, with the same answer as ``AnalyticCollider.query``.

Method
------
* Closest point: the AABB tree of :mod:`.bvh` over the collider triangles
  (built once with the topology, refit when the mesh has moved) and, per
  query point, a depth-first branch-and-bound search on an explicit stack:
  a node is skipped when the distance from the point to its box exceeds the
  best triangle distance found so far (initially ``max_distance``), the
  nearer child is visited first.  The triangle test is
  :func:`.proximity.point_triangle` (Ericson's Voronoi-region closest point).
* Sign (closed meshes only): J. A. Bærentzen and H. Aanæs, "Signed distance
  computation using the angle weighted pseudonormal", IEEE Trans.
  Visualization and Computer Graphics 11(3):243-253, 2005.  With c the
  closest surface point of p, sign(phi) = sign((p - c) . N), N the pseudo
  normal of the feature that contains c: the face normal if c is interior
  to a face, the sum of the two face normals if c is on an edge, and the
  sum of the incident face normals weighted by their angles at the vertex
  if c is a vertex.  This is exact for any watertight, consistently
  oriented manifold mesh (unlike the face normal of the closest face, which
  is wrong near convex vertices and edges).
* Open meshes (some edge not shared by exactly two consistently oriented
  triangles) have no inside: phi is the unsigned distance and the normal
  points from the closest point towards the query point, i.e. the surface is
  two-sided.

Conventions as in :mod:`.colliders`: phi < 0 inside, ``normal`` the unit
outward normal with ``points - phi * normal`` the closest surface point,
``velocity`` the collider's surface velocity there (barycentric
interpolation of ``collider.velocities(t)``).  Pure array code, no MPI.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .bvh import build_bvh, refit
from .colliders import MeshCollider
from .proximity import point_triangle

__all__ = ["MeshProximity"]

# below this distance (relative to the mesh size) p - c is rounding noise and
# the normal is taken from the surface instead
_NORMAL_REL = 1e-10


@njit(cache=True)
def _box_d2(p, lo, hi, i):
    """Squared distance from p to box i (0 inside)."""
    s = 0.0
    for a in range(3):
        g = max(lo[i, a] - p[a], p[a] - hi[i, a], 0.0)
        s += g * g
    return s


@njit(cache=True)
def _closest_kernel(pts, x, tri, lo, hi, left, right, first, count, order, plo, phi,
                    max_d, face, w, dist):
    """Nearest triangle of every point within max_d: face (-1 if none),
    barycentric weights, distance.  Ties keep the first triangle found."""
    nn = left.shape[0]
    stack = np.empty(nn + 1, np.int64)     # DFS: never more than depth + 1 entries
    sd2 = np.empty(nn + 1)
    for i in range(pts.shape[0]):
        p = pts[i]
        best = max_d
        bf = -1
        b0 = 0.0
        b1 = 0.0
        b2 = 0.0
        top = 0
        if nn > 0:
            stack[0] = 0
            sd2[0] = _box_d2(p, lo, hi, 0)
            top = 1
        while top > 0:
            top -= 1
            node = stack[top]
            if sd2[top] > best * best:
                continue
            l = left[node]
            if l < 0:
                for j in range(first[node], first[node] + count[node]):
                    f = order[j]
                    if _box_d2(p, plo, phi, f) > best * best:
                        continue
                    d, w0, w1, w2, _, _, _ = point_triangle(p, x[tri[f, 0]], x[tri[f, 1]],
                                                            x[tri[f, 2]])
                    if d < best or (bf < 0 and d <= best):
                        best = d
                        bf = f
                        b0 = w0
                        b1 = w1
                        b2 = w2
            else:
                r = right[node]
                dl = _box_d2(p, lo, hi, l)
                dr = _box_d2(p, lo, hi, r)
                if dl > dr:                  # push the farther child first
                    l, r = r, l
                    dl, dr = dr, dl
                b2max = best * best
                if dr <= b2max:
                    stack[top] = r
                    sd2[top] = dr
                    top += 1
                if dl <= b2max:
                    stack[top] = l
                    sd2[top] = dl
                    top += 1
        face[i] = bf
        if bf >= 0:
            w[i, 0] = b0
            w[i, 1] = b1
            w[i, 2] = b2
            dist[i] = best
        else:
            w[i, 0] = 0.0
            w[i, 1] = 0.0
            w[i, 2] = 0.0
            dist[i] = np.inf


def _unit_rows(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 0.0, n, 1.0)


def _edge_adjacency(tri: np.ndarray, n_vertices: int, cut: bool = False):
    """(closed, adj): adj[f, k] is the face across edge k of face f (edge k
    runs from corner k to corner k+1 mod 3).  closed: every directed edge is
    unique and its reverse exists, i.e. every edge is shared by exactly two
    triangles with opposite orientation (watertight, consistently oriented).
    ``cut``: a part cut out of such a mesh; its boundary edges get adj -1 and
    it counts as closed if every directed edge is unique (consistently
    oriented)."""
    a = tri.reshape(-1)
    b = tri[:, [1, 2, 0]].reshape(-1)
    key = a * n_vertices + b
    rev = b * n_vertices + a
    srt = np.argsort(key, kind="stable")
    ks = key[srt]
    if (ks[1:] == ks[:-1]).any():
        return False, None
    pos = np.minimum(np.searchsorted(ks, rev), ks.shape[0] - 1)
    found = ks[pos] == rev
    if cut:
        return True, np.where(found, srt[pos] // 3, -1).reshape(-1, 3)
    if not found.all():
        return False, None
    return True, (srt[pos] // 3).reshape(-1, 3)


class MeshProximity:
    """Closest points and signed distances to a :class:`MeshCollider`.

    ``closed`` tells whether the mesh is watertight and consistently
    oriented (then phi is signed; an inward oriented mesh, negative volume,
    is flipped); otherwise phi is the unsigned distance.  Geometry is cached
    per t for the last ``KEEP_TIMES`` times: a step asks at its start and
    its end in turn (detection, then the solve's revision and the
    response), and going back to a kept time neither refits nor recomputes
    normals or velocities; a static mesh without motion is never refit.
    ``n_refits`` counts the refits.
    """

    KEEP_TIMES = 3           # the current time included

    def __init__(self, collider: MeshCollider, leaf_size: int = 4):
        self.collider = collider
        self.triangles = np.ascontiguousarray(collider.triangles, dtype=np.int64)
        nv = collider.n_vertices
        # a body part cut out of a closed mesh keeps signed distances
        # (body/regions.py: the cut lies where parts out of the cloth's reach join)
        self.closed, self._adj = _edge_adjacency(self.triangles, nv,
                                                 collider.cut_of_closed)
        self._static = not collider.is_deforming and collider.motion.is_identity
        t0 = float(collider.frame_times[0])
        x0 = np.ascontiguousarray(collider.vertices(t0))
        self._bvh = build_bvh(self.triangles, x0, leaf_size=leaf_size)
        a, b, c = (x0[self.triangles[:, k]] for k in range(3))
        self._orient = 1.0
        if self.closed and np.einsum("ij,ij->i", a, np.cross(b, c)).sum() < 0.0:
            self._orient = -1.0
        self.n_refits = 0
        self._t = t0
        self._x = x0
        self._v = None
        self._fn = self._vn = None
        self._kept: dict = {}      # t -> the geometry at t other than the current

    # -------------------------------------------------------------- geometry at t
    friction = property(lambda self: self.collider.friction)
    thickness = property(lambda self: self.collider.thickness)

    def _update(self, t: float) -> None:
        t = float(t)
        if self._static or t == self._t:
            return
        b = self._bvh
        self._kept[self._t] = (self._x, self._v, self._fn, self._vn, b.lo, b.hi, b.plo, b.phi)
        kept = self._kept.pop(t, None)
        if kept is None:
            if len(self._kept) >= self.KEEP_TIMES:      # the oldest time's boxes are reused
                boxes = self._kept.pop(next(iter(self._kept)))[4:]
            else:
                boxes = tuple(a.copy() for a in (b.lo, b.hi, b.plo, b.phi))
            b.lo, b.hi, b.plo, b.phi = boxes
            self._x = np.ascontiguousarray(self.collider.vertices(t))
            refit(b, self.triangles, self._x)
            self.n_refits += 1
            self._v = self._fn = self._vn = None
        else:
            self._x, self._v, self._fn, self._vn, b.lo, b.hi, b.plo, b.phi = kept
        self._t = t

    def vertices(self, t: float = 0.0) -> np.ndarray:
        self._update(t)
        return self._x

    def move_to(self, vertices) -> None:
        """A static mesh's vertices moved (the same triangles, the same
        orientation): its tree is refit, not rebuilt, and its edge adjacency
        kept, for callers that query one mesh in many poses."""
        if not self._static:
            raise ValueError("MeshProximity.move_to: the mesh moves by itself")
        self._x = np.ascontiguousarray(vertices, dtype=np.float64).reshape(self._x.shape)
        refit(self._bvh, self.triangles, self._x)
        self.n_refits += 1
        self._v = self._fn = self._vn = None

    def _velocities(self) -> np.ndarray:
        if self._v is None:
            self._v = self.collider.velocities(self._t)
        return self._v

    def _normals(self):
        """Unit face normals and (closed meshes) angle-weighted vertex pseudo-normals."""
        if self._fn is None:
            tri, x = self.triangles, self._x
            corner = [x[tri[:, k]] for k in range(3)]
            fn = _unit_rows(np.cross(corner[1] - corner[0], corner[2] - corner[0])) * self._orient
            vn = None
            if self.closed:
                vn = np.zeros_like(x)
                for k in range(3):
                    e1 = corner[(k + 1) % 3] - corner[k]
                    e2 = corner[(k + 2) % 3] - corner[k]
                    ang = np.arctan2(np.linalg.norm(np.cross(e1, e2), axis=1),
                                     np.einsum("ij,ij->i", e1, e2))
                    for a in range(3):
                        vn[:, a] += np.bincount(tri[:, k], ang * fn[:, a], minlength=x.shape[0])
            self._fn, self._vn = fn, vn
        return self._fn, self._vn

    # -------------------------------------------------------------- queries
    def closest(self, points, t: float = 0.0, max_distance: float = np.inf):
        """(face (n,) int64, weights (n, 3), distance (n,)) of the closest
        point of the mesh at time t to every point; face = -1, weights 0 and
        distance inf when no triangle is within ``max_distance``."""
        if not max_distance >= 0.0:
            raise ValueError("MeshProximity: max_distance must be >= 0")
        pts = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 3))
        self._update(t)
        n = pts.shape[0]
        face = np.empty(n, np.int64)
        w = np.empty((n, 3))
        dist = np.empty(n)
        b = self._bvh
        _closest_kernel(pts, self._x, self.triangles, b.lo, b.hi, b.left, b.right, b.first,
                        b.count, b.order, b.plo, b.phi, float(max_distance), face, w, dist)
        return face, w, dist

    def query(self, points, t: float = 0.0, max_distance: float = np.inf):
        """(phi (n,), normal (n, 3), velocity (n, 3)) as ``AnalyticCollider.query``;
        points farther than ``max_distance`` get phi = +inf, normal = velocity = 0
        (also when inside a closed mesh: depth beyond max_distance is not seen)."""
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        face, w, dist = self.closest(pts, t, max_distance)
        n = pts.shape[0]
        phi = np.full(n, np.inf)
        normal = np.zeros((n, 3))
        velocity = np.zeros((n, 3))
        hit = np.flatnonzero(face >= 0)
        if hit.size == 0:
            return phi, normal, velocity
        f, wh, d = face[hit], w[hit], dist[hit]
        vid = self.triangles[f]                                     # (k, 3)
        c = np.einsum("ij,ijk->ik", wh, self._x[vid])
        velocity[hit] = np.einsum("ij,ijk->ik", wh, self._velocities()[vid])
        e = pts[hit] - c
        fn, vn = self._normals()
        surf = fn[f]                          # normal of the surface at c (face, edge or vertex)
        zero = wh == 0.0
        nzero = zero.sum(axis=1)
        if self.closed:
            edge = np.flatnonzero(nzero == 1)        # edge k = corners k, k+1: opposite corner k+2
            k = (np.argmax(zero[edge], axis=1) + 1) % 3
            across = self._adj[f[edge], k]            # -1: a cut's boundary, its own face only
            surf[edge] += fn[np.where(across >= 0, across, f[edge])]
            vert = np.flatnonzero(nzero == 2)
            surf[vert] = vn[vid[vert, np.argmax(wh[vert], axis=1)]]
            sign = np.where(np.einsum("ij,ij->i", e, surf) < 0.0, -1.0, 1.0)
        else:
            side = np.einsum("ij,ij->i", e, surf)
            surf *= np.where(side < 0.0, -1.0, 1.0)[:, None]          # two-sided
            sign = np.ones(hit.size)
        lo, hi = self._bvh.root_box()
        tiny = _NORMAL_REL * max(float(np.max(hi - lo)), 1e-300)
        far = d > tiny
        nrm = _unit_rows(surf)
        nrm[far] = sign[far, None] * e[far] / d[far, None]
        bad = np.linalg.norm(nrm, axis=1) == 0.0                    # degenerate faces only
        nrm[bad] = (0.0, 0.0, 1.0)
        phi[hit] = sign * d
        normal[hit] = nrm
        return phi, normal, velocity

    def signed_distance(self, points, t: float = 0.0, max_distance: float = np.inf):
        """(phi, normal) as ``AnalyticCollider.signed_distance``."""
        phi, normal, _ = self.query(points, t, max_distance)
        return phi, normal
