"""Automatic skinning weights by bone heat.

I. Baran and J. Popović, "Automatic rigging and animation of 3D
characters", ACM SIGGRAPH 2007, §4: the weight of bone i is the equilibrium
temperature of the surface when bone i is held at 1 and the others at 0,
each vertex j exchanging heat with its nearest *visible* bone only:

    (-Δ + H) w_i = H p_i,

Δ the cotangent Laplacian of the surface normalised by the vertex areas,
H = diag(c / d(j)^2) with d(j) the distance from vertex j to its nearest
visible bone and c = 1, p_i(j) = 1 if bone i is that bone, else 0.  A vertex
that sees no bone gets H_jj = 0 (pure diffusion).  Multiplying by the
lumped mass M gives the symmetric positive definite system

    (-L + M H) w_i = M H p_i,      L_ab = (cot α + cot β) / 2,

factorised once (SuperLU, ``scipy.sparse.linalg.splu``) and solved for all
bones as one right-hand-side block.  The weights of a vertex sum to one
before post-processing (the constant solves the sum of the systems);
then every weight below 0.01 is dropped, the 4 largest are kept and the
rest renormalised to sum 1.

The solve is SuperLU with a symmetric minimum-degree ordering and no
pivoting (the matrix is SPD): 0.2 s for the 23,752-vertex GarmentCode body,
whose whole weight computation (bones, visibility, Laplacian, solve) takes
about 0.5 s.  (SuperLU's default partial pivoting destroys the ordering's
sparsity: 35 s for the same factorisation.)

Visibility: the segment from the vertex to the closest point of the bone
must not cross the mesh.  It is tested exactly against the triangles (the
AABB tree of :mod:`distcloth.collision.bvh`, a Möller-Trumbore
segment/triangle test with the barycentric bounds widened by 1e-9 so that a
segment through a shared edge is not let through by rounding), skipping the
triangles incident to the vertex (the segment starts on them); the bones
are tried in order of distance and the first unobstructed one is the
vertex's bone.  So the flank under the arm, nearer the upper arm than the
spine through the air of the armpit, is heated by the torso.  One
deliberate exception: a vertex whose nearest bone is a leaf's (hand, foot,
head) takes it without the test.  The leaf bones are straight stand-ins for
curled, separate fingers and a head with ears, eye sockets and a mouth
cavity: on the GarmentCode body 3,856 of the 11,893 vertices nearest a leaf
bone (2,161 on the hands, 1,695 on the head) would see no bone (2,629) or
only another one (the forearm's end, the neck), which pulls fingers onto
the forearm and lips onto the neck; the region nearest a leaf bone is the
rigid extremity anyway.

Bones (``bone_segments``): joint j owns the segment from its rest position
to its first child; with ``girdles`` (default) a joint with several
children also owns the segments to the others: the pelvis the two
pelvis-hip segments, the chest the two chest-shoulder segments (the
clavicles).  Without them the buttocks and the top of the shoulders up to
the neck are nearest to the thigh and upper-arm bones and follow the legs
and arms (GarmentCode body: mean thigh weight on the buttocks 0.64 and
upper-arm weight on the trapezius 0.41; with the girdles 0.54 and 0.25).  A leaf (head,
wrists, ankles) owns a segment towards its extremity: the vertices beyond
the leaf joint (their closest point on the parent's bone is its end) whose
nearest bone is the parent's; the segment aims at the centroid of the far
part of that region (the vertices at least 0.6 of the farthest one's
distance from the joint: the crown of the head, the fingers, the toes), and
is shortened from the full length in steps of 0.1 until eight points along
it are inside the mesh (so that bone heat sees it from inside).  A fixed
length along the parent bone would miss the foot, which is at an angle to
the shank; aiming at the single farthest vertex gives a bone along the
edge of the hand that leaves the mesh.

Ties: a vertex beyond a joint is equally near the bone that ends there
and the bone that starts there (the same closest point); it goes to the
child's bone.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy.sparse import coo_matrix, diags
from scipy.sparse.linalg import splu

from ..collision.bvh import build_bvh
from ..garment.start_check import ClosedMesh, segment_hits_box
from .skeleton import Skeleton

__all__ = ["Bones", "bone_segments", "cotangent_laplacian", "segment_distances", "visible_bone",
           "bone_heat", "skinning_weights", "dense_weights"]

HEAT_C = 1.0
MIN_WEIGHT = 0.01
# influences kept per vertex: at the sides of the waist bone heat gives the
# pelvis, spine and chest about 0.3 each and an upper arm and a thigh about
# 0.1 each, so a fourth slot would hold one or the other (_sparsify)
MAX_INFLUENCES = 6
LEAF_FAR = 0.6        # a leaf bone aims at the centroid of its region's far part


# ------------------------------------------------------------------ geometry

def segment_distances(points, heads, tails):
    """(distance (n, B), closest point (n, B, 3), parameter t (n, B)) from
    every point to every segment heads[b] -> tails[b]."""
    p = np.asarray(points, dtype=np.float64)
    a = np.asarray(heads, dtype=np.float64)
    ab = np.asarray(tails, dtype=np.float64) - a
    ll = np.einsum("bk,bk->b", ab, ab)
    rel = p[:, None, :] - a[None, :, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(ll > 0.0, np.einsum("nbk,bk->nb", rel, ab) / ll, 0.0)
    t = np.clip(t, 0.0, 1.0)
    c = a[None] + t[..., None] * ab[None]
    return np.linalg.norm(p[:, None, :] - c, axis=2), c, t


@dataclass(frozen=True)
class Bones:
    """Bone segments heads[s] -> tails[s] (S, 3) each, ``owner`` (S,) the
    bone (joint) every segment belongs to, ``trusted`` (S,) segments whose
    nearest vertices need no visibility test (module docstring)."""
    heads: np.ndarray
    tails: np.ndarray
    owner: np.ndarray
    trusted: np.ndarray

    @property
    def n_bones(self) -> int:
        return int(self.owner.max()) + 1 if self.owner.size else 0


def bone_segments(vertices, triangles, skeleton: Skeleton, mesh: ClosedMesh | None = None,
                  girdles: bool = True) -> Bones:
    """The segments every joint owns (module docstring): joint j -> its
    first child (with ``girdles``, -> each child), a leaf -> its
    extremity.  ``mesh``: the body's prepared ``ClosedMesh`` if at hand."""
    x = np.asarray(vertices, dtype=np.float64)
    rest = skeleton.rest
    n = rest.shape[0]
    heads = rest.copy()
    tails = rest.copy()
    leaves = []
    extra = []
    for j in range(n):
        ch = skeleton.children(j)
        if ch.size:
            tails[j] = rest[ch[0]]
            if girdles:
                extra += [(j, c) for c in ch[1:]]
        else:
            leaves.append(j)
    inner = np.array([j for j in range(n) if j not in leaves], dtype=np.int64)
    d, _, t = segment_distances(x, heads[inner], tails[inner])
    k = np.argmin(d, axis=1)
    nearest = inner[k]
    t_near = t[np.arange(x.shape[0]), k]
    if mesh is None:
        mesh = ClosedMesh(x, triangles)
    steps = np.linspace(0.125, 1.0, 8)
    for j in leaves:
        p = skeleton.parents[j]
        region = np.flatnonzero((nearest == p) & (t_near >= 1.0))
        if region.size == 0:
            continue
        r = np.linalg.norm(x[region] - rest[j], axis=1)
        far = x[region[r >= LEAF_FAR * r.max()]].mean(axis=0) - rest[j]
        for f in np.arange(1.0, 0.05, -0.1):
            if mesh.inside(rest[j] + (f * steps)[:, None] * far).all():
                tails[j] = rest[j] + f * far
                break
    owner = np.arange(n, dtype=np.int64)
    trusted = np.zeros(n, dtype=np.bool_)
    trusted[leaves] = True
    if extra:
        e = np.array(extra, dtype=np.int64)
        heads = np.concatenate([heads, rest[e[:, 0]]])
        tails = np.concatenate([tails, rest[e[:, 1]]])
        owner = np.concatenate([owner, e[:, 0]])
        trusted = np.concatenate([trusted, np.zeros(len(extra), np.bool_)])
    return Bones(heads, tails, owner, trusted)


