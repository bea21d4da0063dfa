"""Start-state checks of a garment: vertices inside the body, garment
triangles crossing body triangles, garment triangles crossing each other.

Array in, array out; the run decides what to do with a report (``describe``
gives the one-line message).  Lengths are in metres.

Inside test
-----------
The generalized winding number (Jacobson et al. 2013) of a point p with
respect to a triangle soup: the solid angle the soup subtends at p over 4 pi,
1 inside and 0 outside a closed outward oriented mesh, 2 where two closed
parts overlap (self-intersecting bodies: the lips and armpits of a scanned
body), and a smooth value between for a mesh with holes; inside is w > 0.5.

For a closed mesh (every edge used as often in one direction as in the
other: an integral 2-cycle) w is an integer and equals the signed number of
times a ray from p crosses the surface (+1 leaving through the outward side,
-1 entering), so it is computed exactly by ray casting through the AABB tree
of :mod:`distcloth.collision.bvh`.  A mesh with holes is first closed by a
*cap*: one triangle from every unmatched edge to an apex (the mean of the
boundary vertices), which makes the soup plus cap a 2-cycle.  Then
w(mesh) = crossings(mesh + cap) - (solid angle of the cap)/4 pi, the cap's
solid angle summed triangle by triangle (Van Oosterom & Strackee 1983): the
exact generalized winding number at the cost of a ray plus a loop over the
(few) cap triangles.

Robustness: a ray crossing decision is five orientation signs (the segment's
ends against the triangle's plane, the segment's line against the three
edges), each a 3x3 determinant of input differences with Shewchuk's static
error bound (Shewchuk 1997): a sign is used only when certified, so the
crossing count of a ray is exact or the ray is known to be ambiguous (it
grazes an edge or a vertex within rounding); then the next of a few fixed
generic directions is tried.  A point for which every ray is ambiguous lies
on the surface (within rounding) and counts as inside: the body is a closed
set, as triangles are for the crossing tests.

Distances: the unsigned closest-point distance of
:class:`distcloth.collision.mesh_query.MeshProximity`; only the sign is
independent of the simulator's contact query (its pseudo-normal sign is not
used), which is what makes ``signed_distance_to_closed_mesh`` a check of the
simulator rather than a copy of it.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numba import njit

from ..collision.bvh import build_bvh
from ..collision.colliders import MeshCollider
from ..collision.mesh_query import MeshProximity
from ..collision.traverse import cross_pairs, self_pairs
from ..collision.tritri import CROSSING_COPLANAR_TOL, plane_side, tri_tri_batch

__all__ = ["BodyIntersections", "ClosedMesh", "StartReport", "body_intersections",
           "boundary_edges", "check_start", "describe", "inside_closed_mesh",
           "self_intersections", "signed_distance_to_closed_mesh", "winding_number"]

# generic ray directions in the frame (u, v, w) of the mesh box, w its
# thinnest axis (shortest rays, fewest boxes): near +-w with irrational-ish
# tilts so that no lattice-aligned vertex or edge lies on them
_DIRECTIONS = np.array([[0.0173, 0.0297, 1.0], [-0.0311, 0.0127, -1.0],
                        [0.4219, -0.2335, 1.0], [-0.3371, -0.5113, -1.0],
                        [1.0, 0.1903, 0.0571], [0.1457, -1.0, -0.2683]])


# ------------------------------------------------------------------ mesh topology

def _directed_edge_balance(triangles: np.ndarray):
    """(edges (k, 2) with edges[:, 0] < edges[:, 1], net (k,)): every distinct
    edge and how many more times the mesh runs it low -> high than high -> low."""
    a = triangles.reshape(-1)
    b = triangles[:, [1, 2, 0]].reshape(-1)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    n = int(hi.max()) + 1
    # scalar keys: np.unique(axis=0) on rows is several times slower
    key, inv = np.unique(lo * n + hi, return_inverse=True)
    net = np.bincount(inv.reshape(-1), np.where(a < b, 1, -1), minlength=key.shape[0])
    return np.stack([key // n, key % n], axis=1), np.rint(net).astype(np.int64)


def boundary_edges(triangles) -> np.ndarray:
    """Directed edges (k, 2) the mesh runs once more than their reverse (an
    edge used |net| times unmatched is listed |net| times).  Empty iff the
    mesh is closed and consistently oriented (watertight)."""
    tri = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    if tri.shape[0] == 0:
        return np.empty((0, 2), np.int64)
    edges, net = _directed_edge_balance(tri)
    k = np.flatnonzero(net)
    rows = np.where((net[k] > 0)[:, None], edges[k], edges[k][:, ::-1])
    return np.repeat(rows, np.abs(net[k]), axis=0)


# ------------------------------------------------------------------ kernels

@njit(cache=True)
def _orient(a, b, c, d):
    """((b - a) x (c - a)) . (d - a), or 0 when within Shewchuk's error bound
    (the sign is then not certified): the triangle oracle's filtered orient3d."""
    return plane_side(b, c, a, d)


