"""Skinning: linear blend (LBS) and dual quaternion (DQS).

Bone j maps a rest point x to R_j x + t_j (its world transform relative to
the rest pose); a vertex with bones idx[k] and weights w[k] (rows summing
to one, ``skinning_weights``) moves to

* LBS: sum_k w_k (R_k x + t_k).  Blending matrices is not a rotation: a
  joint twisted by 2 phi shrinks the vertices blended half-half across it
  by cos phi (the candy-wrapper collapse; EG07 cloth tutorial, Part 2
  §2.2.2).
* DQS: L. Kavan, S. Collins, J. Zara and C. O'Sullivan, "Geometric
  skinning with approximate dual quaternion blending", ACM TOG 27(4), 2008.
  Every bone as a unit dual quaternion q = r + eps d, r the rotation's unit
  quaternion and d = (0, t) r / 2; per vertex b = sum_k w_k s_k q_k with
  s_k = sign(r_k . r_dominant) (antipodality: q and -q are the same
  transform, the blend must take every bone on the dominant bone's
  hemisphere), normalised by |b_r|, and applied as a rigid transform
  (Kavan et al.'s Algorithm 1).  The blend of rigid transforms is rigid,
  so volume is kept where LBS collapses.

Transforms: ``R`` (J, 3, 3) and ``t`` (J, 3) for one pose, or (F, J, 3, 3)
and (F, J, 3) for F frames (the result is then (F, V, 3)); one compiled
loop over the vertices per frame (a body is skinned several times a step:
numpy's temporaries made DQS of the 23,752-vertex body 10 ms a frame).
Velocities by central differences of the skinned positions are the
caller's business.
"""
from __future__ import annotations

import numpy as np
from numba import njit
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from ..garment.start_check import boundary_edges
from ..rotations import quat_from_matrix, quat_mul
from .skeleton import Skeleton
from .skeleton_fit import sections
from .skinning_weights import dense_weights

__all__ = ["linear_blend", "dual_quaternion", "skin", "axis_angle_matrix", "mesh_volume",
           "candy_wrapper"]

METHODS = ("lbs", "dqs")


# ------------------------------------------------------------------ helpers

def _poses(R, t):
    """(R (F, J, 3, 3), t (F, J, 3), one pose?)."""
    R = np.asarray(R, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64)
    single = R.ndim == 3
    if single:
        R, t = R[None], t[None]
    if R.ndim != 4 or R.shape[-2:] != (3, 3) or t.shape != R.shape[:-1]:
        raise ValueError(f"R must be (J,3,3) or (F,J,3,3) and t (J,3) or (F,J,3); "
                         f"got {R.shape} and {t.shape}")
    return R, t, single


def _weights(rest_vertices, idx, w):
    x = np.asarray(rest_vertices, dtype=np.float64).reshape(-1, 3)
    idx = np.asarray(idx, dtype=np.int64)
    w = np.asarray(w, dtype=np.float64)
    if idx.ndim == 1:
        idx, w = idx[:, None], w[:, None]
    if idx.shape != w.shape or idx.shape[0] != x.shape[0]:
        raise ValueError(f"idx {idx.shape} and w {w.shape} must be (V, k) for V = {x.shape[0]}")
    return x, idx, w


def axis_angle_matrix(axis, angle: float) -> np.ndarray:
    """Rotation matrix (3, 3) by ``angle`` radians about the unit ``axis``
    (Rodrigues)."""
    a = np.asarray(axis, dtype=np.float64)
    a = a / np.linalg.norm(a)
    K = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
    return np.eye(3) + np.sin(angle) * K + (1.0 - np.cos(angle)) * (K @ K)


# ------------------------------------------------------------------ skinning

@njit(cache=True)
def _lbs_kernel(x, idx, w, R, t, out):
    for v in range(x.shape[0]):
        o0 = 0.0; o1 = 0.0; o2 = 0.0
        for k in range(idx.shape[1]):
            wk = w[v, k]
            if wk == 0.0:
                continue
            j = idx[v, k]
            for a in range(3):
                val = t[j, a] + R[j, a, 0] * x[v, 0] + R[j, a, 1] * x[v, 1] + R[j, a, 2] * x[v, 2]
                if a == 0:
                    o0 += wk * val
                elif a == 1:
                    o1 += wk * val
                else:
                    o2 += wk * val
        out[v, 0] = o0; out[v, 1] = o1; out[v, 2] = o2


