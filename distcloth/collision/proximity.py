"""Proximity queries on candidate pairs: vertex-face and edge-edge.

EG07 tutorial, Part 1 §2.3: the response of Bridson et
al. 2002 acts on vertex-triangle and edge-edge pairs "whenever their
distance falls below a certain threshold" (the cloth thickness); these
kernels find those pairs among the BVH candidates and return what the
response needs: the ids, the barycentric weights of the closest points, the
unit direction and the distance.

Conventions
-----------
* Vertex-face: weights (w0, w1, w2) of the closest point on the triangle
  (sum 1, all >= 0); ``normal`` points from the closest point on the
  triangle to the vertex.  If the vertex lies on the triangle (distance
  ~ 0) the triangle's face normal (right-hand winding) is returned.
* Edge-edge: parameters (s, t) in [0, 1] of the closest points
  a0 + s (a1 - a0) and b0 + t (b1 - b0); ``normal`` points from edge a to
  edge b; at distance ~ 0 it is the unit a x b (or any unit vector
  perpendicular to a if the edges are parallel).
* Pairs sharing a vertex are skipped (they are in contact by construction).
* Output is sorted by the primitive ids, so it does not depend on the order
  of the candidate list.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from .traverse import unique_rows


class VertexFaceContacts(NamedTuple):
    vertex: np.ndarray     # int64 (k,)
    face: np.ndarray       # int64 (k,)
    weights: np.ndarray    # float64 (k, 3)
    normal: np.ndarray     # float64 (k, 3), face -> vertex
    distance: np.ndarray   # float64 (k,)


class EdgeEdgeContacts(NamedTuple):
    edge_a: np.ndarray     # int64 (k,), edge_a < edge_b
    edge_b: np.ndarray     # int64 (k,)
    params: np.ndarray     # float64 (k, 2): (s, t)
    normal: np.ndarray     # float64 (k, 3), edge a -> edge b
    distance: np.ndarray   # float64 (k,)


_TINY = 1e-300
_REL = 1e-12      # distances below _REL * (primitive size) count as touching for the normal


@njit(cache=True)
def _dot(a0, a1, a2, b0, b1, b2):
    return a0 * b0 + a1 * b1 + a2 * b2


@njit(cache=True)
def _point_segment(p, a, b):
    """Closest point of segment ab to p: (dist2, t)."""
    d0 = b[0] - a[0]; d1 = b[1] - a[1]; d2 = b[2] - a[2]
    dd = _dot(d0, d1, d2, d0, d1, d2)
    t = 0.0
    if dd > 0.0:
        t = _dot(p[0] - a[0], p[1] - a[1], p[2] - a[2], d0, d1, d2) / dd
        t = min(1.0, max(0.0, t))
    e0 = a[0] + t * d0 - p[0]; e1 = a[1] + t * d1 - p[1]; e2 = a[2] + t * d2 - p[2]
    return _dot(e0, e1, e2, e0, e1, e2), t


@njit(cache=True)
def _unit_or(v0, v1, v2, f0, f1, f2, vmin):
    """v / |v|, or the unit fallback f when |v| <= vmin (v is then rounding
    noise and its direction meaningless)."""
    n = np.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
    if n > max(vmin, _TINY):
        return v0 / n, v1 / n, v2 / n
    n = np.sqrt(f0 * f0 + f1 * f1 + f2 * f2)
    if n > _TINY:
        return f0 / n, f1 / n, f2 / n
    return 0.0, 0.0, 1.0


@njit(cache=True)
def _triangle_weights(p, a, b, c):
    """Barycentric weights of the point of triangle abc closest to p, by
    Voronoi regions (Ericson, Real-Time Collision Detection §5.1.5).  Only
    the region actually hit divides, by a squared edge length (edge
    regions) or the squared double area (face region); a zero denominator
    means a degenerate triangle and returns (-1, -1, -1)."""
    ab0 = b[0] - a[0]; ab1 = b[1] - a[1]; ab2 = b[2] - a[2]
    ac0 = c[0] - a[0]; ac1 = c[1] - a[1]; ac2 = c[2] - a[2]
    ap0 = p[0] - a[0]; ap1 = p[1] - a[1]; ap2 = p[2] - a[2]
    d1 = _dot(ab0, ab1, ab2, ap0, ap1, ap2)
    d2 = _dot(ac0, ac1, ac2, ap0, ap1, ap2)
    if d1 <= 0.0 and d2 <= 0.0:
        return 1.0, 0.0, 0.0                                  # vertex a
    bp0 = p[0] - b[0]; bp1 = p[1] - b[1]; bp2 = p[2] - b[2]
    d3 = _dot(ab0, ab1, ab2, bp0, bp1, bp2)
    d4 = _dot(ac0, ac1, ac2, bp0, bp1, bp2)
    if d3 >= 0.0 and d4 <= d3:
        return 0.0, 1.0, 0.0                                  # vertex b
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0 and d1 - d3 > 0.0:
        v = d1 / (d1 - d3)                                    # edge ab
        return 1.0 - v, v, 0.0
    cp0 = p[0] - c[0]; cp1 = p[1] - c[1]; cp2 = p[2] - c[2]
    d5 = _dot(ab0, ab1, ab2, cp0, cp1, cp2)
    d6 = _dot(ac0, ac1, ac2, cp0, cp1, cp2)
    if d6 >= 0.0 and d5 <= d6:
        return 0.0, 0.0, 1.0                                  # vertex c
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0 and d2 - d6 > 0.0:
        w = d2 / (d2 - d6)                                    # edge ac
        return 1.0 - w, 0.0, w
    va = d3 * d6 - d5 * d4
    e43 = d4 - d3
    e56 = d5 - d6
    if va <= 0.0 and e43 >= 0.0 and e56 >= 0.0 and e43 + e56 > 0.0:
        w = e43 / (e43 + e56)                                 # edge bc
        return 0.0, 1.0 - w, w
    den = va + vb + vc
    if den > 0.0:
        v = vb / den                                          # face
        w = vc / den
        return 1.0 - v - w, v, w
    return -1.0, -1.0, -1.0


@njit(cache=True)
def point_triangle(p, a, b, c):
    """Closest point of triangle abc to p (see ``_triangle_weights``);
    degenerate (zero-area) triangles fall back to the closest of the three
    edges.  Returns (dist, w0, w1, w2, n0, n1, n2); n is the unit direction
    from the closest point to p (the face normal when p is on the
    triangle)."""
    w0, w1, w2 = _triangle_weights(p, a, b, c)
    if w0 < 0.0:
        dab, tab = _point_segment(p, a, b)
        dac, tac = _point_segment(p, a, c)
        dbc, tbc = _point_segment(p, b, c)
        if dab <= dac and dab <= dbc:
            w0 = 1.0 - tab; w1 = tab; w2 = 0.0
        elif dac <= dbc:
            w0 = 1.0 - tac; w1 = 0.0; w2 = tac
        else:
            w0 = 0.0; w1 = 1.0 - tbc; w2 = tbc
    e0 = p[0] - (w0 * a[0] + w1 * b[0] + w2 * c[0])
    e1 = p[1] - (w0 * a[1] + w1 * b[1] + w2 * c[1])
    e2 = p[2] - (w0 * a[2] + w1 * b[2] + w2 * c[2])
    dist = np.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
    ab0 = b[0] - a[0]; ab1 = b[1] - a[1]; ab2 = b[2] - a[2]
    ac0 = c[0] - a[0]; ac1 = c[1] - a[1]; ac2 = c[2] - a[2]
    fn0 = ab1 * ac2 - ab2 * ac1; fn1 = ab2 * ac0 - ab0 * ac2; fn2 = ab0 * ac1 - ab1 * ac0
    scale = np.sqrt(max(_dot(ab0, ab1, ab2, ab0, ab1, ab2), _dot(ac0, ac1, ac2, ac0, ac1, ac2)))
    n0, n1, n2 = _unit_or(e0, e1, e2, fn0, fn1, fn2, _REL * scale)
    return dist, w0, w1, w2, n0, n1, n2


@njit(cache=True)
def segment_segment(a0, a1, b0, b1):
    """Closest points of segments a0a1 and b0b1 (Ericson §5.1.9).

    Parallel (or degenerate) segments are detected with a *relative* test
    on the Gram determinant; then s = 0 is taken and t, and s again after
    clamping t, are the exact clamped projections, which is a closest pair
    for parallel segments.  Returns (dist, s, t, n0, n1, n2), n the unit
    direction from the point on a to the point on b."""
    d10 = a1[0] - a0[0]; d11 = a1[1] - a0[1]; d12 = a1[2] - a0[2]
    d20 = b1[0] - b0[0]; d21 = b1[1] - b0[1]; d22 = b1[2] - b0[2]
    r0 = a0[0] - b0[0]; r1 = a0[1] - b0[1]; r2 = a0[2] - b0[2]
    aa = _dot(d10, d11, d12, d10, d11, d12)
    ee = _dot(d20, d21, d22, d20, d21, d22)
    f = _dot(d20, d21, d22, r0, r1, r2)
    s = 0.0
    t = 0.0
    if aa <= _TINY and ee <= _TINY:
        pass
    elif aa <= _TINY:
        t = min(1.0, max(0.0, f / ee))
    else:
        c = _dot(d10, d11, d12, r0, r1, r2)
        if ee <= _TINY:
            s = min(1.0, max(0.0, -c / aa))
        else:
            b = _dot(d10, d11, d12, d20, d21, d22)
            den = aa * ee - b * b
            if den > 1e-14 * aa * ee:
                s = min(1.0, max(0.0, (b * f - c * ee) / den))
            t = (b * s + f) / ee
            if t < 0.0:
                t = 0.0
                s = min(1.0, max(0.0, -c / aa))
            elif t > 1.0:
                t = 1.0
                s = min(1.0, max(0.0, (b - c) / aa))
    e0 = b0[0] + t * d20 - a0[0] - s * d10
    e1 = b0[1] + t * d21 - a0[1] - s * d11
    e2 = b0[2] + t * d22 - a0[2] - s * d12
    dist = np.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
    c0 = d11 * d22 - d12 * d21; c1 = d12 * d20 - d10 * d22; c2 = d10 * d21 - d11 * d20
    if c0 * c0 + c1 * c1 + c2 * c2 <= 1e-24 * aa * ee:        # parallel: any normal of a
        if abs(d10) <= abs(d11) and abs(d10) <= abs(d12):
            c0 = 0.0; c1 = d12; c2 = -d11
        elif abs(d11) <= abs(d12):
            c0 = -d12; c1 = 0.0; c2 = d10
        else:
            c0 = d11; c1 = -d10; c2 = 0.0
    n0, n1, n2 = _unit_or(e0, e1, e2, c0, c1, c2, _REL * np.sqrt(max(aa, ee)))
    return dist, s, t, n0, n1, n2


@njit(cache=True)
def _vf_kernel(x, tri, pairs, thickness, keep, w, nrm, dist):
    for k in range(pairs.shape[0]):
        v = pairs[k, 0]
        f = pairs[k, 1]
        i0 = tri[f, 0]; i1 = tri[f, 1]; i2 = tri[f, 2]
        keep[k] = False
        if v == i0 or v == i1 or v == i2:
            continue
        d, w0, w1, w2, n0, n1, n2 = point_triangle(x[v], x[i0], x[i1], x[i2])
        if d < thickness:
            keep[k] = True
            w[k, 0] = w0; w[k, 1] = w1; w[k, 2] = w2
            nrm[k, 0] = n0; nrm[k, 1] = n1; nrm[k, 2] = n2
            dist[k] = d


@njit(cache=True)
def _ee_kernel(x, edges, pairs, thickness, keep, st, nrm, dist):
    for k in range(pairs.shape[0]):
        ea = pairs[k, 0]
        eb = pairs[k, 1]
        a0 = edges[ea, 0]; a1 = edges[ea, 1]; b0 = edges[eb, 0]; b1 = edges[eb, 1]
        keep[k] = False
        if ea == eb or a0 == b0 or a0 == b1 or a1 == b0 or a1 == b1:
            continue
        d, s, t, n0, n1, n2 = segment_segment(x[a0], x[a1], x[b0], x[b1])
        if d < thickness:
            keep[k] = True
            st[k, 0] = s; st[k, 1] = t
            nrm[k, 0] = n0; nrm[k, 1] = n1; nrm[k, 2] = n2
            dist[k] = d


def _pairs(pairs) -> np.ndarray:
    return np.ascontiguousarray(np.asarray(pairs, dtype=np.int64).reshape(-1, 2))


def _sorted_unique(pairs, keep):
    """Indices of the kept rows in canonical order, one per distinct row."""
    idx = np.flatnonzero(keep)
    rows = pairs[idx]
    order = np.lexsort(rows.T[::-1])
    idx, rows = idx[order], rows[order]
    first = np.ones(idx.shape[0], np.bool_)
    first[1:] = np.any(rows[1:] != rows[:-1], axis=1)
    return idx[first]


def vertex_face_contacts(x, tri, pairs, thickness: float) -> VertexFaceContacts:
    """Vertex-face pairs ``(vertex, face) (n, 2)`` closer than ``thickness``,
    sorted by (vertex, face); duplicates in ``pairs`` are removed."""
    pairs = _pairs(pairs)
    x = np.ascontiguousarray(x, dtype=np.float64)
    n = pairs.shape[0]
    keep = np.zeros(n, np.bool_)
    w = np.zeros((n, 3)); nrm = np.zeros((n, 3)); dist = np.zeros(n)
    _vf_kernel(x, np.ascontiguousarray(tri, dtype=np.int64), pairs, float(thickness),
               keep, w, nrm, dist)
    k = _sorted_unique(pairs, keep)
    return VertexFaceContacts(pairs[k, 0], pairs[k, 1], w[k], nrm[k], dist[k])


def edge_edge_contacts(x, edges, pairs, thickness: float) -> EdgeEdgeContacts:
    """Edge-edge pairs ``(ea, eb) (n, 2)`` closer than ``thickness``, as
    canonical rows ea < eb sorted by (ea, eb); duplicates are removed."""
    pairs = np.ascontiguousarray(np.sort(_pairs(pairs), axis=1))
    x = np.ascontiguousarray(x, dtype=np.float64)
    n = pairs.shape[0]
    keep = np.zeros(n, np.bool_)
    st = np.zeros((n, 2)); nrm = np.zeros((n, 3)); dist = np.zeros(n)
    _ee_kernel(x, np.ascontiguousarray(edges, dtype=np.int64), pairs, float(thickness),
               keep, st, nrm, dist)
    k = _sorted_unique(pairs, keep)
    return EdgeEdgeContacts(pairs[k, 0], pairs[k, 1], st[k], nrm[k], dist[k])


def open_edges(tri) -> np.ndarray:
    """(m, 2) the undirected edges (i < j) that belong to one triangle only:
    a mesh's boundary."""
    tri = np.asarray(tri, dtype=np.int64).reshape(-1, 3)
    e = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    key = np.sort(e, axis=1)
    _, first, counts = np.unique(key, axis=0, return_index=True, return_counts=True)
    return key[first[counts == 1]]


def mesh_edges(tri) -> np.ndarray:
    """Unique undirected edges (i < j) of a triangle mesh, sorted, int64 (e, 2)."""
    tri = np.asarray(tri, dtype=np.int64).reshape(-1, 3)
    e = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    return unique_rows(np.sort(e, axis=1))
