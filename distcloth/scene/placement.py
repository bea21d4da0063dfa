"""Place a piece or a body in the world: rotate, then move its bounding-box centre.

Rotation angles are degrees about the fixed world axes x, then y, then z
(docs/config.md), i.e. R = Rz Ry Rx acting on column vectors.
"""
from __future__ import annotations

import numpy as np

from ..rotations import Y_UP_TO_Z_UP, rotation_matrix

__all__ = ["Y_UP_TO_Z_UP", "bounding_box_center", "place", "place_frames", "rotation_matrix"]


def bounding_box_center(points: np.ndarray) -> np.ndarray:
    return 0.5 * (points.min(axis=0) + points.max(axis=0))


def place(points: np.ndarray, rotation, center) -> np.ndarray:
    """Rotate ``points`` (n, 3) and translate so their bounding-box centre is ``center``."""
    rotated = points @ rotation_matrix(rotation).T
    return rotated + (np.asarray(center, dtype=np.float64) - bounding_box_center(rotated))


def place_frames(frames: np.ndarray, rotation, *, center=None, translation=None) -> np.ndarray:
    """One rigid placement of every frame of a sequence (k, n, 3), computed
    from frame 0: rotate about frame 0's bounding-box centre, then move frame
    0's bounding-box centre to ``center`` or add ``translation`` (at most one
    of them).  A zero rotation and no move leave the frames bit for bit."""
    if center is not None and translation is not None:
        raise ValueError("place_frames: give center or translation, not both")
    placed = np.asarray(frames, dtype=np.float64)
    if np.any(np.asarray(rotation, dtype=np.float64) != 0.0):
        pivot = bounding_box_center(placed[0])
        placed = (placed - pivot) @ rotation_matrix(rotation).T + pivot
    if center is not None:
        placed = placed + (np.asarray(center, dtype=np.float64) - bounding_box_center(placed[0]))
    elif translation is not None:
        placed = placed + np.asarray(translation, dtype=np.float64)
    return placed