@njit(cache=True)
def _dqs_kernel(x, idx, w, dominant, qr, qd, out):
    """Kavan et al. 2008 Algorithm 1 per vertex: blend the bones' dual
    quaternions on the dominant bone's hemisphere, normalise, apply."""
    for v in range(x.shape[0]):
        dm = dominant[v]
        br = np.zeros(4)
        bd = np.zeros(4)
        for k in range(idx.shape[1]):
            wk = w[v, k]
            if wk == 0.0:
                continue
            j = idx[v, k]
            dot = qr[j, 0] * qr[dm, 0] + qr[j, 1] * qr[dm, 1] + qr[j, 2] * qr[dm, 2] + qr[j, 3] * qr[dm, 3]
            if dot < 0.0:
                wk = -wk
            for c in range(4):
                br[c] += wk * qr[j, c]
                bd[c] += wk * qd[j, c]
        norm = np.sqrt(br[0] ** 2 + br[1] ** 2 + br[2] ** 2 + br[3] ** 2)
        r0 = br[0] / norm; r1 = br[1] / norm; r2 = br[2] / norm; r3 = br[3] / norm
        d0 = bd[0] / norm; d1 = bd[1] / norm; d2 = bd[2] / norm; d3 = bd[3] / norm
        x0 = x[v, 0]; x1 = x[v, 1]; x2 = x[v, 2]
        # x + 2 rv x (rv x x + r0 x)
        c0 = r2 * x2 - r3 * x1 + r0 * x0
        c1 = r3 * x0 - r1 * x2 + r0 * x1
        c2 = r1 * x1 - r2 * x0 + r0 * x2
        m0 = x0 + 2.0 * (r2 * c2 - r3 * c1)
        m1 = x1 + 2.0 * (r3 * c0 - r1 * c2)
        m2 = x2 + 2.0 * (r1 * c1 - r2 * c0)
        # + 2 (r0 dv - d0 rv + rv x dv)
        out[v, 0] = m0 + 2.0 * (r0 * d1 - d0 * r1 + r2 * d3 - r3 * d2)
        out[v, 1] = m1 + 2.0 * (r0 * d2 - d0 * r2 + r3 * d1 - r1 * d3)
        out[v, 2] = m2 + 2.0 * (r0 * d3 - d0 * r3 + r1 * d2 - r2 * d1)


def linear_blend(rest_vertices, idx, w, R, t) -> np.ndarray:
    """LBS positions (V, 3), or (F, V, 3) for per-frame transforms."""
    x, idx, w = _weights(rest_vertices, idx, w)
    R, t, single = _poses(R, t)
    x, idx, w = (np.ascontiguousarray(a) for a in (x, idx, w))
    out = np.empty((R.shape[0], x.shape[0], 3))
    for f in range(R.shape[0]):
        _lbs_kernel(x, idx, w, np.ascontiguousarray(R[f]), np.ascontiguousarray(t[f]), out[f])
    return out[0] if single else out


def dual_quaternion(rest_vertices, idx, w, R, t) -> np.ndarray:
    """DQS positions (V, 3), or (F, V, 3) for per-frame transforms (module
    docstring; the dominant bone is the vertex's largest weight)."""
    x, idx, w = _weights(rest_vertices, idx, w)
    R, t, single = _poses(R, t)
    x, idx, w = (np.ascontiguousarray(a) for a in (x, idx, w))
    dominant = np.ascontiguousarray(np.take_along_axis(idx, np.argmax(w, axis=1)[:, None], axis=1)[:, 0])
    out = np.empty((R.shape[0], x.shape[0], 3))
    for f in range(R.shape[0]):
        qr = quat_from_matrix(R[f])                                  # (J, 4)
        qd = 0.5 * quat_mul(np.concatenate([np.zeros((t.shape[1], 1)), t[f]], axis=1), qr)
        _dqs_kernel(x, idx, w, dominant, np.ascontiguousarray(qr), np.ascontiguousarray(qd), out[f])
    return out[0] if single else out


def skin(method: str, rest_vertices, idx, w, R, t) -> np.ndarray:
    """``linear_blend`` (method "lbs") or ``dual_quaternion`` ("dqs")."""
    if method == "lbs":
        return linear_blend(rest_vertices, idx, w, R, t)
    if method == "dqs":
        return dual_quaternion(rest_vertices, idx, w, R, t)
    raise ValueError(f"skinning method must be one of {METHODS}, got {method!r}")