def cotangent_laplacian(vertices, triangles):
    """(L, mass): the cotangent Laplacian (V, V) CSR, L_ab = (cot α + cot β)/2
    off the diagonal, rows summing to zero (negative semidefinite), and the
    barycentric vertex areas (V,)."""
    x = np.asarray(vertices, dtype=np.float64)
    tri = np.asarray(triangles, dtype=np.int64)
    n = x.shape[0]
    rows, cols, vals = [], [], []
    cross_len = np.linalg.norm(np.cross(x[tri[:, 1]] - x[tri[:, 0]], x[tri[:, 2]] - x[tri[:, 0]]),
                               axis=1)
    floor = 1e-12 * max(float(cross_len.max()), 1e-300)
    for k in range(3):
        i, a, b = tri[:, k], tri[:, (k + 1) % 3], tri[:, (k + 2) % 3]
        u, v = x[a] - x[i], x[b] - x[i]
        cot = np.einsum("ij,ij->i", u, v) / np.maximum(cross_len, floor)
        rows += [a, b]
        cols += [b, a]
        vals += [0.5 * cot, 0.5 * cot]
    rows, cols, vals = np.concatenate(rows), np.concatenate(cols), np.concatenate(vals)
    off = coo_matrix((vals, (rows, cols)), shape=(n, n)).tocsr()
    L = (off - diags(np.asarray(off.sum(axis=1)).ravel())).tocsr()
    mass = np.bincount(tri.reshape(-1), np.repeat(cross_len / 6.0, 3), minlength=n)
    return L, mass


