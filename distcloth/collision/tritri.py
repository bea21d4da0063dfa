"""Triangle-triangle intersection: the oracle for "is the cloth tangled".

The EG07 tutorial, Part 1 §2.3, notes that even robust
response cannot always prevent intersections (multi-layer collisions,
pinching), so a simulation needs a way to *detect* an intersecting state;
this module counts the intersecting triangle pairs of a mesh.

Predicate
---------
Guigue and Devillers, "Fast and robust triangle-triangle overlap test using
orientation predicates" (JGT 8(1), 2003): the same scheme as Möller (1997)
but every decision is the sign of a 3x3 determinant of input point
differences (no constructed intersection points, no divisions).  With
double precision the signs are exact whenever the determinant is computed
exactly (e.g. small integer coordinates); a determinant smaller than its
forward error bound (Shewchuk's orient3d filter) is taken as zero, so a
configuration within rounding of a degenerate one is decided as that
degenerate (touching or coplanar) case rather than by the sign of noise.  The coplanar case is a
2D test in the axis plane best aligned with the triangles: two closed
triangles overlap iff a vertex of one lies in the other or two edges cross.

Convention: triangles are *closed* sets.  Touching (a vertex on the other
triangle, an edge touching an edge, coplanar triangles sharing only boundary
points) counts as intersecting.  Zero-area triangles are not supported.

Mesh self-intersection
----------------------
Triangles of one mesh that share vertices always touch, so:

* no shared vertex: the full predicate above;
* exactly one shared vertex v, T1 = (v, a, b), T2 = (v, c, d): they
  intersect in more than v iff segment ab meets T2 or segment cd meets T1
  (closed segment-triangle tests).  Non-coplanar case: both triangles meet
  the line of their two planes, which passes through v, in segments
  starting at v; if these overlap beyond v, the end of the shorter one
  lies on the opposite edge of its triangle and inside the other.
  Coplanar case: likewise along any ray from v into the common wedge;
* two or three shared vertices (neighbours across an edge, or duplicates):
  not tested (a fold of neighbours onto each other is not a crossing a
  triangle-pair test can define).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .bvh import build_bvh
from .traverse import self_pairs, unique_rows


@njit(cache=True)
def plane_side(p, q, r, x):
    """((p - r) x (q - r)) . (x - r): > 0 if x is on the side of plane pqr
    its right-hand normal points to (orient3d up to sign convention)."""
    u0 = p[0] - r[0]; u1 = p[1] - r[1]; u2 = p[2] - r[2]
    v0 = q[0] - r[0]; v1 = q[1] - r[1]; v2 = q[2] - r[2]
    w0 = x[0] - r[0]; w1 = x[1] - r[1]; w2 = x[2] - r[2]
    det = (u1 * v2 - u2 * v1) * w0 + (u2 * v0 - u0 * v2) * w1 + (u0 * v1 - u1 * v0) * w2
    # Shewchuk's static filter for orient3d (error bound (7 + 56 eps) eps times
    # the permanent): a determinant within rounding has no reliable sign, and
    # a random one sends nearly coplanar triangles (flat cloth on a flat
    # body) down the transversal branch, which then reports false crossings;
    # 0 sends them to the coplanar 2D test instead
    perm = ((abs(u1 * v2) + abs(u2 * v1)) * abs(w0) + (abs(u2 * v0) + abs(u0 * v2)) * abs(w1)
            + (abs(u0 * v1) + abs(u1 * v0)) * abs(w2))
    if abs(det) <= 7.771561172376103e-16 * perm:
        return 0.0
    return det


@njit(cache=True)
def _orient2d(a0, a1, b0, b1, c0, c1):
    return (a0 - c0) * (b1 - c1) - (a1 - c1) * (b0 - c0)


@njit(cache=True)
def _drop_axis(p1, q1, r1, p2, q2, r2):
    """Axis of the largest normal component of the larger of the two
    triangles' normals: projecting along it keeps the plane bijective."""
    best = -1.0
    axis = 2
    for t in range(2):
        a = p1 if t == 0 else p2
        b = q1 if t == 0 else q2
        c = r1 if t == 0 else r2
        u0 = b[0] - a[0]; u1 = b[1] - a[1]; u2 = b[2] - a[2]
        v0 = c[0] - a[0]; v1 = c[1] - a[1]; v2 = c[2] - a[2]
        n0 = abs(u1 * v2 - u2 * v1); n1 = abs(u2 * v0 - u0 * v2); n2 = abs(u0 * v1 - u1 * v0)
        if n0 > best:
            best = n0; axis = 0
        if n1 > best:
            best = n1; axis = 1
        if n2 > best:
            best = n2; axis = 2
    return axis