@njit(cache=True)
def _opposite(s, t):
    return (s > 0.0 and t < 0.0) or (s < 0.0 and t > 0.0)


@njit(cache=True)
def _segment_crossing(p, q, a, b, c):
    """Signed crossing of segment pq through triangle abc: +1 if q is on the
    side abc's right-hand normal points to, -1 the other way, 0 no crossing,
    2 not certified (an orientation within rounding)."""
    sp = _orient(a, b, c, p)
    sq = _orient(a, b, c, q)
    if (sp > 0.0 and sq > 0.0) or (sp < 0.0 and sq < 0.0):
        return 0
    e0 = _orient(p, q, a, b)
    e1 = _orient(p, q, b, c)
    e2 = _orient(p, q, c, a)
    if _opposite(e0, e1) or _opposite(e1, e2) or _opposite(e2, e0):
        return 0
    if sp == 0.0 or sq == 0.0 or e0 == 0.0 or e1 == 0.0 or e2 == 0.0:
        return 2
    return 1 if sq > 0.0 else -1


@njit(cache=True)
def segment_hits_box(p, inv, lo, hi, i):
    """Slab test of the segment p + t d, t in [0, 1] (inv = 1/d, inf for a
    zero component) against box i."""
    t0 = 0.0
    t1 = 1.0
    for a in range(3):
        if np.isinf(inv[a]):
            if p[a] < lo[i, a] or p[a] > hi[i, a]:
                return False
            continue
        ta = (lo[i, a] - p[a]) * inv[a]
        tb = (hi[i, a] - p[a]) * inv[a]
        if ta > tb:
            ta, tb = tb, ta
        t0 = max(t0, ta)
        t1 = min(t1, tb)
        if t0 > t1:
            return False
    return True


@njit(cache=True)
def _ray_count(p, q, x, tri, lo, hi, left, right, first, count, order, plo, phi, stack):
    """(signed crossings of segment pq with the mesh, certified?)."""
    d = q - p
    inv = np.empty(3)
    for a in range(3):
        inv[a] = 1.0 / d[a] if d[a] != 0.0 else np.inf
    total = 0
    top = 1
    stack[0] = 0
    while top > 0:
        top -= 1
        node = stack[top]
        if not segment_hits_box(p, inv, lo, hi, node):
            continue
        l = left[node]
        if l >= 0:
            stack[top] = l
            stack[top + 1] = right[node]
            top += 2
            continue
        for j in range(first[node], first[node] + count[node]):
            f = order[j]
            if not segment_hits_box(p, inv, plo, phi, f):
                continue
            s = _segment_crossing(p, q, x[tri[f, 0]], x[tri[f, 1]], x[tri[f, 2]])
            if s == 2:
                return 0, False
            total += s
    return total, True


@njit(cache=True)
def _crossings_kernel(pts, dirs, center, radius, x, tri, lo, hi, left, right, first, count,
                      order, plo, phi, out, certain):
    """Signed crossing count of a ray from every point, out of the mesh box
    (the first certified direction; if none, certain[i] = False)."""
    stack = np.empty(left.shape[0] + 1, np.int64)
    q = np.empty(3)
    for i in range(pts.shape[0]):
        p = pts[i]
        # the segment must end outside the box (winding number 0 there)
        r = radius + np.sqrt(np.sum((p - center) ** 2))
        out[i] = 0
        certain[i] = False
        if left.shape[0] == 0:
            certain[i] = True
            continue
        for k in range(dirs.shape[0]):
            for a in range(3):
                q[a] = p[a] + r * dirs[k, a]
            c, ok = _ray_count(p, q, x, tri, lo, hi, left, right, first, count, order,
                               plo, phi, stack)
            if ok:
                out[i] = c
                certain[i] = True
                break


