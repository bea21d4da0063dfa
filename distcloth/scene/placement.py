"""Place a piece in the world: rotate, then move its bounding-box centre.

Rotation angles are degrees about the fixed world axes x, then y, then z
(docs/config.md), i.e. R = Rz Ry Rx acting on column vectors.
"""
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


def bounding_box_center(points: np.ndarray) -> np.ndarray:
    return 0.5 * (points.min(axis=0) + points.max(axis=0))


def place(points: np.ndarray, rotation, center) -> np.ndarray:
    """Rotate ``points`` (n, 3) and translate so their bounding-box centre is ``center``."""
    rotated = points @ rotation_matrix(rotation).T
    return rotated + (np.asarray(center, dtype=np.float64) - bounding_box_center(rotated))
