"""Points attached to a moving triangle mesh (EG07 tutorial, Part 2 §2.3:
skin-following regions): each point keeps its offset in the orthonormal
frame of one triangle, taken at the barycentric point where it was
attached.  A triangle that moves rigidly carries its points rigidly; one
that stretches carries them at the same height above it and the same
tangential offset, measured along its first edge and its normal."""
from __future__ import annotations

import numpy as np


def triangle_frames(x: np.ndarray, triangles: np.ndarray, face: np.ndarray,
                    weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(origin (k, 3), frame (k, 3, 3)) of the triangles ``face`` of the mesh
    (x, triangles): the origin is the barycentric point ``weights``, the frame's
    rows the unit first edge e1, n x e1 and the unit normal n (orientation as
    the triangle's corners)."""
    corners = x[triangles[face]]                       # (k, 3, 3)
    origin = np.einsum("kc,kci->ki", weights, corners)
    e1 = corners[:, 1] - corners[:, 0]
    n = np.cross(e1, corners[:, 2] - corners[:, 0])
    e1 = e1 / np.linalg.norm(e1, axis=1, keepdims=True)
    n = n / np.linalg.norm(n, axis=1, keepdims=True)
    return origin, np.stack([e1, np.cross(n, e1), n], axis=1)


def attach(points: np.ndarray, x: np.ndarray, triangles: np.ndarray, face: np.ndarray,
           weights: np.ndarray) -> np.ndarray:
    """(k, 3) offsets of ``points`` in their triangles' frames (triangle_frames)."""
    origin, frame = triangle_frames(x, triangles, face, weights)
    return np.einsum("kij,kj->ki", frame, np.asarray(points, dtype=np.float64) - origin)


def follow(x: np.ndarray, triangles: np.ndarray, face: np.ndarray, weights: np.ndarray,
           offsets: np.ndarray) -> np.ndarray:
    """(k, 3) where the attached points are on the mesh at positions ``x``."""
    origin, frame = triangle_frames(x, triangles, face, weights)
    return origin + np.einsum("kji,kj->ki", frame, offsets)