@njit(cache=True)
def _solid_angle_kernel(pts, x, tri, out):
    """Sum over triangles of the solid angle at every point / 4 pi (Van
    Oosterom & Strackee 1983), positive for a triangle seen from behind
    its right-hand normal."""
    for i in range(pts.shape[0]):
        s = 0.0
        for f in range(tri.shape[0]):
            a = x[tri[f, 0]] - pts[i]
            b = x[tri[f, 1]] - pts[i]
            c = x[tri[f, 2]] - pts[i]
            la = np.sqrt(np.sum(a * a))
            lb = np.sqrt(np.sum(b * b))
            lc = np.sqrt(np.sum(c * c))
            det = (a[0] * (b[1] * c[2] - b[2] * c[1]) + a[1] * (b[2] * c[0] - b[0] * c[2])
                   + a[2] * (b[0] * c[1] - b[1] * c[0]))
            den = la * lb * lc + np.sum(a * b) * lc + np.sum(b * c) * la + np.sum(c * a) * lb
            s += 2.0 * np.arctan2(det, den)
        out[i] = s / (4.0 * np.pi)


# ------------------------------------------------------------------ prepared mesh

class ClosedMesh:
    """A body mesh prepared for many inside / distance queries: closing cap,
    AABB tree, orientation and closest-point search built once.

    ``closed``: the mesh is watertight and consistently oriented (no cap
    needed, the winding number is an exact integer).  ``orientation``: +1
    for an outward mesh, -1 for an inward one (negative volume), whose
    winding numbers are flipped so that inside is always w ~ 1.
    """

    def __init__(self, vertices, triangles):
        x = np.ascontiguousarray(np.asarray(vertices, dtype=np.float64).reshape(-1, 3))
        tri = np.ascontiguousarray(np.asarray(triangles, dtype=np.int64).reshape(-1, 3))
        if tri.shape[0] == 0:
            raise ValueError("ClosedMesh: the mesh has no triangles")
        self.vertices, self.triangles = x, tri
        self.n_boundary_edges = 0
        cap = np.empty((0, 3), np.int64)
        xs = x
        open_edges = boundary_edges(tri)
        if open_edges.shape[0]:
            self.n_boundary_edges = int(open_edges.shape[0])
            apex = x[np.unique(open_edges)].mean(axis=0)
            xs = np.concatenate([x, apex[None]])
            # edge u -> v unmatched: the cap runs v -> u
            cap = np.column_stack([open_edges[:, 1], open_edges[:, 0],
                                   np.full(open_edges.shape[0], x.shape[0])])
        self.closed = self.n_boundary_edges == 0
        self._xs = xs
        self._cap = np.ascontiguousarray(cap)
        soup = np.ascontiguousarray(np.concatenate([tri, cap]))
        self._soup = soup
        a, b, c = (xs[soup[:, k]] for k in range(3))
        volume = np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0
        self.orientation = -1.0 if volume < 0.0 else 1.0
        box_lo, box_hi = xs.min(axis=0), xs.max(axis=0)
        # pad the boxes so that rounding in the slab test never drops a
        # triangle the segment touches (the crossing signs are certified,
        # the box test is not)
        size = max(float(np.linalg.norm(box_hi - box_lo)), float(np.abs(xs).max()), 1e-300)
        pad = 1e-9 * size
        self._bvh = build_bvh(soup, xs, pad=pad)
        self._center = 0.5 * (box_lo + box_hi)
        # rays end beyond the sphere around the box, where w = 0
        self._radius = 1.01 * (0.5 * float(np.linalg.norm(box_hi - box_lo)) + pad)
        thin = np.argsort(box_hi - box_lo)           # thinnest axis first
        frame = np.eye(3)[[thin[1], thin[2], thin[0]]]   # rows u, v, w
        dirs = _DIRECTIONS @ frame
        self._dirs = np.ascontiguousarray(dirs / np.linalg.norm(dirs, axis=1)[:, None])
        self._proximity = None

    @property
    def directions(self) -> np.ndarray:
        """Unit ray directions (k, 3), tried in this order until one is certified."""
        return self._dirs.copy()

    def winding_number(self, points) -> np.ndarray:
        """Generalized winding number (n,) of every point (module docstring);
        points on the surface (within rounding) get 1."""
        pts = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 3))
        n = pts.shape[0]
        count = np.empty(n, np.int64)
        certain = np.empty(n, np.bool_)
        b = self._bvh
        _crossings_kernel(pts, self._dirs, self._center, self._radius, self._xs, self._soup,
                          b.lo, b.hi, b.left, b.right, b.first, b.count, b.order, b.plo,
                          b.phi, count, certain)
        w = count.astype(np.float64)
        if self._cap.shape[0]:
            cap_w = np.empty(n)
            _solid_angle_kernel(pts, self._xs, self._cap, cap_w)
            w -= cap_w
        w *= self.orientation
        w[~certain] = 1.0
        return w

    def inside(self, points) -> np.ndarray:
        """Bool (n,): winding number above 1/2 (Jacobson et al. 2013)."""
        return self.winding_number(points) > 0.5

    def distance(self, points, max_distance: float = np.inf) -> np.ndarray:
        """Unsigned closest-point distance (n,), inf beyond max_distance."""
        if self._proximity is None:
            self._proximity = MeshProximity(MeshCollider.static(self.vertices, self.triangles))
        return self._proximity.closest(points, max_distance=max_distance)[2]

    def signed_distance(self, points) -> np.ndarray:
        """Closest-point distance, negative inside (sign from ``inside``)."""
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        return np.where(self.inside(pts), -1.0, 1.0) * self.distance(pts)