# ------------------------------------------------------------------ visibility

_BARY_EPS = 1e-9


@njit(cache=True)
def _segment_triangle(p, d, a, b, c):
    """Möller-Trumbore: does p + t d, 0 < t <= 1, cross triangle abc?  The
    barycentric bounds are widened by 1e-9 so that a segment through a
    shared edge or vertex is not let through the crack between the
    triangles by rounding (a graze counts as blocked)."""
    e1 = b - a
    e2 = c - a
    h0 = d[1] * e2[2] - d[2] * e2[1]
    h1 = d[2] * e2[0] - d[0] * e2[2]
    h2 = d[0] * e2[1] - d[1] * e2[0]
    det = e1[0] * h0 + e1[1] * h1 + e1[2] * h2
    if det == 0.0:
        return False
    f = 1.0 / det
    s = p - a
    u = f * (s[0] * h0 + s[1] * h1 + s[2] * h2)
    if u < -_BARY_EPS or u > 1.0 + _BARY_EPS:
        return False
    q0 = s[1] * e1[2] - s[2] * e1[1]
    q1 = s[2] * e1[0] - s[0] * e1[2]
    q2 = s[0] * e1[1] - s[1] * e1[0]
    v = f * (d[0] * q0 + d[1] * q1 + d[2] * q2)
    if v < -_BARY_EPS or u + v > 1.0 + _BARY_EPS:
        return False
    t = f * (e2[0] * q0 + e2[1] * q1 + e2[2] * q2)
    return t > 1e-9 and t <= 1.0


@njit(cache=True)
def _blocked_kernel(x, tri, vid, ends, lo, hi, left, right, first, count, order, plo, phi,
                    out):
    stack = np.empty(left.shape[0] + 1, np.int64)
    inv = np.empty(3)
    for i in range(vid.shape[0]):
        v = vid[i]
        p = x[v]
        d = ends[i] - p
        for a in range(3):
            inv[a] = 1.0 / d[a] if d[a] != 0.0 else np.inf
        hit = False
        top = 1
        stack[0] = 0
        while top > 0 and not hit:
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
            for k in range(first[node], first[node] + count[node]):
                f = order[k]
                if tri[f, 0] == v or tri[f, 1] == v or tri[f, 2] == v:
                    continue
                if not segment_hits_box(p, inv, plo, phi, f):
                    continue
                if _segment_triangle(p, d, x[tri[f, 0]], x[tri[f, 1]], x[tri[f, 2]]):
                    hit = True
                    break
        out[i] = hit


def visible_bone(vertices, triangles, heads, tails, trusted=None):
    """(segment (V,) or -1, distance (V,)): per vertex the nearest segment
    whose closest point the vertex sees without crossing the mesh; a vertex
    whose nearest segment is ``trusted`` takes it without the test (module
    docstring)."""
    x = np.ascontiguousarray(np.asarray(vertices, dtype=np.float64))
    tri = np.ascontiguousarray(np.asarray(triangles, dtype=np.int64))
    d, c, t = segment_distances(x, heads, tails)
    # a vertex beyond a joint is as near the bone ending there as the one
    # starting there: the tie goes to the child (the face to the head, not
    # the neck)
    tie = 1e-9 * float(np.ptp(x, axis=0).max())
    rank = np.argsort(d + tie * (t >= 1.0), axis=1, kind="stable")
    n, nb = d.shape
    rows = np.arange(n)
    seg = np.full(n, -1, np.int64)
    dist = np.full(n, np.inf)
    pending = rows
    if trusted is not None:
        first = rank[:, 0]
        sure = np.asarray(trusted, dtype=np.bool_)[first]
        seg[sure] = first[sure]
        dist[sure] = d[rows[sure], first[sure]]
        pending = rows[~sure]
    bvh = build_bvh(tri, x, pad=1e-9 * float(np.ptp(x, axis=0).max()))
    for r in range(nb):
        if pending.size == 0:
            break
        b = rank[pending, r]
        ends = np.ascontiguousarray(c[pending, b])
        blocked = np.empty(pending.size, np.bool_)
        _blocked_kernel(x, tri, pending, ends, bvh.lo, bvh.hi, bvh.left, bvh.right, bvh.first,
                        bvh.count, bvh.order, bvh.plo, bvh.phi, blocked)
        ok = ~blocked
        seg[pending[ok]] = b[ok]
        dist[pending[ok]] = d[pending[ok], b[ok]]
        pending = pending[blocked]
    return seg, dist


