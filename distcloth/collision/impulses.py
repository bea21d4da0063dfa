"""Bridson-style collision response on arrays: self-collision and kinematic colliders.

EG07 tutorial, Part 1 §2.3: the response of Bridson, Fedkiw and Anderson
(Bridson et al. 2002) applies "a stopping impulse to approaching
triangles (i.e. adjusts their nodal velocities) whenever their distance
falls below a certain threshold", CCD catches the fast ones, and a fail-safe
is needed because "even with such robust approaches there can be situations
in which intersections cannot be prevented".  This module is that pipeline
(Bridson et al. 2002 §3 overview): proximity repulsion at x0 (§7.2, friction §7.3), CCD
impulse iterations (§6 detection, §7.1 impulses), rigid impact zones
(§7.4, after Provot 1997).  Pure arrays, no MPI.

Index space and state
---------------------
One combined vertex set: cloth vertices plus kinematic vertices (collider
mesh vertices, pins) with ``inv_mass == 0``.  ``x0 (n, 3)`` start positions,
``u (n, 3)`` the step's average velocity (end positions x1 = x0 + h u),
``tri (m, 3)`` and ``edges (e, 2)`` (``mesh_edges``) over that index space.
Kinematic rows of u are never changed.

Pair stencil
------------
Every vertex-face or edge-edge pair is four vertex ids ``ids`` and
coefficients ``c`` with sum 0 such that ``d = sum_j c_j x_j`` is the vector
between the two closest (or hit) points, oriented along the pair normal n:
vertex-face (v; f0 f1 f2): c = (1, -w0, -w1, -w2), n face -> vertex;
edge-edge (a0 a1; b0 b1):  c = (-(1-s), -s, 1-t, t), n edge a -> edge b
(the conventions of proximity.py and ccd.py).  The relative normal velocity
is vn = n . sum_j c_j u_j.  An impulse P changes u_j by c_j inv_m_j P, hence
the relative velocity by S P with S = sum_j c_j^2 inv_m_j: the Bridson et al. 2002 §7.1
"I / (1 + sum w^2)" distribution written with inverse masses (kinematic
vertices simply drop out of S).  Since sum_j c_j = 0, every pair impulse
conserves linear momentum when all its vertices are free.

Jacobi accumulation
-------------------
All pairs of a pass are computed from the same input u; each active pair's
impulse is scaled by 1 / (largest number of active pairs sharing one of its
free vertices), then summed per vertex in canonical pair order.  The per-pair
(not per-vertex) scaling keeps momentum conservation exact and stops several
contacts on one vertex from over-correcting; what it under-corrects, the
next pass / CCD iteration picks up.  Candidate rows are canonicalised
(sorted, de-duplicated) first, so the result is independent of their order
and bitwise reproducible.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .ccd import edge_edge_ccd, vertex_face_ccd
from .friction import coulomb_fraction
from .proximity import edge_edge_contacts, vertex_face_contacts
from .traverse import unique_rows

_S_MIN = 1e-12        # S <= this * max inv_mass of the pair: contact point ~kinematic, left to zones
_PINV_RCOND = 1e-12   # relative cut-off for singular zone inertias / affine fits


# ------------------------------------------------------------------ candidates

def clean_pairs(vf, ee, tri, edges, inv_mass, same=None):
    """Canonical candidate rows: vf sorted unique, ee as (ea < eb) sorted
    unique; rows whose primitives share a vertex or whose vertices are all
    kinematic are dropped (Bridson et al. 2002: adjacent primitives touch by construction;
    collider-collider pairs need no response).  ``same`` (n,): the vertex each
    vertex will be welded into (stitched panels being sewn): vertices with the
    same one count as shared, so a seam may close."""
    vf = unique_rows(np.asarray(vf, dtype=np.int64).reshape(-1, 2))
    ee = unique_rows(np.sort(np.asarray(ee, dtype=np.int64).reshape(-1, 2), axis=1))
    kin = np.asarray(inv_mass) == 0
    f = tri[vf[:, 1]]
    a, b = edges[ee[:, 0]], edges[ee[:, 1]]
    if same is not None:
        vf_id, f_id, a_id, b_id = same[vf[:, :1]], same[f], same[a], same[b]
    else:
        vf_id, f_id, a_id, b_id = vf[:, :1], f, a, b
    keep = np.all(f_id != vf_id, axis=1) & ~(kin[vf[:, 0]] & np.all(kin[f], axis=1))
    keep_e = (np.all(a_id[:, :, None] != b_id[:, None, :], axis=(1, 2))
              & ~(np.all(kin[a], axis=1) & np.all(kin[b], axis=1)))
    return np.ascontiguousarray(vf[keep]), np.ascontiguousarray(ee[keep_e])


# ------------------------------------------------------------------ stencils

def _vf_stencil(tri, vertex, face, weights):
    ids = np.column_stack([vertex, tri[face]]).astype(np.int64)
    coef = np.column_stack([np.ones(len(vertex)), -weights])
    return np.ascontiguousarray(ids), np.ascontiguousarray(coef)


def _ee_stencil(edges, ea, eb, st):
    ids = np.column_stack([edges[ea], edges[eb]]).astype(np.int64)
    s, t = st[:, 0], st[:, 1]
    coef = np.column_stack([-(1.0 - s), -s, 1.0 - t, t])
    return np.ascontiguousarray(ids), np.ascontiguousarray(coef)


def _cat(*parts):
    ids = np.concatenate([p[0] for p in parts]).reshape(-1, 4)
    coef = np.concatenate([p[1] for p in parts]).reshape(-1, 4)
    nrm = np.concatenate([p[2] for p in parts]).reshape(-1, 3)
    return (np.ascontiguousarray(ids, dtype=np.int64), np.ascontiguousarray(coef, dtype=np.float64),
            np.ascontiguousarray(nrm, dtype=np.float64))


# ------------------------------------------------------------------ the Jacobi pass (numba)

@njit(cache=True)
def _jacobi_pass(u, wpair, ids, coef, normal, target, mu, du):
    """One Jacobi pass: pair p wants vn >= target[p]; its impulse is
    P = (dvn n - min(mu dvn, |vt|) vt/|vt|) / S (Bridson et al. 2002 §7.1 distribution,
    §7.3 Coulomb friction on the relative tangential velocity vt), scaled by
    1/max active count over its free vertices, accumulated into du in pair
    order.  ``wpair`` (k, 4): the inverse mass each pair gives its vertices
    (``pair_weights``).  Returns the number of active pairs."""
    k = ids.shape[0]
    n = u.shape[0]
    P = np.zeros((k, 3))
    active = np.zeros(k, np.bool_)
    count = np.zeros(n, np.int64)
    for p in range(k):
        vr0 = 0.0; vr1 = 0.0; vr2 = 0.0
        S = 0.0
        wmax = 0.0
        for j in range(4):
            i = ids[p, j]
            c = coef[p, j]
            vr0 += c * u[i, 0]; vr1 += c * u[i, 1]; vr2 += c * u[i, 2]
            S += c * c * wpair[p, j]
            wmax = max(wmax, wpair[p, j])
        n0 = normal[p, 0]; n1 = normal[p, 1]; n2 = normal[p, 2]
        vn = vr0 * n0 + vr1 * n1 + vr2 * n2
        dvn = target[p] - vn
        if not (dvn > 0.0) or not (S > _S_MIN * wmax) or not np.isfinite(dvn):
            continue
        t0 = vr0 - vn * n0; t1 = vr1 - vn * n1; t2 = vr2 - vn * n2
        vt = np.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
        f = coulomb_fraction(vt, mu * dvn)
        P[p, 0] = (dvn * n0 - f * t0) / S
        P[p, 1] = (dvn * n1 - f * t1) / S
        P[p, 2] = (dvn * n2 - f * t2) / S
        active[p] = True
        for j in range(4):
            if coef[p, j] != 0.0 and wpair[p, j] > 0.0:
                count[ids[p, j]] += 1
    nact = 0
    for p in range(k):
        if not active[p]:
            continue
        nact += 1
        cmax = 1
        for j in range(4):
            i = ids[p, j]
            if coef[p, j] != 0.0 and wpair[p, j] > 0.0:
                cmax = max(cmax, count[i])
        for j in range(4):
            i = ids[p, j]
            w = coef[p, j] * wpair[p, j] / cmax
            if w != 0.0:
                du[i, 0] += w * P[p, 0]
                du[i, 1] += w * P[p, 1]
                du[i, 2] += w * P[p, 2]
    return nact


def pair_weights(inv_mass, ids, priority=None):
    """(k, 4) the inverse mass each pair gives its vertices: their own, or
    with ``priority`` (n,) per vertex, zero for the vertices of a pair below
    its highest priority (while one of the highest stays free).  Layered
    garments give each cloth its layer: a pair between an inner and an outer
    layer moves only the outer one, so the inner layer is an obstacle to the
    outer as the body is to the inner, and the response between layers
    cannot push the inner layer into the body: a stack of layers is
    resolved from the body outwards (docs/garments.md, "Layers")."""
    w = np.ascontiguousarray(inv_mass[ids], dtype=np.float64)
    if priority is None or ids.shape[0] == 0:
        return w
    pr = np.asarray(priority)[ids]
    top = pr == pr.max(axis=1, keepdims=True)
    lowered = np.where(top, w, 0.0)
    free_top = lowered.max(axis=1) > 0.0
    return np.ascontiguousarray(np.where(free_top[:, None], lowered, w))


def _apply(u, inv_mass, ids, coef, normal, target, mu, priority=None):
    du = np.zeros_like(u)
    nact = _jacobi_pass(u, pair_weights(inv_mass, ids, priority), ids, coef, normal,
                        np.ascontiguousarray(target, dtype=np.float64), float(mu), du)
    out = u + du
    kin = inv_mass == 0
    out[kin] = u[kin]                     # bitwise: kinematic rows are prescribed
    return out, nact


def _prep(x0, u, inv_mass, tri, edges):
    return (np.ascontiguousarray(x0, dtype=np.float64), np.array(u, dtype=np.float64, order="C"),
            np.ascontiguousarray(inv_mass, dtype=np.float64),
            np.ascontiguousarray(tri, dtype=np.int64).reshape(-1, 3),
            np.ascontiguousarray(edges, dtype=np.int64).reshape(-1, 2))


def pair_thickness(ids, coef, thickness, keep=None, priority=None):
    """(k,) the distance each pair keeps: ``thickness``, or with ``keep`` (n,)
    per vertex: a vertex-face pair (coef[:, 0] = 1) its vertex's, an
    edge-edge pair the smaller of its vertices' (a primitive belongs wholly
    to the cloth or to one collider).  A cloth vertex over a body face keeps
    the cloth's: the body's distance field holds that vertex at the offset
    anyway; a body vertex or edge under a cloth face or edge keeps the body's.
    With ``priority`` (layers, ``pair_weights``) ``keep`` is what a vertex
    keeps from the primitives of the layers above it, and a pair within one
    layer keeps ``thickness``: a garment's vertex under the face of one worn
    over it keeps its own, as a body vertex does."""
    if keep is None:
        return np.full(ids.shape[0], float(thickness))
    keep = np.asarray(keep)
    if priority is None:
        return np.where(coef[:, 0] > 0.0, keep[ids[:, 0]], np.min(keep[ids], axis=1))
    pr = np.asarray(priority)[ids]
    under = pr[:, 0] < np.min(pr[:, 1:], axis=1)          # a vertex under a face
    vf = np.where(under, keep[ids[:, 0]], thickness)
    a_under = np.max(pr[:, :2], axis=1) < np.min(pr[:, 2:], axis=1)
    b_under = np.max(pr[:, 2:], axis=1) < np.min(pr[:, :2], axis=1)
    ee = np.where(a_under, np.min(keep[ids[:, :2]], axis=1),
                  np.where(b_under, np.min(keep[ids[:, 2:]], axis=1), thickness))
    return np.where(coef[:, 0] > 0.0, vf, ee)


# ------------------------------------------------------------------ 1. proximity repulsion

def repulsion(x0, u, h, inv_mass, tri, edges, vf, ee, thickness, friction=0.0, iterations=4,
              keep=None, priority=None):
    """Proximity response at x0 (Bridson et al. 2002 §7.2, friction §7.3) for the contacts
    ``vf`` / ``ee`` (proximity.py NamedTuples, distance < thickness).

    Each pair gets the normal velocity change dvn = max(0, (thickness - d)/h - vn):
    it removes the approaching relative normal velocity (the inelastic
    impulse) and adds just enough separation to reach the thickness distance
    by the end of the step, never more (the "limited" repulsion of §7.2 with
    the full overlap as target).  Friction reduces the relative tangential
    velocity by at most ``friction * dvn``.  ``iterations`` Jacobi passes
    (pairs already satisfied are inactive).  ``keep`` (n,): per-vertex
    distances that replace ``thickness`` as the target (``resolve``);
    ``priority`` (n,): see ``pair_weights``.  Returns the new u."""
    x0, u, inv_mass, tri, edges = _prep(x0, u, inv_mass, tri, edges)
    ids, coef, nrm = _cat(_vf_stencil(tri, vf.vertex, vf.face, vf.weights) + (vf.normal,),
                          _ee_stencil(edges, ee.edge_a, ee.edge_b, ee.params) + (ee.normal,))
    target = (pair_thickness(ids, coef, thickness, keep, priority)
              - np.concatenate([vf.distance, ee.distance])) / h
    for _ in range(iterations):
        u, nact = _apply(u, inv_mass, ids, coef, nrm, target, friction, priority)
        if nact == 0:
            break
    return u


# ------------------------------------------------------------------ 2. CCD impulses

def collisions(x0, x1, tri, edges, vf_pairs, ee_pairs, eta, with_rows=False):
    """CCD hits (Bridson et al. 2002 §6, ccd.py) of clean candidate rows over x0 -> x1:
    stencils (ids (k, 4), coef (k, 4), normal (k, 3)) of the hitting pairs,
    vertex-face hits first, each block in candidate (canonical) order;
    ``with_rows``: also the indices of the hitting vf and ee rows."""
    r = vertex_face_ccd(x0, x1, tri, vf_pairs, eta)
    q = edge_edge_ccd(x0, x1, edges, ee_pairs, eta)
    a = np.isfinite(r.t)
    b = np.isfinite(q.t)
    out = _cat(_vf_stencil(tri, vf_pairs[a, 0], vf_pairs[a, 1], r.weights[a]) + (r.normal[a],),
               _ee_stencil(edges, ee_pairs[b, 0], ee_pairs[b, 1], q.weights[b]) + (q.normal[b],))
    return out + (np.flatnonzero(a), np.flatnonzero(b)) if with_rows else out


def ccd_impulses(x0, u, h, inv_mass, tri, edges, vf_pairs, ee_pairs, thickness,
                 eta=None, margin=0.01, sweeps=8, hits=collisions, keep=None, priority=None):
    """One detection pass over the CCD hits of the candidates on
    x0 -> x0 + h u, answered with inelastic impulses (Bridson et al. 2002 §7.1).  For a hit with normal n and
    start gap g0 = n . sum c_j x0_j the relative normal velocity is raised to

        vn >= (min(max(g0, 0), thickness) - g0 + margin * thickness) / h,

    i.e. a pair starting farther than ``thickness`` may still approach but
    stops at thickness (+ margin) instead of freezing at its start gap, and a
    closer pair becomes separating by the small margin.  The hits' stencils
    (contact weights and normals at the hit) are kept fixed for up to
    ``sweeps`` Jacobi sweeps (cheap; each sweep only acts on the hits whose
    target is still unmet), so clustered hits need fewer re-detections.
    Candidate rows must be clean (``clean_pairs``).  ``hits``: the CCD
    narrow phase, ``collisions`` or a drop-in that shares the rows out over
    ranks and returns the same stencils in the same order.
    Returns (u_new, number of hits)."""
    x0, u, inv_mass, tri, edges = _prep(x0, u, inv_mass, tri, edges)
    eta = 1e-3 * thickness if eta is None else eta
    ids, coef, nrm = hits(x0, x0 + h * u, tri, edges, vf_pairs, ee_pairs, eta)
    if ids.shape[0] == 0:
        return u, 0
    g0 = np.einsum("kd,kd->k", np.einsum("kj,kjd->kd", coef, x0[ids]), nrm)
    th = pair_thickness(ids, coef, thickness, keep, priority)
    target = (np.clip(g0, 0.0, th) - g0 + margin * th) / h
    for _ in range(sweeps):
        u, nact = _apply(u, inv_mass, ids, coef, nrm, target, 0.0, priority)
        if nact == 0:
            break
    return u, int(ids.shape[0])


# ------------------------------------------------------------------ 3. rigid impact zones

@njit(cache=True)
def _find(parent, i):
    while parent[i] != i:
        parent[i] = parent[parent[i]]
        i = parent[i]
    return i


@njit(cache=True)
def _union_rows(parent, ids):
    """Merge the vertices of every row into one set; the root is the smallest
    vertex id (deterministic)."""
    for p in range(ids.shape[0]):
        for j in range(1, ids.shape[1]):
            a = _find(parent, ids[p, 0])
            b = _find(parent, ids[p, j])
            if a < b:
                parent[b] = a
            elif b < a:
                parent[a] = b


@njit(cache=True)
def _roots(parent, idx):
    out = np.empty(idx.shape[0], np.int64)
    for k in range(idx.shape[0]):
        out[k] = _find(parent, idx[k])
    return out


def _zone_sum(z, nz, vals):
    """Per-zone sums of vals (k, ...) (np.bincount: sequential, deterministic)."""
    flat = vals.reshape(vals.shape[0], -1)
    out = np.stack([np.bincount(z, weights=flat[:, c], minlength=nz) for c in range(flat.shape[1])], 1)
    return out.reshape((nz,) + vals.shape[1:])


def rigidify(x0, u, inv_mass, idx, z):
    """Zone velocities for the zone vertices ``idx`` with zone labels ``z``
    (0..nz-1).  Returns u with those rows replaced (kinematic rows kept).

    Free zone (Bridson et al. 2002 §7.4, Provot 1997): u = v + w x (x0 - c), with c, v the
    centre of mass and its velocity and w = I^+ L, so linear and angular
    momentum are conserved exactly (to rounding).  This is the linearised
    rigid motion: x0 -> x0 + t h u is an affine map I + t h [w]x whose
    singular values are >= 1, so distances inside the zone never shrink and
    a zone collision-free at x0 cannot collide with itself.

    Zone with kinematic vertices: its free vertices follow the affine
    velocity field u(x) = b + A (x - ck) fitted (least squares, minimum
    norm) to the zone's kinematic vertices.  It is exact when those move
    affinely -- one rigid collider (x1 - x0 = (R - I) x0 + T is affine), any
    common translation; a static collider gives u = 0 exactly, so the zone
    stays at x0.  Kinematic vertices with disagreeing, non-affine velocities
    (two colliders, pinching) make it an approximation."""
    nz = int(z.max()) + 1 if z.size else 0
    w = inv_mass[idx]
    kin = w == 0
    m = np.where(kin, 0.0, 1.0 / np.where(kin, 1.0, w))
    xi, ui = x0[idx], u[idx]
    zkin = np.bincount(z, weights=kin.astype(np.float64), minlength=nz) > 0
    # free zones: momentum-conserving rigid velocity
    M = np.bincount(z, weights=m, minlength=nz)
    Ms = np.where(M > 0, M, 1.0)[:, None]
    c = _zone_sum(z, nz, m[:, None] * xi) / Ms
    v = _zone_sum(z, nz, m[:, None] * ui) / Ms
    r = xi - c[z]
    L = _zone_sum(z, nz, m[:, None] * np.cross(r, ui))
    inertia = _zone_sum(z, nz, m[:, None, None] * (np.einsum("kd,kd->k", r, r)[:, None, None] * np.eye(3)
                                                      - r[:, :, None] * r[:, None, :]))
    omega = np.einsum("zab,zb->za", np.linalg.pinv(inertia, rcond=_PINV_RCOND), L)
    u_rigid = v[z] + np.cross(omega[z], r)
    # kinematic zones: affine fit to the kinematic members
    k = kin.astype(np.float64)
    nk = np.bincount(z, weights=k, minlength=nz)
    ck = _zone_sum(z, nz, k[:, None] * xi) / np.where(nk > 0, nk, 1.0)[:, None]
    rk = xi - ck[z]
    ell = np.sqrt(np.bincount(z, weights=k * np.einsum("kd,kd->k", rk, rk), minlength=nz)
                  / np.where(nk > 0, nk, 1.0))
    ell = np.where(ell > 0, ell, 1.0)
    phi = np.column_stack([np.ones(len(idx)), rk / ell[z][:, None]])
    G = _zone_sum(z, nz, k[:, None, None] * phi[:, :, None] * phi[:, None, :])
    R = _zone_sum(z, nz, k[:, None, None] * phi[:, :, None] * ui[:, None, :])
    coeff = np.linalg.pinv(G, rcond=_PINV_RCOND) @ R
    u_fit = np.einsum("ka,kab->kb", phi, coeff[z])
    new = np.where(zkin[z][:, None], u_fit, u_rigid)
    out = u.copy()
    out[idx[~kin]] = new[~kin]
    return out


def impact_zones(x0, u, h, inv_mass, tri, edges, thickness, candidates, max_iterations=100,
                 eta=None, parent=None, hits=collisions, same=None):
    """Fail-safe (Bridson et al. 2002 §7.4): detect CCD hits on x0 -> x0 + h u, merge the
    vertices of every hitting pair into zones (union-find, merging with the
    zones of earlier iterations, or of ``parent`` if given), give every zone
    its rigid velocity (``rigidify``), repeat until no hit remains or
    ``max_iterations`` merges were done.  Returns (u_new, stats) with stats
    zone_iterations, zones, zone_vertices (free vertices in zones),
    remaining (hits of the final u; 0 on success) and parent (the
    union-find forest, to continue merging in a later call).

    The zone velocities are recomputed from the current u after every
    merge, so a merged zone inherits the summed momentum of its parts.
    Cannot converge only if x0 itself has a pair within ``eta`` (a rigid
    zone keeps it there) or the kinematic vertices of a zone do not move
    affinely (see ``rigidify``)."""
    x0, u, inv_mass, tri, edges = _prep(x0, u, inv_mass, tri, edges)
    n = x0.shape[0]
    eta = 1e-3 * thickness if eta is None else eta
    parent = np.arange(n, dtype=np.int64) if parent is None else np.array(parent, dtype=np.int64)
    all_roots = _roots(parent, np.arange(n, dtype=np.int64))
    in_zone = np.bincount(all_roots, minlength=n)[all_roots] > 1      # members of earlier zones
    it = 0
    raw_prev, u_prev, ids = None, None, np.zeros((0, 4), np.int64)
    while True:
        raw = candidates(x0, x0 + h * u)
        if raw is not raw_prev:
            vf, ee = clean_pairs(*raw, tri, edges, inv_mass, same)
            vf_t, ee_t = vf, ee
        else:
            # same candidates as the last pass: a pair none of whose vertices
            # changed velocity (or was in a hit) has the same path as when it
            # was last found clear, so only the others are tested again
            # (exact; a pass used to re-test every pair, 70 % of a pile-up step)
            changed = np.any(u != u_prev, axis=1)
            changed[ids.ravel()] = True
            vf_t = vf[changed[vf[:, 0]] | changed[tri[vf[:, 1]]].any(axis=1)]
            ee_t = ee[changed[edges[ee]].reshape(-1, 4).any(axis=1)]
        raw_prev, u_prev = raw, u.copy()
        ids = hits(x0, x0 + h * u, tri, edges, vf_t, ee_t, eta)[0]
        if ids.shape[0] == 0 or it >= max_iterations:
            break
        _union_rows(parent, ids)
        in_zone[ids.ravel()] = True
        idx = np.flatnonzero(in_zone)
        roots, z = np.unique(_roots(parent, idx), return_inverse=True)
        u = rigidify(x0, u, inv_mass, idx, z.reshape(-1))
        it += 1
    idx = np.flatnonzero(in_zone)
    roots = np.unique(_roots(parent, idx)) if idx.size else idx
    return u, {"zone_iterations": it, "zones": int(roots.size),
               "zone_vertices": int(np.count_nonzero(inv_mass[idx] > 0)),
               "remaining": int(ids.shape[0]), "parent": parent}


# ------------------------------------------------------------------ 4. pipeline

class ReusedCandidates:
    """``candidates(x0, x1)`` for the passes of one :func:`resolve`, found
    once with the boxes grown by ``slack`` more and reused while every
    vertex's end position stays within the box of its old path (x0 to the
    end position they were found for) grown by ``slack`` per coordinate.

    Conservative: the new path's box, grown by the pad, then lies inside the
    old one's grown by pad + slack, so every pair whose swept boxes (grown
    by the pad) overlap on the new paths is among the pairs found; the
    narrow phase is exact, so the extra pairs change nothing.  A query at
    rest (x1 = x0: proximity) is always inside.  On a pile-up (EG07
    tutorial, Part 1 Fig. 19) the CCD and impact-zone passes move few
    vertices by little, and a whole traversal per pass was 39 traversals
    per step.  The decision uses the
    replicated arrays only, so every rank makes it alike (the detection is
    collective)."""

    def __init__(self, detect, pad: float, slack: float):
        self.detect, self.pad, self.slack = detect, float(pad), float(slack)
        self._key = None          # (x0, x1) the cached pairs were found for
        self._pairs = None
        self.detections = 0
        self.calls = 0

    def __call__(self, x0, x1):
        self.calls += 1
        if self._key is not None:
            k0, k1 = self._key
            if (k0.shape == x0.shape and np.array_equal(k0, x0)
                    and np.all(x1 >= np.minimum(x0, k1) - self.slack)
                    and np.all(x1 <= np.maximum(x0, k1) + self.slack)):
                return self._pairs
        self._pairs = self.detect(x0, x1, self.pad + self.slack)
        self._key = (x0.copy(), x1.copy())
        self.detections += 1
        return self._pairs


def resolve(x0, u, h, inv_mass, tri, edges, thickness, friction, candidates,
            max_ccd_iterations=10, max_zone_iterations=100, repulsion_iterations=16,
            sweeps=8, eta=None, margin=0.01, hits=collisions, same=None, keep=None,
            priority=None):
    """The Bridson et al. 2002 §3 pipeline on the average velocity u of a step:

    1. proximity at x0 (pairs closer than ``thickness``) -> ``repulsion``;
    2. up to ``max_ccd_iterations`` passes of ``ccd_impulses`` (new candidates
       every pass, since x1 moves);
    3. if hits remain, ``impact_zones`` until none remain.

    ``repulsion_iterations``: Jacobi passes of the proximity impulses.  A
    stack of layers resting on a body needs the body's push to travel up
    through every layer: with 4 passes the piling ribbon's bottom layer
    ended up to 0.82 of the contact offset inside its ramp's offset, with
    16 at most 0.56 (tests/test_scene_penetration.py).

    ``hits``: the CCD narrow phase of every pass (``collisions``, or the
    distributed drop-in of ``DistributedCollisions.shared_hits``); ``same``:
    see ``clean_pairs``.

    ``keep`` (n,): the distance each vertex's pairs keep in the repulsion
    and the CCD impulses instead of ``thickness`` (``pair_thickness``);
    contact.py gives a closed body's vertices the thickness less the cloth's
    sagitta over the body's curvature there (sagitta.py): a distance-field
    collider already holds every cloth *vertex* at its contact offset, and
    repelling a coarse cloth triangle on a curved body to the full thickness
    from the body's vertices lifted it every step, for the contact to put
    its corners back the next.

    ``priority`` (n,): which vertex of a pair the repulsion and the CCD
    impulses move (``pair_weights``; the impact zones, a last resort,
    rigidify with the true masses).

    Returns (u_new, stats): proximity_pairs, ccd_hits (per pass), zones,
    zone_vertices, zone_iterations, remaining (CCD hits of u_new, 0 unless
    the zone iteration cap was hit)."""
    x0, u, inv_mass, tri, edges = _prep(x0, u, inv_mass, tri, edges)
    eta = 1e-3 * thickness if eta is None else eta
    # the proximity pairs from the candidates of the unresolved step's paths: a superset
    # of those at x0 (each swept box holds its box at x0; the contact kernels measure the
    # distance at x0), so the first CCD pass can reuse them (ReusedCandidates)
    raw = candidates(x0, x0 + h * u)
    vf, ee = clean_pairs(*raw, tri, edges, inv_mass, same)
    pvf = vertex_face_contacts(x0, tri, vf, thickness)
    pee = edge_edge_contacts(x0, edges, ee, thickness)
    u = repulsion(x0, u, h, inv_mass, tri, edges, pvf, pee, thickness, friction,
                  repulsion_iterations, keep, priority)
    stats = {"proximity_pairs": int(pvf.vertex.size + pee.edge_a.size), "ccd_hits": [],
             "zones": 0, "zone_vertices": 0, "zone_iterations": 0, "remaining": 0}
    n_hits = 1
    for _ in range(max_ccd_iterations):
        raw_prev, raw = raw, candidates(x0, x0 + h * u)
        if raw is not raw_prev:          # reused candidates (ReusedCandidates) are clean already
            vf, ee = clean_pairs(*raw, tri, edges, inv_mass, same)
        u, n_hits = ccd_impulses(x0, u, h, inv_mass, tri, edges, vf, ee, thickness, eta, margin,
                                 sweeps, hits, keep, priority)
        stats["ccd_hits"].append(n_hits)
        if n_hits == 0:
            break
    if n_hits:
        u, zs = impact_zones(x0, u, h, inv_mass, tri, edges, thickness, candidates,
                             max_zone_iterations, eta, hits=hits, same=same)
        zs.pop("parent")
        stats.update(zs)
    return u, stats