def winding_number(points, vertices, triangles) -> np.ndarray:
    """Generalized winding number of every point (see ``ClosedMesh``)."""
    return ClosedMesh(vertices, triangles).winding_number(points)


def inside_closed_mesh(points, vertices, triangles) -> np.ndarray:
    """Bool (n,): the points inside the mesh (winding number > 1/2; a mesh
    with small holes is handled, points on the surface count as inside)."""
    return ClosedMesh(vertices, triangles).inside(points)


def signed_distance_to_closed_mesh(points, vertices, triangles) -> np.ndarray:
    """Distance (n,) to the mesh surface, negative inside."""
    return ClosedMesh(vertices, triangles).signed_distance(points)


# ------------------------------------------------------------------ garment checks

@dataclass(frozen=True)
class BodyIntersections:
    """Garment against body.  ``vertices``: garment vertices inside the body
    or within ``clearance`` of its surface (ascending ids); ``depth``: their
    depth below the surface (negative: outside, within the clearance);
    ``triangle_pairs`` (k, 2): (garment triangle, body triangle) pairs that
    intersect (closed sets: touching counts)."""
    vertices: np.ndarray
    depth: np.ndarray
    triangle_pairs: np.ndarray
    clearance: float = 0.0

    @property
    def ok(self) -> bool:
        return self.vertices.shape[0] == 0 and self.triangle_pairs.shape[0] == 0


def body_intersections(positions, triangles, body_vertices, body_triangles,
                       clearance: float = 0.0) -> BodyIntersections:
    """Garment vertices inside the body (or within ``clearance`` of it) and
    garment triangles crossing body triangles.  ``body_vertices`` may also
    be a prepared ``ClosedMesh`` (then ``body_triangles`` is ignored)."""
    body = (body_vertices if isinstance(body_vertices, ClosedMesh)
            else ClosedMesh(body_vertices, body_triangles))
    x = np.ascontiguousarray(np.asarray(positions, dtype=np.float64).reshape(-1, 3))
    tri = np.ascontiguousarray(np.asarray(triangles, dtype=np.int64).reshape(-1, 3))
    inside = body.inside(x)
    depth = np.full(x.shape[0], -np.inf)
    depth[inside] = body.distance(x[inside])
    if clearance > 0.0:
        out = np.flatnonzero(~inside)
        depth[out] = -body.distance(x[out], max_distance=clearance)
    flagged = np.flatnonzero(inside | (depth >= -clearance))
    return BodyIntersections(flagged, depth[flagged],
                             _garment_body_pairs(x, tri, body), float(clearance))


def _garment_body_pairs(x, tri, body: ClosedMesh) -> np.ndarray:
    """(garment, body) triangle pairs that intersect: box-overlap candidates
    of the two AABB trees, then Guigue-Devillers."""
    if tri.shape[0] == 0:
        return np.empty((0, 2), np.int64)
    pairs = cross_pairs(build_bvh(tri, x), build_bvh(body.triangles, body.vertices))
    P = x[tri[pairs[:, 0]]]
    Q = body.vertices[body.triangles[pairs[:, 1]]]
    return np.ascontiguousarray(pairs[tri_tri_batch(P, Q, CROSSING_COPLANAR_TOL)])


