"""Fit the fixed skeleton (:mod:`.skeleton`) to a closed body mesh.

The mesh is in the body file's frame: y up, metres, the body's left +x, its
front +z, standing on its lowest vertex, roughly A- or T-posed (arms away
from the torso, legs apart or at least not fused).  Nothing is hard-coded to
one body: every joint is found from the mesh's own topology and its cross
sections, then placed at fixed anthropometric fractions of lengths measured
on that mesh.

Tools
-----
* **Cross sections** (``sections``): the plane n.x = c cuts every triangle
  with vertices on both sides in one segment; segments are oriented by the
  triangle (consistently outward mesh: they chain head to tail) and grouped
  into loops by the mesh edges they share (connected components), so two
  limbs that touch geometrically (thighs, an arm on the flank) stay two
  loops.  Per loop: the signed area, area centroid (shoelace sums over the
  unordered segments) and perimeter.  Holes (the mouth) come out with a
  negative area and are ignored.
* **Merge sweep** (``merge_vertex``): the union-find sweep of 0-dimensional
  persistence over a height function f on the vertex graph (vertices in
  increasing f, each joined with its already swept neighbours, the elder
  component absorbing the younger).  It returns the vertex at which the
  component of a seed vertex first merges with a component born elsewhere
  (a birth vertex in a given set, at least ``min_size`` vertices): the
  saddle of f where a limb joins the rest of the body.

Landmarks
---------
H = body height (max y - min y), x_mid = x of the volume centroid.

* Crotch: f = y, seed the lowest vertex with x > x_mid (left foot), the
  other component must be born at x < x_mid (right leg): the saddle where
  the legs' cross sections stop being two separate loops.
* Armpits: per side, the arm direction d is the principal axis of the
  outer 40 % of the side's lateral extent (forearm and hand, in A- and
  T-pose alike); fingertip = the extreme vertex along d; f = -x.d' (a plane
  sweeping from the fingertip towards the body), d' = d tilted down to at
  least 45 degrees below the horizontal (for an arm near the horizontal,
  planes perpendicular to it would sweep the flank from its widest point,
  hips or ribs, up to the armpit as pieces that all merge with the arm
  first; a tilted plane reaches the flank from below, connected to the
  legs); the other component must be born more than 0.1 H from the arm
  axis (the legs and torso; fingers are born on the axis).  The saddle is
  the armpit.
* Neck level: the minimum-area horizontal section between the higher armpit
  and the widest head section (the widest section in the top 12 % of H).

Joints (fractions in brackets)
------------------------------
Segment proportions from Drillis & Contini 1966 (as tabulated by Winter,
"Biomechanics and motor control of human movement"): hip (greater
trochanter) 0.530 H, knee 0.285 H, ankle 0.039 H; upper arm 0.186 H,
forearm 0.146 H, hand 0.108 H.

* hips: height crotch + 0.05 H (the femoral head at trochanter level,
  ~0.06 H above a crotch at ~0.47 H in those tables; 0.05 H keeps the joint
  in the pelvis of bodies with a low crotch), on the thigh axis: the line
  through the centroids of the leg loop 0.03 H below the crotch and at the
  knee, extended up to that height.
* pelvis: centroid of the torso section 0.04 H above the hips (~7 cm, the
  middle of the pelvis between the hip joints and the iliac crest; the
  pelvis-to-hip segments slope down and out like the pelvic bones).
* knees: centroid of the leg loop half way (0.50) between hip and ankle
  heights (thigh 0.245 H, shank 0.246 H).
* ankles: height 0.039 H above the sole, on the shank axis (knee centroid
  to the centroid of the narrowest shank section between 0.05 H and
  0.12 H, extended down): the centroid of a horizontal section that low
  would be pulled forward by the foot.
* chest: centroid of the torso loop 0.02 H below the lower armpit (arms are
  separate loops there); spine: the torso section half way between pelvis
  and chest heights (the waist).
* head: centroid of the narrowest neck section, just under the jaw: the
  head's bone then starts below the chin, so the face is nearer to it than
  to the neck's (with the head joint higher up, at the skull base, the chin
  and mouth of a GarmentCode body are weighted to the neck).  neck: centroid
  of the section 0.025 H lower (the neck's base: half the visible neck,
  shoulder line 0.818 H to chin 0.870 H in Drillis & Contini).
* shoulders: the centroid of the arm-torso junction, the loop the vertical
  plane x = x_armpit cuts around the upper-arm axis (a line fitted to the
  centroids of the arm loops cut perpendicular to d from 0.06 to 0.35 of
  the armpit-to-fingertip length), i.e. half way between the armpit and
  the top of the shoulder rather than at the armpit on its underside.
* wrists: 0.755 of shoulder-to-fingertip ((0.186 + 0.146) / 0.44), then the
  narrowest arm section within +-0.06 of that length (the wrist is the
  forearm's narrowest point), its centroid.
* elbows: 0.56 of shoulder-to-wrist (0.186 / 0.332), the centroid of the
  arm section there (perpendicular to the shoulder-fingertip line).

Every joint is then checked with the generalized winding number of
:class:`distcloth.garment.start_check.ClosedMesh`; a joint that is not
inside (a thin or odd body) is pulled towards its parent (the root towards
its first child) until it is; on the GarmentCode mean body none needs it.

Checked on ``mean_all.obj`` (all joints inside, left/right mirror images
within 9 mm, the mesh itself being symmetric to ~1 cm), on affine copies of
it (moved, scaled 1.1, widened 1.25 or slimmed 0.85 across, stretched 1.15
upwards: every joint within 6 mm of the transformed fit), and on copies
whose arms were raised by 20, 45 and 55 degrees (almost T-pose, and just
above) by dual quaternion skinning: wrists and elbows within 1.6 cm,
shoulders within 3.6 cm of the raised joints (the skinned armpit is not the
rest armpit), trunk within 1.1 cm.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from ..garment.start_check import ClosedMesh
from .skeleton import JOINT_NAMES, Skeleton, skeleton_from_positions

__all__ = ["Sections", "sections", "merge_vertex", "vertex_adjacency", "body_landmarks",
           "fit_skeleton"]

# anthropometric fractions (module docstring)
HIP_ABOVE_CROTCH = 0.05          # x H
PELVIS_ABOVE_HIP = 0.04          # x H
ANKLE_HEIGHT = 0.039             # x H
KNEE_FRACTION = 0.50             # hip -> ankle
WRIST_FRACTION = 0.755           # shoulder -> fingertip
WRIST_SEARCH = 0.06              # +- shoulder-to-fingertip length
ELBOW_FRACTION = 0.56            # shoulder -> wrist
NECK_BELOW_HEAD = 0.025          # x H
CHEST_BELOW_ARMPIT = 0.02        # x H
ARM_OUTER = 0.6                  # outer part of the lateral extent: forearm and hand
ARM_AXIS_RADIUS = 0.10           # x H: births farther than this from the arm axis
UPPER_ARM = (0.06, 0.35)         # of the armpit-to-fingertip length
SWEEP_DOWN = 45.0                # degrees: least tilt of the armpit sweep


# ------------------------------------------------------------------ cross sections

@dataclass(frozen=True)
class Sections:
    """Loops of one planar cut: signed area (negative for holes), area
    centroid (3D, in the plane) and perimeter per loop."""
    area: np.ndarray
    centroid: np.ndarray
    perimeter: np.ndarray

    def __len__(self) -> int:
        return int(self.area.shape[0])

    def nearest(self, point) -> int:
        """The solid loop (positive area) whose centroid is nearest the point,
        -1 if there is none."""
        if len(self) == 0 or not (self.area > 0).any():
            return -1
        d = np.linalg.norm(self.centroid - np.asarray(point, float), axis=1)
        return int(np.argmin(np.where(self.area > 0, d, np.inf)))


def sections(vertices, triangles, normal, offset: float) -> Sections:
    """The loops where the plane normal.x = offset cuts the mesh (a vertex
    on the plane counts as above it).  See the module docstring."""
    x = np.asarray(vertices, dtype=np.float64)
    tri = np.asarray(triangles, dtype=np.int64)
    n = np.asarray(normal, dtype=np.float64)
    n = n / np.linalg.norm(n)
    s = x @ n - float(offset)
    above = (s >= 0.0)[tri]
    k = above.sum(axis=1)
    cut = (k == 1) | (k == 2)
    T, A = tri[cut], above[cut]
    if T.shape[0] == 0:
        return Sections(np.zeros(0), np.zeros((0, 3)), np.zeros(0))
    An = np.roll(A, -1, axis=1)
    rows = np.arange(T.shape[0])
    nv = x.shape[0]

    def crossing(kk):
        u, v = T[rows, kk], T[rows, (kk + 1) % 3]
        t = s[u] / (s[u] - s[v])
        return x[u] + t[:, None] * (x[v] - x[u]), np.minimum(u, v) * nv + np.maximum(u, v)

    # each cut triangle has one edge going above -> below and one below -> above
    # (in its own vertex order); the segment runs from the first to the second,
    # so neighbouring triangles' segments chain head to tail
    p, key_p = crossing(np.argmax(A & ~An, axis=1))
    q, key_q = crossing(np.argmax(~A & An, axis=1))
    keys, inv = np.unique(np.concatenate([key_p, key_q]), return_inverse=True)
    m = T.shape[0]
    graph = coo_matrix((np.ones(m), (inv[:m], inv[m:])), shape=(keys.size, keys.size))
    n_loops, label = connected_components(graph, directed=False)
    seg = label[inv[:m]]
    o = p.mean(axis=0)
    a2 = np.cross(p - o, q - o) @ n                      # twice the signed triangle area
    area = 0.5 * np.bincount(seg, a2, n_loops)
    moment = np.stack([np.bincount(seg, a2 * (p[:, c] + q[:, c] - 2.0 * o[c]), n_loops)
                       for c in range(3)], axis=1) / 6.0
    with np.errstate(divide="ignore", invalid="ignore"):
        centroid = o + moment / area[:, None]
    perimeter = np.bincount(seg, np.linalg.norm(q - p, axis=1), n_loops)
    return Sections(area, centroid, perimeter)


# ------------------------------------------------------------------ merge sweep

def vertex_adjacency(triangles, n_vertices: int):
    """CSR (indptr, indices) of the vertex graph of the mesh edges."""
    tri = np.asarray(triangles, dtype=np.int64)
    a = tri.reshape(-1)
    b = tri[:, [1, 2, 0]].reshape(-1)
    g = coo_matrix((np.ones(2 * a.size), (np.concatenate([a, b]), np.concatenate([b, a]))),
                   shape=(n_vertices, n_vertices)).tocsr()
    return g.indptr.astype(np.int64), g.indices.astype(np.int64)


@njit(cache=True)
def _root(parent, v):
    r = v
    while parent[r] != r:
        r = parent[r]
    while parent[v] != r:                 # path compression
        nxt = parent[v]
        parent[v] = r
        v = nxt
    return r


@njit(cache=True)
def _merge_sweep(order, indptr, indices, seed, other_ok, min_size):
    n = order.shape[0]
    rank = np.empty(n, np.int64)
    for k in range(n):
        rank[order[k]] = k
    parent = np.full(n, -1, np.int64)
    birth = np.empty(n, np.int64)
    size = np.zeros(n, np.int64)
    for k in range(n):
        v = order[k]
        parent[v] = v
        birth[v] = v
        size[v] = 1
        for e in range(indptr[v], indptr[v + 1]):
            u = indices[e]
            if parent[u] < 0:
                continue
            ru = _root(parent, u)
            rv = _root(parent, v)
            if ru == rv:
                continue
            if parent[seed] >= 0:
                rs = _root(parent, seed)
                if ru == rs or rv == rs:
                    other = rv if ru == rs else ru
                    if other_ok[birth[other]] and size[other] >= min_size:
                        return v
            if rank[birth[ru]] < rank[birth[rv]]:       # elder rule: older root stays
                ru, rv = rv, ru
            parent[ru] = rv
            size[rv] += size[ru]
    return -1


def merge_vertex(f, adjacency, seed: int, other_ok, min_size: int = 1) -> int:
    """Sweep the vertices in increasing f; the vertex at which the seed's
    component first merges with a component of at least ``min_size``
    vertices whose birth (lowest f) vertex has ``other_ok``; -1 if never."""
    indptr, indices = adjacency
    order = np.argsort(np.asarray(f, dtype=np.float64), kind="stable")
    return int(_merge_sweep(order, indptr, indices, int(seed),
                            np.asarray(other_ok, dtype=np.bool_), int(min_size)))


# ------------------------------------------------------------------ landmarks

def _volume_centroid(x, tri):
    a, b, c = x[tri[:, 0]], x[tri[:, 1]], x[tri[:, 2]]
    v6 = np.einsum("ij,ij->i", a, np.cross(b, c))
    return (v6[:, None] * (a + b + c)).sum(axis=0) / (4.0 * v6.sum())


def _fit_line(points):
    """(mean, unit direction) of the least-squares line through the points."""
    mu = points.mean(axis=0)
    _, _, vt = np.linalg.svd(points - mu)
    return mu, vt[0]


def _horizontal(x, tri, y, near):
    """Centroid and area of the horizontal loop at height y nearest ``near``."""
    S = sections(x, tri, (0.0, 1.0, 0.0), y)
    i = S.nearest(near)
    if i < 0:
        raise ValueError(f"fit_skeleton: no cross section at height {y:.3f}")
    return S.centroid[i], S.area[i]


def _arm(x, tri, adjacency, side, x_mid, height):
    """Landmarks of one arm (side +1 left, -1 right)."""
    lateral = side * (x[:, 0] - x_mid)
    outer = lateral > ARM_OUTER * lateral.max()
    mu, d = _fit_line(x[outer])
    if side * d[0] < 0:
        d = -d
    proj = x @ d
    tip = int(np.flatnonzero(outer)[np.argmax(proj[outer])])
    rel = x - mu
    off_axis = np.linalg.norm(rel - np.outer(rel @ d, d), axis=1)
    # sweep direction: the arm's, tilted down to at least SWEEP_DOWN below
    # the horizontal (a T-pose arm would otherwise be swept by vertical
    # planes, which reach the flank below the armpit before the armpit)
    horizontal = np.array([d[0], 0.0, d[2]]) / np.hypot(d[0], d[2])
    down = max(np.arcsin(np.clip(-d[1], -1.0, 1.0)), np.radians(SWEEP_DOWN))
    sweep = np.cos(down) * horizontal - np.sin(down) * np.array([0.0, 1.0, 0.0])
    armpit = merge_vertex(-(x @ sweep), adjacency, tip, off_axis > ARM_AXIS_RADIUS * height,
                          max(1, x.shape[0] // 100))
    if armpit < 0:
        raise ValueError("fit_skeleton: could not find where an arm joins the torso")
    a, b = proj[armpit], proj[tip]
    centroids = []
    for s in np.linspace(a + UPPER_ARM[0] * (b - a), a + UPPER_ARM[1] * (b - a), 8):
        S = sections(x, tri, d, s)
        i = S.nearest(mu + (s - mu @ d) * d)
        if i >= 0:
            centroids.append(S.centroid[i])
    c0, u = _fit_line(np.array(centroids))
    if abs(u[0]) < 1e-6:
        raise ValueError("fit_skeleton: the upper arm is parallel to the body's side")
    # the arm-torso junction: the loop of the vertical plane x = x_armpit
    # around the upper-arm axis
    on_axis = c0 + (x[armpit, 0] - c0[0]) / u[0] * u
    S = sections(x, tri, (1.0, 0.0, 0.0), x[armpit, 0])
    i = S.nearest(on_axis)
    shoulder = S.centroid[i] if i >= 0 else on_axis
    return dict(armpit=x[armpit], fingertip=x[tip], direction=d, shoulder=shoulder)


def _along_arm(x, tri, shoulder, fingertip):
    """Wrist and elbow of one arm (module docstring)."""
    axis = fingertip - shoulder
    length = float(np.linalg.norm(axis))
    u = axis / length
    best = None
    for f in np.linspace(WRIST_FRACTION - WRIST_SEARCH, WRIST_FRACTION + WRIST_SEARCH, 25):
        p = shoulder + f * axis
        S = sections(x, tri, u, p @ u)
        i = S.nearest(p)
        if i >= 0 and (best is None or S.area[i] < best[0]):
            best = (S.area[i], S.centroid[i])
    if best is None:
        raise ValueError("fit_skeleton: no arm section near the wrist")
    wrist = best[1]
    p = shoulder + ELBOW_FRACTION * (wrist - shoulder)
    S = sections(x, tri, u, p @ u)
    i = S.nearest(p)
    return (S.centroid[i] if i >= 0 else p), wrist


def body_landmarks(vertices, triangles) -> dict:
    """Landmarks the skeleton is built from (module docstring): floor and top
    heights, height, x_mid, crotch, per side armpit / fingertip / arm
    direction, neck level and the widest head level."""
    x = np.ascontiguousarray(np.asarray(vertices, dtype=np.float64))
    tri = np.ascontiguousarray(np.asarray(triangles, dtype=np.int64))
    adjacency = vertex_adjacency(tri, x.shape[0])
    floor, top = float(x[:, 1].min()), float(x[:, 1].max())
    height = top - floor
    x_mid = float(_volume_centroid(x, tri)[0])
    left = x[:, 0] > x_mid
    seed = int(np.flatnonzero(left)[np.argmin(x[left, 1])])
    crotch = merge_vertex(x[:, 1], adjacency, seed, ~left, max(1, x.shape[0] // 100))
    if crotch < 0:
        raise ValueError("fit_skeleton: the legs never join (is the mesh one closed body?)")
    out = dict(floor=floor, top=top, height=height, x_mid=x_mid, crotch=x[crotch])
    for name, side in (("l", 1.0), ("r", -1.0)):
        for key, value in _arm(x, tri, adjacency, side, x_mid, height).items():
            out[f"{name}_{key}"] = value
    y_armpit = max(out["l_armpit"][1], out["r_armpit"][1])
    centre = np.array([x_mid, 0.0, float(x[:, 2].mean())])

    def midline_area(levels):
        """Area of the loop nearest the body's vertical axis at every level."""
        areas = np.zeros(levels.shape[0])
        for k, y in enumerate(levels):
            S = sections(x, tri, (0.0, 1.0, 0.0), y)
            i = S.nearest(centre + [0.0, y, 0.0])
            if i >= 0:
                areas[k] = S.area[i]
        return areas

    head_levels = np.linspace(top - 0.12 * height, top - 0.01 * height, 23)
    y_head = float(head_levels[np.argmax(midline_area(head_levels))])
    neck_levels = np.arange(y_armpit + 0.005 * height, y_head, 0.002 * height)
    out["head_level"] = y_head
    out["neck_level"] = float(neck_levels[np.argmin(midline_area(neck_levels))])
    return out