@njit(cache=True)
def _project(pts, axis, out):
    i = 1 if axis == 0 else 0
    j = 1 if axis == 2 else 2
    for k in range(pts.shape[0]):
        out[k, 0] = pts[k, i]
        out[k, 1] = pts[k, j]


@njit(cache=True)
def _on_segment2d(a, b, p):
    """p (known collinear with ab) within the closed segment's bounds."""
    return (min(a[0], b[0]) <= p[0] <= max(a[0], b[0])
            and min(a[1], b[1]) <= p[1] <= max(a[1], b[1]))


@njit(cache=True)
def _seg_seg2d(a, b, c, d):
    """Closed 2D segments ab and cd intersect."""
    d1 = _orient2d(c[0], c[1], d[0], d[1], a[0], a[1])
    d2 = _orient2d(c[0], c[1], d[0], d[1], b[0], b[1])
    d3 = _orient2d(a[0], a[1], b[0], b[1], c[0], c[1])
    d4 = _orient2d(a[0], a[1], b[0], b[1], d[0], d[1])
    if ((d1 > 0.0 and d2 < 0.0) or (d1 < 0.0 and d2 > 0.0)) and \
            ((d3 > 0.0 and d4 < 0.0) or (d3 < 0.0 and d4 > 0.0)):
        return True
    if d1 == 0.0 and _on_segment2d(c, d, a):
        return True
    if d2 == 0.0 and _on_segment2d(c, d, b):
        return True
    if d3 == 0.0 and _on_segment2d(a, b, c):
        return True
    if d4 == 0.0 and _on_segment2d(a, b, d):
        return True
    return False


@njit(cache=True)
def _point_in_tri2d(p, a, b, c):
    """p in the closed 2D triangle abc (either winding; False if abc is
    degenerate, whose cases the edge tests cover)."""
    if _orient2d(a[0], a[1], b[0], b[1], c[0], c[1]) == 0.0:
        return False
    o1 = _orient2d(a[0], a[1], b[0], b[1], p[0], p[1])
    o2 = _orient2d(b[0], b[1], c[0], c[1], p[0], p[1])
    o3 = _orient2d(c[0], c[1], a[0], a[1], p[0], p[1])
    return (o1 >= 0.0 and o2 >= 0.0 and o3 >= 0.0) or (o1 <= 0.0 and o2 <= 0.0 and o3 <= 0.0)


@njit(cache=True)
def _polys2d_overlap(P, nP, Q, nQ):
    """Closed 2D triangles/segments P (nP = 3 or 2 points) and Q overlap:
    a vertex of one inside the other, or two edges intersect."""
    if nQ == 3:
        for i in range(nP):
            if _point_in_tri2d(P[i], Q[0], Q[1], Q[2]):
                return True
    if nP == 3:
        for i in range(nQ):
            if _point_in_tri2d(Q[i], P[0], P[1], P[2]):
                return True
    for i in range(nP if nP == 3 else 1):
        for j in range(nQ if nQ == 3 else 1):
            if _seg_seg2d(P[i], P[(i + 1) % nP], Q[j], Q[(j + 1) % nQ]):
                return True
    return False


@njit(cache=True)
def _coplanar_tri_tri(p1, q1, r1, p2, q2, r2):
    axis = _drop_axis(p1, q1, r1, p2, q2, r2)
    A = np.empty((3, 3)); B = np.empty((3, 3))
    A[0] = p1; A[1] = q1; A[2] = r1
    B[0] = p2; B[1] = q2; B[2] = r2
    P = np.empty((3, 2)); Q = np.empty((3, 2))
    _project(A, axis, P)
    _project(B, axis, Q)
    return _polys2d_overlap(P, 3, Q, 3)


@njit(cache=True)
def _pick(p, q, r, i):
    return p if i == 0 else (q if i == 1 else r)


@njit(cache=True)
def _canonical_form(dp1, dq1, dr1):
    """Guigue-Devillers canonical form of a triangle T from the signs of its
    vertices against the other triangle's plane: (rotation of T so that its
    first vertex is alone on its side, whether the *other* triangle's last
    two vertices must be swapped); rotation -1 means all three on the
    plane.  This one case table is both dispatch levels of the paper's code
    (T1 against T2's plane, then T2 against T1's)."""
    if dp1 > 0.0:
        if dq1 > 0.0:
            return 2, True
        if dr1 > 0.0:
            return 1, True
        return 0, False
    if dp1 < 0.0:
        if dq1 < 0.0:
            return 2, False
        if dr1 < 0.0:
            return 1, False
        return 0, True
    if dq1 < 0.0:
        return (1, True) if dr1 >= 0.0 else (0, False)
    if dq1 > 0.0:
        return (0, True) if dr1 > 0.0 else (1, False)
    if dr1 > 0.0:
        return 2, False
    if dr1 < 0.0:
        return 2, True
    return -1, False