# ------------------------------------------------------------------ bone heat

def bone_heat(vertices, triangles, heads, tails, owner=None, trusted=None, *,
              max_influences: int = MAX_INFLUENCES, min_weight: float = MIN_WEIGHT,
              dense: bool = False):
    """Bone heat weights of the bones made of segments heads[s] -> tails[s]
    (``owner[s]`` the bone of segment s, default s itself; ``trusted`` see
    ``visible_bone``).

    Returns ``(idx (V, k), w (V, k))`` with k = max_influences, rows sorted
    by decreasing weight (column 0 the dominant bone), weights >= min_weight
    or 0 (then the index repeats the dominant bone), rows summing to 1;
    with ``dense=True`` the raw solution (V, n_bones) before clamping.
    """
    x = np.asarray(vertices, dtype=np.float64)
    tri = np.asarray(triangles, dtype=np.int64)
    heads = np.asarray(heads, dtype=np.float64).reshape(-1, 3)
    tails = np.asarray(tails, dtype=np.float64).reshape(-1, 3)
    owner = (np.arange(heads.shape[0]) if owner is None
             else np.asarray(owner, dtype=np.int64))
    n, nb = x.shape[0], int(owner.max()) + 1
    seg, dist = visible_bone(x, tri, heads, tails, trusted)
    seen = seg >= 0
    heat = np.zeros(n)
    heat[seen] = HEAT_C / np.maximum(dist[seen], 1e-9 * float(np.ptp(x, axis=0).max())) ** 2
    L, mass = cotangent_laplacian(x, tri)
    mh = mass * heat
    A = (diags(mh) - L).tocsc()
    rhs = np.zeros((n, nb))
    rhs[np.flatnonzero(seen), owner[seg[seen]]] = mh[seen]
    # symmetric positive definite: no pivoting, a symmetric ordering (module
    # docstring)
    lu = splu(A, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
              options=dict(SymmetricMode=True))
    W = lu.solve(rhs)
    if dense:
        return W
    return _sparsify(W, max_influences, min_weight)


def _sparsify(W, k, min_weight):
    """The k largest weights of each row less the (k+1)-th, clipped, then
    ``min_weight`` and renormalised.  Less the (k+1)-th, the truncation is
    continuous in W: where two neighbouring vertices' k-th and (k+1)-th
    bones swap (an upper arm's and a thigh's 0.1 at the waist), both weigh
    about zero on either side.  Plain top-k truncation gave one vertex the
    arm's 10 % and its neighbour the thigh's, and the walk stretched skin
    edges between them up to 3.7 times (1.7 so, with k = 6)."""
    W = np.clip(W, 0.0, None)
    if W.shape[1] > k:
        W = np.clip(W - np.partition(W, -(k + 1), axis=1)[:, -(k + 1)][:, None], 0.0, None)
    if W.shape[1] < k:                     # fewer bones than columns: pad with zeros
        W = np.concatenate([W, np.zeros((W.shape[0], k - W.shape[1]))], axis=1)
    idx = np.argsort(-W, axis=1, kind="stable")[:, :k]
    w = np.take_along_axis(W, idx, axis=1)
    w[w < min_weight] = 0.0
    w[:, 0] = np.where(w[:, 0] > 0.0, w[:, 0], 1.0)    # never an empty row
    w /= w.sum(axis=1, keepdims=True)
    idx = np.where(w > 0.0, idx, idx[:, :1])
    return idx.astype(np.int64), w


def skinning_weights(vertices, triangles, skeleton: Skeleton, girdles: bool = True, **kwargs):
    """Bone heat weights of the skeleton's bones (``bone_segments``):
    ``(idx (V, k), w (V, k))``, k = MAX_INFLUENCES, bone index = joint index."""
    bones = bone_segments(vertices, triangles, skeleton, girdles=girdles)
    return bone_heat(vertices, triangles, bones.heads, bones.tails, bones.owner, bones.trusted,
                     **kwargs)


def dense_weights(idx, w, n_bones: int) -> np.ndarray:
    """(V, n_bones) weight matrix of sparse (idx, w)."""
    idx = np.asarray(idx, dtype=np.int64)
    out = np.zeros((idx.shape[0], n_bones))
    np.add.at(out, (np.repeat(np.arange(idx.shape[0]), idx.shape[1]), idx.reshape(-1)),
              np.asarray(w, dtype=np.float64).reshape(-1))
    return out