# ------------------------------------------------------------------ joints

def fit_skeleton(vertices, triangles) -> Skeleton:
    """The fixed skeleton placed in the body mesh (module docstring)."""
    x = np.ascontiguousarray(np.asarray(vertices, dtype=np.float64))
    tri = np.ascontiguousarray(np.asarray(triangles, dtype=np.int64))
    L = body_landmarks(x, tri)
    H, floor, x_mid = L["height"], L["floor"], L["x_mid"]
    crotch = L["crotch"]
    J = {}
    y_hip = crotch[1] + HIP_ABOVE_CROTCH * H
    y_ankle = floor + ANKLE_HEIGHT * H
    y_knee = y_hip + KNEE_FRACTION * (y_ankle - y_hip)
    for name, side in (("l", 1.0), ("r", -1.0)):
        guess = np.array([x_mid + side * 0.05 * H, 0.0, crotch[2]])
        thigh, _ = _horizontal(x, tri, crotch[1] - 0.03 * H, guess + [0, crotch[1], 0])
        knee, _ = _horizontal(x, tri, y_knee, thigh)
        knee[1] = y_knee
        # narrowest shank section above the foot
        best = None
        for y in np.linspace(floor + 0.05 * H, floor + 0.12 * H, 15):
            c, a = _horizontal(x, tri, y, knee)
            if best is None or a < best[0]:
                best = (a, c)
        shank = best[1]
        J[f"{name}_knee"] = knee
        J[f"{name}_ankle"] = knee + (y_ankle - knee[1]) / (shank[1] - knee[1]) * (shank - knee)
        J[f"{name}_hip"] = knee + (y_hip - knee[1]) / (thigh[1] - knee[1]) * (thigh - knee)
        J[f"{name}_shoulder"] = L[f"{name}_shoulder"]
        J[f"{name}_elbow"], J[f"{name}_wrist"] = _along_arm(x, tri, L[f"{name}_shoulder"],
                                                            L[f"{name}_fingertip"])
    mid = 0.5 * (J["l_hip"] + J["r_hip"])
    y_pelvis = y_hip + PELVIS_ABOVE_HIP * H
    J["pelvis"], _ = _horizontal(x, tri, y_pelvis, mid + [0.0, y_pelvis - y_hip, 0.0])
    y_chest = min(L["l_armpit"][1], L["r_armpit"][1]) - CHEST_BELOW_ARMPIT * H
    J["chest"], _ = _horizontal(x, tri, y_chest, J["pelvis"] + [0.0, y_chest - y_pelvis, 0.0])
    y_spine = 0.5 * (y_pelvis + y_chest)
    J["spine"], _ = _horizontal(x, tri, y_spine, 0.5 * (J["pelvis"] + J["chest"]))
    y_head = L["neck_level"]
    y_neck = y_head - NECK_BELOW_HEAD * H
    J["neck"], _ = _horizontal(x, tri, y_neck, J["chest"] + [0.0, y_neck - y_chest, 0.0])
    J["head"], _ = _horizontal(x, tri, y_head, J["neck"] + [0.0, y_head - y_neck, 0.0])
    rest = np.array([J[name] for name in JOINT_NAMES])
    skeleton = skeleton_from_positions(rest)
    return skeleton_from_positions(_pull_inside(ClosedMesh(x, tri), skeleton))


def _pull_inside(mesh: ClosedMesh, skeleton: Skeleton) -> np.ndarray:
    """Joints outside the mesh moved towards their parent (the root towards
    its first child) to the farthest inside point of 20 on that segment."""
    rest = skeleton.rest.copy()
    outside = np.flatnonzero(~mesh.inside(rest))
    t = np.linspace(1.0, 0.0, 21)[1:]
    for j in outside:
        p = skeleton.parents[j]
        anchor = rest[p] if p >= 0 else rest[skeleton.children(j)[0]]
        cand = anchor + t[:, None] * (rest[j] - anchor)
        ok = np.flatnonzero(mesh.inside(cand))
        if ok.size:
            rest[j] = cand[ok[0]]
    return rest