@njit(cache=True)
def tri_tri_intersect(p1, q1, r1, p2, q2, r2):
    """Closed triangles p1q1r1 and p2q2r2 intersect (Guigue-Devillers 2003).

    After the two plane-side rejections, both triangles are brought into
    canonical form (a vertex alone on its side of the other plane, the
    other triangle's winding adjusted so that the alone vertex sees it
    positively); then the intervals the triangles cut on the line of the two
    planes overlap iff neither of two orientations is positive."""
    dp1 = plane_side(p2, q2, r2, p1)
    dq1 = plane_side(p2, q2, r2, q1)
    dr1 = plane_side(p2, q2, r2, r1)
    if (dp1 > 0.0 and dq1 > 0.0 and dr1 > 0.0) or (dp1 < 0.0 and dq1 < 0.0 and dr1 < 0.0):
        return False
    dp2 = plane_side(p1, q1, r1, p2)
    dq2 = plane_side(p1, q1, r1, q2)
    dr2 = plane_side(p1, q1, r1, r2)
    if (dp2 > 0.0 and dq2 > 0.0 and dr2 > 0.0) or (dp2 < 0.0 and dq2 < 0.0 and dr2 < 0.0):
        return False
    rot1, flip2 = _canonical_form(dp1, dq1, dr1)
    if rot1 < 0:
        return _coplanar_tri_tri(p1, q1, r1, p2, q2, r2)
    a1 = _pick(p1, q1, r1, rot1)
    b1 = _pick(p1, q1, r1, (rot1 + 1) % 3)
    c1 = _pick(p1, q1, r1, (rot1 + 2) % 3)
    if flip2:                                   # T2 -> (p2, r2, q2)
        q2, r2 = r2, q2
        dq2, dr2 = dr2, dq2
    rot2, flip1 = _canonical_form(dp2, dq2, dr2)
    if rot2 < 0:
        return _coplanar_tri_tri(p1, q1, r1, p2, q2, r2)
    a2 = _pick(p2, q2, r2, rot2)
    b2 = _pick(p2, q2, r2, (rot2 + 1) % 3)
    c2 = _pick(p2, q2, r2, (rot2 + 2) % 3)
    if flip1:                                   # T1 -> (a1, c1, b1)
        b1, c1 = c1, b1
    # CHECK_MIN_MAX(a1, b1, c1, a2, b2, c2)
    if plane_side(a2, a1, b1, b2) > 0.0:
        return False
    if plane_side(a2, c1, a1, c2) > 0.0:
        return False
    return True


@njit(cache=True)
def segment_triangle_intersect(a, b, p, q, r):
    """Closed segment ab meets closed triangle pqr.  The segment reaches the
    plane iff a and b are not strictly on one side; the line ab meets the
    triangle iff the three volumes (a, b, edge) have no strictly opposite
    signs.  A segment lying in the plane is a 2D test."""
    da = plane_side(p, q, r, a)
    db = plane_side(p, q, r, b)
    if (da > 0.0 and db > 0.0) or (da < 0.0 and db < 0.0):
        return False
    if da == 0.0 and db == 0.0:
        axis = _drop_axis(p, q, r, p, q, r)
        T = np.empty((3, 3)); S = np.empty((2, 3))
        T[0] = p; T[1] = q; T[2] = r
        S[0] = a; S[1] = b
        P = np.empty((3, 2)); Q = np.empty((2, 2))
        _project(T, axis, P)
        _project(S, axis, Q)
        return _polys2d_overlap(P, 3, Q, 2)
    s1 = plane_side(a, b, p, q)
    s2 = plane_side(a, b, q, r)
    s3 = plane_side(a, b, r, p)
    return (s1 >= 0.0 and s2 >= 0.0 and s3 >= 0.0) or (s1 <= 0.0 and s2 <= 0.0 and s3 <= 0.0)


