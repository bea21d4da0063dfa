"""Continuous collision detection for linear trajectories x0 -> x1.

EG07 tutorial, Part 1 §2.3: "continuous collision
detection based on BVHs can be used, in which the exact contact points
between two successive time steps are detected" (citing Bridson et al. 2002).
Following Provot 1997 and Bridson et al. 2002 (§4), vertices move linearly
over the step, and a vertex-face or edge-edge pair can only meet when its
four points are coplanar:

    f(t) = ((x1(t) - x0(t)) x (x2(t) - x0(t))) . (x3(t) - x0(t)) = 0,

a cubic in t in [0, 1].  Every root in [0, 1] is a candidate time, checked
in increasing order with a proximity query (distance <= ``eta``); the first
that passes is the hit.

Root finding: the cubic's critical points in (0, 1) cut [0, 1] into
intervals on which f is monotone; an interval whose ends differ in sign
contains exactly one root, found by Newton's method safeguarded by
bisection (the bracket always shrinks, so it converges to rounding level).
Critical points and interval ends where |f| is at rounding level are
candidates too (tangential contacts, double roots, pairs coplanar at the
start).  Lower-degree cases (leading coefficients zero) need no special
case: the derivative's roots are computed with the stable quadratic
formula, which degrades to the linear and constant cases.

Degenerate case: if f vanishes identically (relative to the size of the
configuration: the four points stay coplanar for the whole step, e.g. flat
cloth sliding in its plane) the coplanarity test carries no timing
information; the pair is then sampled at t = 0, 1/8, ..., 1.  This is an
approximation; in-plane contacts are caught by the proximity (thickness)
stage, as in Bridson et al.

Results are per candidate: ``t`` is the earliest hit time or +inf,
``weights`` (vertex-face: barycentric (w0, w1, w2) of the contact point on
the triangle; edge-edge: (s, t) on the two edges) and a unit ``normal``
(vertex-face: face normal at the hit, on the side the vertex came from;
edge-edge: a x b at the hit, pointing from edge a towards edge b before the
hit).  Pairs sharing a vertex get t = +inf.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from .proximity import point_triangle, segment_segment

_N_SAMPLES = 9          # sampling of identically-coplanar pairs
_DEGENERATE = 1e-13     # |coefficients| <= this * L^3: f is identically zero
_FTOL = 1e-12           # |f| <= this * sum|coefficients|: a (tangential) root


class CCDResult(NamedTuple):
    t: np.ndarray          # float64 (n,), +inf where no hit
    weights: np.ndarray    # float64 (n, 3) vertex-face, (n, 2) edge-edge
    normal: np.ndarray     # float64 (n, 3)


@njit(cache=True)
def _cross(a0, a1, a2, b0, b1, b2):
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


@njit(cache=True)
def triple_cubic(a, va, b, vb, c, vc):
    """Coefficients (k0, k1, k2, k3) of ((a + t va) x (b + t vb)) . (c + t vc)."""
    x0, x1, x2 = _cross(a[0], a[1], a[2], b[0], b[1], b[2])
    y0, y1, y2 = _cross(a[0], a[1], a[2], vb[0], vb[1], vb[2])
    z0, z1, z2 = _cross(va[0], va[1], va[2], b[0], b[1], b[2])
    y0 += z0; y1 += z1; y2 += z2
    w0, w1, w2 = _cross(va[0], va[1], va[2], vb[0], vb[1], vb[2])
    k0 = x0 * c[0] + x1 * c[1] + x2 * c[2]
    k1 = x0 * vc[0] + x1 * vc[1] + x2 * vc[2] + y0 * c[0] + y1 * c[1] + y2 * c[2]
    k2 = y0 * vc[0] + y1 * vc[1] + y2 * vc[2] + w0 * c[0] + w1 * c[1] + w2 * c[2]
    k3 = w0 * vc[0] + w1 * vc[1] + w2 * vc[2]
    return k0, k1, k2, k3


@njit(cache=True)
def _f(k0, k1, k2, k3, t):
    return ((k3 * t + k2) * t + k1) * t + k0


@njit(cache=True)
def _df(k1, k2, k3, t):
    return (3.0 * k3 * t + 2.0 * k2) * t + k1


@njit(cache=True)
def _critical_points(k1, k2, k3, out):
    """Roots of f' = 3 k3 t^2 + 2 k2 t + k1 strictly inside (0, 1), sorted;
    returns their number.  The stable form q = -(B + sign(B) sqrt(D)) / 2,
    roots q / A and C / q, stays accurate when A -> 0 (then f' is linear)."""
    A = 3.0 * k3
    B = 2.0 * k2
    C = k1
    n = 0
    r1 = -1.0
    r2 = -1.0
    if A == 0.0:
        if B != 0.0:
            r1 = -C / B
    else:
        disc = B * B - 4.0 * A * C
        if disc >= 0.0:
            sq = np.sqrt(disc)
            q = -0.5 * (B + sq) if B >= 0.0 else -0.5 * (B - sq)
            r1 = q / A
            r2 = C / q if q != 0.0 else r1
    if 0.0 < r1 < 1.0:
        out[n] = r1
        n += 1
    if 0.0 < r2 < 1.0 and r2 != r1:
        out[n] = r2
        n += 1
    if n == 2 and out[1] < out[0]:
        out[0], out[1] = out[1], out[0]
    return n


@njit(cache=True)
def _refine(k0, k1, k2, k3, lo, hi, flo):
    """The root of f in [lo, hi] (f(lo) f(hi) < 0): Newton safeguarded by
    bisection of the bracket."""
    t = 0.5 * (lo + hi)
    for _ in range(200):
        ft = _f(k0, k1, k2, k3, t)
        if ft == 0.0:
            return t
        if (ft > 0.0) == (flo > 0.0):
            lo = t
            flo = ft
        else:
            hi = t
        d = _df(k1, k2, k3, t)
        tn = t - ft / d if d != 0.0 else 0.5 * (lo + hi)
        if not (lo < tn < hi):
            tn = 0.5 * (lo + hi)
        if abs(tn - t) <= 1e-16 or hi - lo <= 1e-16:
            return tn
        t = tn
    return t


@njit(cache=True)
def cubic_roots01(k0, k1, k2, k3, out):
    """Candidate times in [0, 1] of f(t) = k0 + k1 t + k2 t^2 + k3 t^3 = 0,
    sorted ascending into ``out`` (size >= 8); returns their number."""
    crit = np.empty(2)
    nc = _critical_points(k1, k2, k3, crit)
    ftol = _FTOL * (abs(k0) + abs(k1) + abs(k2) + abs(k3))
    pts = np.empty(4)
    pts[0] = 0.0
    for i in range(nc):
        pts[i + 1] = crit[i]
    pts[nc + 1] = 1.0
    n = 0
    for i in range(nc + 2):                     # near-zero ends / critical points
        if abs(_f(k0, k1, k2, k3, pts[i])) <= ftol:
            out[n] = pts[i]
            n += 1
    for i in range(nc + 1):                     # one root per sign change
        lo = pts[i]
        hi = pts[i + 1]
        flo = _f(k0, k1, k2, k3, lo)
        fhi = _f(k0, k1, k2, k3, hi)
        if flo != 0.0 and fhi != 0.0 and (flo > 0.0) != (fhi > 0.0):
            out[n] = _refine(k0, k1, k2, k3, lo, hi, flo)
            n += 1
    for i in range(1, n):                       # insertion sort, n <= 7
        v = out[i]
        j = i - 1
        while j >= 0 and out[j] > v:
            out[j + 1] = out[j]
            j -= 1
        out[j + 1] = v
    return n


@njit(cache=True)
def _lerp(x0, x1, t, out):
    for a in range(3):
        out[a] = x0[a] + t * (x1[a] - x0[a])
    return out


@njit(cache=True)
def _coplanarity(p0, a0, b0, c0, p1, a1, b1, c1):
    """Cubic of the trajectories of (b - a, c - a, p - a) and whether it
    vanishes identically relative to the configuration size L."""
    w = np.empty((6, 3))              # rows: b-a, c-a, p-a at t=0, then their velocities
    L = 0.0
    for k in range(3):
        w[0, k] = b0[k] - a0[k]
        w[1, k] = c0[k] - a0[k]
        w[2, k] = p0[k] - a0[k]
        w[3, k] = (b1[k] - a1[k]) - w[0, k]
        w[4, k] = (c1[k] - a1[k]) - w[1, k]
        w[5, k] = (p1[k] - a1[k]) - w[2, k]
        for r in range(6):
            L = max(L, abs(w[r, k]))
    k0, k1, k2, k3 = triple_cubic(w[0], w[3], w[1], w[4], w[2], w[5])
    kmax = max(abs(k0), abs(k1), abs(k2), abs(k3))
    return k0, k1, k2, k3, kmax <= _DEGENERATE * L * L * L


@njit(cache=True)
def _candidate_times(p0, a0, b0, c0, p1, a1, b1, c1, times):
    k0, k1, k2, k3, degenerate = _coplanarity(p0, a0, b0, c0, p1, a1, b1, c1)
    if degenerate:
        for i in range(_N_SAMPLES):
            times[i] = i / (_N_SAMPLES - 1.0)
        return _N_SAMPLES
    return cubic_roots01(k0, k1, k2, k3, times)


@njit(cache=True)
def _orient(n0, n1, n2, side, approach):
    """Flip n to the side the moving primitive came from: side = n.(d at
    t=0); if that is ~0 use the relative velocity (approach = n.(dv), which
    is negative when approaching from the +n side)."""
    if side < 0.0 or (side == 0.0 and approach > 0.0):
        return -n0, -n1, -n2
    return n0, n1, n2


@njit(cache=True)
def vf_ccd(p0, a0, b0, c0, p1, a1, b1, c1, eta):
    """Vertex p against triangle abc moving linearly from *0 to *1.
    Returns (t, w0, w1, w2, n0, n1, n2); t = inf if no contact."""
    times = np.empty(max(8, _N_SAMPLES))
    nt = _candidate_times(p0, a0, b0, c0, p1, a1, b1, c1, times)
    if nt == 0:
        return np.inf, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    p = np.empty(3); a = np.empty(3); b = np.empty(3); c = np.empty(3)
    for i in range(nt):
        t = times[i]
        d, w0, w1, w2, m0, m1, m2 = point_triangle(_lerp(p0, p1, t, p), _lerp(a0, a1, t, a),
                                                   _lerp(b0, b1, t, b), _lerp(c0, c1, t, c))
        if d <= eta:
            ab = b - a
            ac = c - a
            f0, f1, f2 = _cross(ab[0], ab[1], ab[2], ac[0], ac[1], ac[2])
            fn = np.sqrt(f0 * f0 + f1 * f1 + f2 * f2)
            if fn > 0.0:
                m0 = f0 / fn; m1 = f1 / fn; m2 = f2 / fn
            side = 0.0
            approach = 0.0
            for k in range(3):
                q0 = w0 * a0[k] + w1 * b0[k] + w2 * c0[k]
                q1 = w0 * a1[k] + w1 * b1[k] + w2 * c1[k]
                nk = m0 if k == 0 else (m1 if k == 1 else m2)
                side += nk * (p0[k] - q0)
                approach += nk * ((p1[k] - p0[k]) - (q1 - q0))
            m0, m1, m2 = _orient(m0, m1, m2, side, approach)
            return t, w0, w1, w2, m0, m1, m2
    return np.inf, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0


@njit(cache=True)
def ee_ccd(a0, b0, c0, d0, a1, b1, c1, d1, eta):
    """Edge ab against edge cd moving linearly from *0 to *1.  The
    coplanarity cubic is that of (b - a, d - c, c - a).
    Returns (t, s, u, n0, n1, n2): contact points a + s (b - a) and
    c + u (d - c) at time t; t = inf if no contact."""
    times = np.empty(max(8, _N_SAMPLES))
    # coplanar(b - a, d - c, c - a) == coplanar of points a, b, e = a + (d - c), c
    e = np.empty((2, 3))
    for k in range(3):
        e[0, k] = a0[k] + (d0[k] - c0[k])
        e[1, k] = a1[k] + (d1[k] - c1[k])
    nt = _candidate_times(c0, a0, b0, e[0], c1, a1, b1, e[1], times)
    if nt == 0:
        return np.inf, 0.0, 0.0, 0.0, 0.0, 0.0
    a = np.empty(3); b = np.empty(3); c = np.empty(3); d = np.empty(3)
    for i in range(nt):
        t = times[i]
        dist, s, u, m0, m1, m2 = segment_segment(_lerp(a0, a1, t, a), _lerp(b0, b1, t, b),
                                                 _lerp(c0, c1, t, c), _lerp(d0, d1, t, d))
        if dist <= eta:
            ab = b - a
            cd = d - c
            f0, f1, f2 = _cross(ab[0], ab[1], ab[2], cd[0], cd[1], cd[2])
            fn = np.sqrt(f0 * f0 + f1 * f1 + f2 * f2)
            if fn > 1e-12 * np.sqrt(np.sum(ab * ab) * np.sum(cd * cd)):
                m0 = f0 / fn; m1 = f1 / fn; m2 = f2 / fn
            else:                                   # parallel: direction at the start
                _, _, _, m0, m1, m2 = segment_segment(a0, b0, c0, d0)
            side = 0.0
            approach = 0.0
            for k in range(3):
                pa0 = a0[k] + s * (b0[k] - a0[k])
                pb0 = c0[k] + u * (d0[k] - c0[k])
                pa1 = a1[k] + s * (b1[k] - a1[k])
                pb1 = c1[k] + u * (d1[k] - c1[k])
                nk = m0 if k == 0 else (m1 if k == 1 else m2)
                side += nk * (pb0 - pa0)
                approach += nk * ((pb1 - pb0) - (pa1 - pa0))
            m0, m1, m2 = _orient(m0, m1, m2, side, approach)
            return t, s, u, m0, m1, m2
    return np.inf, 0.0, 0.0, 0.0, 0.0, 0.0


@njit(cache=True)
def _apart(x0, x1, p, q, r, u, v, w, eta):
    """Whether the boxes of the swept vertices {p, q, r} and {u, v, w} (over
    x0 -> x1) are more than eta apart along some axis: then the primitives
    never come within eta during the step and the pair cannot hit (exact).
    Candidates come from boxes padded by the thickness, so most resting
    pairs of a pile-up end here, before any allocation or cubic."""
    for k in range(3):
        lo1 = min(x0[p, k], x1[p, k], x0[q, k], x1[q, k], x0[r, k], x1[r, k])
        hi1 = max(x0[p, k], x1[p, k], x0[q, k], x1[q, k], x0[r, k], x1[r, k])
        lo2 = min(x0[u, k], x1[u, k], x0[v, k], x1[v, k], x0[w, k], x1[w, k])
        hi2 = max(x0[u, k], x1[u, k], x0[v, k], x1[v, k], x0[w, k], x1[w, k])
        if lo1 > hi2 + eta or lo2 > hi1 + eta:
            return True
    return False


@njit(cache=True)
def _vf_batch(x0, x1, tri, pairs, eta, t, w, nrm):
    for k in range(pairs.shape[0]):
        v = pairs[k, 0]
        f = pairs[k, 1]
        i0 = tri[f, 0]; i1 = tri[f, 1]; i2 = tri[f, 2]
        t[k] = np.inf
        if v == i0 or v == i1 or v == i2:
            continue
        if _apart(x0, x1, v, v, v, i0, i1, i2, eta):
            continue
        r = vf_ccd(x0[v], x0[i0], x0[i1], x0[i2], x1[v], x1[i0], x1[i1], x1[i2], eta)
        t[k] = r[0]
        w[k, 0] = r[1]; w[k, 1] = r[2]; w[k, 2] = r[3]
        nrm[k, 0] = r[4]; nrm[k, 1] = r[5]; nrm[k, 2] = r[6]


@njit(cache=True)
def _ee_batch(x0, x1, edges, pairs, eta, t, st, nrm):
    for k in range(pairs.shape[0]):
        ea = pairs[k, 0]
        eb = pairs[k, 1]
        a = edges[ea, 0]; b = edges[ea, 1]; c = edges[eb, 0]; d = edges[eb, 1]
        t[k] = np.inf
        if ea == eb or a == c or a == d or b == c or b == d:
            continue
        if _apart(x0, x1, a, b, b, c, d, d, eta):
            continue
        r = ee_ccd(x0[a], x0[b], x0[c], x0[d], x1[a], x1[b], x1[c], x1[d], eta)
        t[k] = r[0]
        st[k, 0] = r[1]; st[k, 1] = r[2]
        nrm[k, 0] = r[3]; nrm[k, 1] = r[4]; nrm[k, 2] = r[5]


def _prep(x0, x1, prims, pairs):
    return (np.ascontiguousarray(x0, dtype=np.float64), np.ascontiguousarray(x1, dtype=np.float64),
            np.ascontiguousarray(prims, dtype=np.int64),
            np.ascontiguousarray(np.asarray(pairs, dtype=np.int64).reshape(-1, 2)))


def vertex_face_ccd(x0, x1, tri, pairs, eta: float = 1e-9) -> CCDResult:
    """Earliest contact of every candidate (vertex, face) row of ``pairs``
    over the step x0 -> x1 (rows in the input order)."""
    x0, x1, tri, pairs = _prep(x0, x1, tri, pairs)
    n = pairs.shape[0]
    t = np.empty(n); w = np.zeros((n, 3)); nrm = np.zeros((n, 3))
    _vf_batch(x0, x1, tri, pairs, float(eta), t, w, nrm)
    return CCDResult(t, w, nrm)


def edge_edge_ccd(x0, x1, edges, pairs, eta: float = 1e-9) -> CCDResult:
    """Earliest contact of every candidate (edge a, edge b) row of ``pairs``
    over the step x0 -> x1 (rows in the input order; weights are (s, t))."""
    x0, x1, edges, pairs = _prep(x0, x1, edges, pairs)
    n = pairs.shape[0]
    t = np.empty(n); st = np.zeros((n, 2)); nrm = np.zeros((n, 3))
    _ee_batch(x0, x1, edges, pairs, float(eta), t, st, nrm)
    return CCDResult(t, st, nrm)