def self_intersections(positions, triangles, same=None) -> np.ndarray:
    """Garment triangle pairs (k, 2), i < j, sorted, that intersect.  Pairs
    sharing a vertex are not tested (they always touch), as in the
    simulator's crossing count; ``same`` (n,) maps every vertex to a
    canonical id, and vertices with one id count as shared (seam vertices
    of unsewn panels that will be welded)."""
    x = np.ascontiguousarray(np.asarray(positions, dtype=np.float64).reshape(-1, 3))
    tri = np.ascontiguousarray(np.asarray(triangles, dtype=np.int64).reshape(-1, 3))
    if tri.shape[0] < 2:
        return np.empty((0, 2), np.int64)
    pairs = self_pairs(build_bvh(tri, x))
    ids = tri if same is None else np.asarray(same, dtype=np.int64)[tri]
    a, b = ids[pairs[:, 0]], ids[pairs[:, 1]]
    pairs = pairs[~(a[:, :, None] == b[:, None, :]).any(axis=(1, 2))]
    hit = tri_tri_batch(x[tri[pairs[:, 0]]], x[tri[pairs[:, 1]]], CROSSING_COPLANAR_TOL)
    return np.ascontiguousarray(pairs[hit])


@dataclass(frozen=True)
class StartReport:
    """Both checks of a start state; ``body`` is None without a body."""
    body: BodyIntersections | None
    self_pairs: np.ndarray = field(default_factory=lambda: np.empty((0, 2), np.int64))

    @property
    def ok(self) -> bool:
        return (self.body is None or self.body.ok) and self.self_pairs.shape[0] == 0


def check_start(positions, triangles, body_vertices=None, body_triangles=None,
                clearance: float = 0.0, same=None) -> StartReport:
    """``body_intersections`` (if a body is given) and ``self_intersections``."""
    body = None
    if body_vertices is not None:
        body = body_intersections(positions, triangles, body_vertices, body_triangles, clearance)
    return StartReport(body, self_intersections(positions, triangles, same))


# ------------------------------------------------------------------ message

def _ids(values, limit: int) -> str:
    shown = ", ".join(str(int(v)) for v in values[:limit])
    return shown + (", ..." if len(values) > limit else "")


def _pairs_text(pairs, limit: int, a: str, b: str) -> str:
    shown = ", ".join(f"{a}{int(i)} & {b}{int(j)}" for i, j in pairs[:limit])
    return shown + (", ..." if len(pairs) > limit else "")


def _count(n: int, one: str, many: str) -> str:
    return f"{n} {one if n == 1 else many}"


def _body_parts(r: BodyIntersections, limit: int) -> list[str]:
    parts = []
    n = r.vertices.shape[0]
    if n:
        where = ("inside the body" if r.clearance <= 0.0
                 else f"inside the body or within {1e3 * r.clearance:.1f} mm of it")
        by_depth = r.vertices[np.argsort(-r.depth, kind="stable")]
        parts.append(f"{_count(n, 'garment vertex', 'garment vertices')} {where} "
                     f"(deepest {1e3 * r.depth.max():.1f} mm: vertices {_ids(by_depth, limit)})")
    k = r.triangle_pairs.shape[0]
    if k:
        parts.append(f"{_count(k, 'garment/body triangle pair', 'garment/body triangle pairs')} "
                     f"crossing ({_pairs_text(r.triangle_pairs, limit, 'garment ', 'body ')})")
    return parts


def describe(report, limit: int = 5) -> str:
    """One line: counts and the first ``limit`` offending elements (vertices
    deepest first) of a ``StartReport``, a ``BodyIntersections`` or the
    pairs of ``self_intersections``."""
    if isinstance(report, BodyIntersections):
        report = StartReport(report)
    elif not isinstance(report, StartReport):
        report = StartReport(None, np.asarray(report, dtype=np.int64).reshape(-1, 2))
    parts = _body_parts(report.body, limit) if report.body is not None else []
    k = report.self_pairs.shape[0]
    if k:
        parts.append(f"{_count(k, 'triangle pair', 'triangle pairs')} crossing each other "
                     f"(triangles {_pairs_text(report.self_pairs, limit, '', '')})")
    if not parts:
        return ("no garment vertex inside the body, no triangle crossing"
                if report.body is not None else "no triangle crossing")
    return parts[0] if len(parts) == 1 else ", ".join(parts[:-1]) + " and " + parts[-1]