@njit(cache=True)
def _mesh_pair_intersects(x, tri, i, j):
    """Intersection test of mesh triangles i and j by shared vertices (see
    the module docstring)."""
    shared = 0
    si = -1
    sj = -1
    for a in range(3):
        for b in range(3):
            if tri[i, a] == tri[j, b]:
                shared += 1
                si = a
                sj = b
    if shared == 0:
        return tri_tri_intersect(x[tri[i, 0]], x[tri[i, 1]], x[tri[i, 2]],
                                 x[tri[j, 0]], x[tri[j, 1]], x[tri[j, 2]])
    if shared == 1:
        a = tri[i, (si + 1) % 3]
        b = tri[i, (si + 2) % 3]
        c = tri[j, (sj + 1) % 3]
        d = tri[j, (sj + 2) % 3]
        if segment_triangle_intersect(x[a], x[b], x[tri[j, 0]], x[tri[j, 1]], x[tri[j, 2]]):
            return True
        return segment_triangle_intersect(x[c], x[d], x[tri[i, 0]], x[tri[i, 1]], x[tri[i, 2]])
    return False


@njit(cache=True)
def _flag_pairs(x, tri, pairs, flags):
    for k in range(pairs.shape[0]):
        flags[k] = _mesh_pair_intersects(x, tri, pairs[k, 0], pairs[k, 1])


def self_intersecting_pairs(x, tri, candidate_pairs=None) -> np.ndarray:
    """Intersecting triangle pairs (i < j) of the mesh, sorted (n, 2).
    Candidates default to the box-overlapping pairs of a BVH at x."""
    x = np.ascontiguousarray(x, dtype=np.float64)
    tri = np.ascontiguousarray(tri, dtype=np.int64)
    if candidate_pairs is None:
        pairs = self_pairs(build_bvh(tri, x))
    else:
        pairs = unique_rows(np.sort(np.asarray(candidate_pairs, dtype=np.int64).reshape(-1, 2), axis=1))
        pairs = pairs[pairs[:, 0] != pairs[:, 1]]
    pairs = np.ascontiguousarray(pairs)
    flags = np.zeros(pairs.shape[0], np.bool_)
    _flag_pairs(x, tri, pairs, flags)
    return pairs[flags]


@njit(cache=True)
def _plane_gap(p, q, r, a, b, c):
    """Largest distance of a, b, c from the plane of pqr (inf if pqr is degenerate)."""
    n = np.cross(q - p, r - p)
    nn = np.sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2])
    if nn == 0.0:
        return np.inf
    return max(abs(np.dot(a - p, n)), abs(np.dot(b - p, n)), abs(np.dot(c - p, n))) / nn


@njit(cache=True)
def tri_tri_intersect_tol(p1, q1, r1, p2, q2, r2, coplanar_tol):
    """``tri_tri_intersect``, except that triangles whose planes coincide to
    within ``coplanar_tol`` times their longest edge (each triangle's
    vertices that close to the other's plane) are decided by the coplanar
    2D overlap test.  Two triangles of a flat cloth lying on a flat body
    are coplanar only to rounding (1e-17 m); exact signs of such offsets
    then decide "touching" configurations in ways that depend on the last
    bit, which is not what a count of *crossings* should see."""
    if coplanar_tol > 0.0:
        L = 0.0
        for u, v in ((p1, q1), (q1, r1), (r1, p1), (p2, q2), (q2, r2), (r2, p2)):
            L = max(L, np.sqrt(np.sum((u - v) ** 2)))
        tol = coplanar_tol * L
        if _plane_gap(p2, q2, r2, p1, q1, r1) <= tol and _plane_gap(p1, q1, r1, p2, q2, r2) <= tol:
            return _coplanar_tri_tri(p1, q1, r1, p2, q2, r2)
    return tri_tri_intersect(p1, q1, r1, p2, q2, r2)


@njit(cache=True)
def _tri_tri_batch(P, Q, coplanar_tol, out):
    for k in range(P.shape[0]):
        out[k] = tri_tri_intersect_tol(P[k, 0], P[k, 1], P[k, 2], Q[k, 0], Q[k, 1], Q[k, 2],
                                       coplanar_tol)


# relative plane coincidence under which the crossing counts of the simulator
# and its tests judge a pair as coplanar (1e-9 of an edge: 1e-11 m on a 1 cm
# mesh, far below any cloth thickness, far above rounding)
CROSSING_COPLANAR_TOL = 1e-9


def tri_tri_batch(P, Q, coplanar_tol: float = 0.0) -> np.ndarray:
    """Row-wise intersection of triangles P, Q (n, 3, 3) -> bool (n,):
    ``tri_tri_intersect``, or ``tri_tri_intersect_tol`` with coplanar_tol > 0."""
    P = np.ascontiguousarray(P, dtype=np.float64).reshape(-1, 3, 3)
    Q = np.ascontiguousarray(Q, dtype=np.float64).reshape(-1, 3, 3)
    out = np.zeros(P.shape[0], np.bool_)
    _tri_tri_batch(P, Q, float(coplanar_tol), out)
    return out
