"""Rotations shared by everything that places or moves geometry (pieces,
bodies, pattern panels, colliders, skinning): angles in degrees about the
fixed axes x, then y, then z; unit quaternions (w, x, y, z) acting on
column vectors."""
from __future__ import annotations

import numpy as np


def rotation_matrix(degrees) -> np.ndarray:
    """R = Rz(c) Ry(b) Rx(a) for angles (a, b, c) in degrees."""
    ax, ay, az = np.radians(np.asarray(degrees, dtype=np.float64))
    cx, sx, cy, sy, cz, sz = np.cos(ax), np.sin(ax), np.cos(ay), np.sin(ay), np.cos(az), np.sin(az)
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cx, -sx], [0.0, sx, cx]])
    ry = np.array([[cy, 0.0, sy], [0.0, 1.0, 0.0], [-sy, 0.0, cy]])
    rz = np.array([[cz, -sz, 0.0], [sz, cz, 0.0], [0.0, 0.0, 1.0]])
    return rz @ ry @ rx


# (x, y, z) -> (x, -z, y): +90 degrees about x, so a y-up file's +y becomes +z.
# Written out rather than rotation_matrix((90, 0, 0)) so the turn is exact
# (cos 90° is 6e-17 in floating point): a turned file keeps its coordinates' bits.
Y_UP_TO_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


def quat_mul(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Quaternion products (..., 4), (w, x, y, z)."""
    pw, pv = p[..., :1], p[..., 1:]
    qw, qv = q[..., :1], q[..., 1:]
    return np.concatenate([pw * qw - np.sum(pv * qv, axis=-1, keepdims=True),
                           pw * qv + qw * pv + np.cross(pv, qv)], axis=-1)


def quat_from_matrix(rot: np.ndarray) -> np.ndarray:
    """(..., 4) unit quaternions (w, x, y, z), w >= 0, of rotation matrices (..., 3, 3)."""
    m = np.asarray(rot, dtype=np.float64)
    m00, m11, m22 = m[..., 0, 0], m[..., 1, 1], m[..., 2, 2]
    # Shepperd's method: take the largest of 4w², 4x², 4y², 4z² as the pivot
    cand = np.stack([1.0 + m00 + m11 + m22, 1.0 + m00 - m11 - m22,
                     1.0 - m00 + m11 - m22, 1.0 - m00 - m11 + m22], axis=-1)
    pivot = np.argmax(cand, axis=-1)
    s = 2.0 * np.sqrt(np.maximum(np.take_along_axis(cand, pivot[..., None], -1)[..., 0], 1e-300))
    d21, d02, d10 = m[..., 2, 1] - m[..., 1, 2], m[..., 0, 2] - m[..., 2, 0], m[..., 1, 0] - m[..., 0, 1]
    s21, s02, s10 = m[..., 2, 1] + m[..., 1, 2], m[..., 0, 2] + m[..., 2, 0], m[..., 1, 0] + m[..., 0, 1]
    options = [
        (0.25 * s, d21 / s, d02 / s, d10 / s),
        (d21 / s, 0.25 * s, s10 / s, s02 / s),
        (d02 / s, s10 / s, 0.25 * s, s21 / s),
        (d10 / s, s02 / s, s21 / s, 0.25 * s),
    ]
    q = np.stack(options[0], axis=-1)
    for k in (1, 2, 3):
        q = np.where((pivot == k)[..., None], np.stack(options[k], axis=-1), q)
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where(q[..., :1] < 0.0, -q, q)


def matrix_from_quat(q: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotation matrices of quaternions (..., 4) (w, x, y, z), normalised first."""
    q = np.asarray(q, dtype=np.float64)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    out = np.empty(q.shape[:-1] + (3, 3))
    out[..., 0, 0] = 1 - 2 * (y * y + z * z)
    out[..., 0, 1] = 2 * (x * y - w * z)
    out[..., 0, 2] = 2 * (x * z + w * y)
    out[..., 1, 0] = 2 * (x * y + w * z)
    out[..., 1, 1] = 1 - 2 * (x * x + z * z)
    out[..., 1, 2] = 2 * (y * z - w * x)
    out[..., 2, 0] = 2 * (x * z - w * y)
    out[..., 2, 1] = 2 * (y * z + w * x)
    out[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return out