# ------------------------------------------------------------------ candy wrapper

def mesh_volume(vertices, triangles) -> float:
    """Signed volume of a closed triangle mesh (divergence theorem)."""
    x = np.asarray(vertices, dtype=np.float64)
    tri = np.asarray(triangles, dtype=np.int64)
    a, b, c = x[tri[:, 0]], x[tri[:, 1]], x[tri[:, 2]]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def _capped_volume(x, tri, edges, loop):
    """Volume of the triangles ``tri`` closed by one fan per boundary loop
    (the directed boundary ``edges`` reversed, to the loop's vertex mean)."""
    n_loops = int(loop.max()) + 1 if loop.size else 0
    apex = np.stack([np.bincount(loop, x[edges[:, 0], c], n_loops) for c in range(3)], axis=1)
    apex /= np.bincount(loop, minlength=n_loops)[:, None]
    a, b, c = x[edges[:, 1]], x[edges[:, 0]], apex[loop]
    cap = float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)
    return mesh_volume(x, tri) + cap


def candy_wrapper(vertices, triangles, skeleton: Skeleton, idx, w, angle_deg: float = 90.0,
                  side: str = "l", band: tuple[float, float] = (0.5, 1.4)) -> dict:
    """Twist the wrist bone by ``angle_deg`` about the forearm axis (every
    other bone identity) and compare LBS with DQS.

    Region: the vertices whose position along the forearm axis, in forearm
    lengths from the elbow, lies in ``band`` (mid forearm to the palm) and
    whose weight on the elbow and wrist bones is at least one half; its
    triangles are closed by a fan per cut loop (rebuilt from the moved
    vertices) and their signed volume is measured at rest and skinned.
    Also the area of the wrist cross section (the plane through the wrist
    joint perpendicular to the forearm).  Returns a dict of the volumes,
    areas and their ratios to rest."""
    x = np.asarray(vertices, dtype=np.float64)
    tri = np.asarray(triangles, dtype=np.int64)
    e, j = skeleton.index(f"{side}_elbow"), skeleton.index(f"{side}_wrist")
    E, W = skeleton.rest[e], skeleton.rest[j]
    length = float(np.linalg.norm(W - E))
    u = (W - E) / length
    n_joints = skeleton.rest.shape[0]
    R = np.repeat(np.eye(3)[None], n_joints, axis=0)
    t = np.zeros((n_joints, 3))
    R[j] = axis_angle_matrix(u, np.radians(angle_deg))
    t[j] = W - R[j] @ W
    s = (x - E) @ u / length
    arm_w = dense_weights(idx, w, n_joints)[:, [e, j]].sum(axis=1)
    region = (s >= band[0]) & (s <= band[1]) & (arm_w >= 0.5)
    sub = tri[region[tri].all(axis=1)]
    edges = boundary_edges(sub)
    ends = np.unique(edges)
    graph = coo_matrix((np.ones(edges.shape[0]), (np.searchsorted(ends, edges[:, 0]),
                                                 np.searchsorted(ends, edges[:, 1]))),
                       shape=(ends.size, ends.size))
    _, label = connected_components(graph, directed=False)
    loop = label[np.searchsorted(ends, edges[:, 0])]
    out = {"angle_deg": float(angle_deg), "region_vertices": int(region.sum()),
           "region_loops": int(loop.max()) + 1 if loop.size else 0}
    poses = {"rest": x, "lbs": linear_blend(x, idx, w, R, t),
             "dqs": dual_quaternion(x, idx, w, R, t)}
    for name, p in poses.items():
        out[f"{name}_volume"] = _capped_volume(p, sub, edges, loop)
        S = sections(p, tri, u, W @ u)
        k = S.nearest(W)
        out[f"{name}_wrist_area"] = float(S.area[k]) if k >= 0 else 0.0
        out[f"{name}_body_volume"] = mesh_volume(p, tri)
    for name in ("lbs", "dqs"):
        out[f"{name}_volume_ratio"] = out[f"{name}_volume"] / out["rest_volume"]
        out[f"{name}_wrist_area_ratio"] = out[f"{name}_wrist_area"] / out["rest_wrist_area"]
    return out
