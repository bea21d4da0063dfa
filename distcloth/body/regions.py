"""Which parts of a body a garment can reach (EG07 tutorial, Part 2 §2.3:
restrict collision detection to the regions that can collide).

A body part is a bone; its skin is the vertices it dominates (their
largest skinning weight).  The parts a garment can reach are the bones
dominating a body vertex within ``reach`` of the garment where it starts;
the body's triangles that stay in its contact are those with a corner
dominated by one of those bones.  (Every influence instead of the dominant
one took in the upper arms for a skirt: bone heat gives the sides of the
waist a few percent of the upper arm's weight.)  A skirt on a body in an A-pose reaches
the pelvis, spine and legs, never the arms: the arms' triangles are then
neither skinned nor refit nor searched.  ``reach`` bounds how far the
garment moves relative to the skin it starts near: a part farther than that
at the start is assumed never to touch it (a hand brushing a skirt while
the arms swing is then not seen).
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree


def dominant_bone(idx, w) -> np.ndarray:
    """(V,) each vertex's bone of largest weight."""
    return np.take_along_axis(np.asarray(idx), np.argmax(np.asarray(w), axis=1)[:, None], axis=1)[:, 0]


def reachable_bones(body_points, idx, w, garment_points, reach: float) -> np.ndarray:
    """Sorted bone indices dominating a body vertex within ``reach`` of a
    garment point (body_points (V, 3) and garment_points (n, 3) in one frame)."""
    tree = cKDTree(np.asarray(garment_points, dtype=np.float64))
    d, _ = tree.query(np.asarray(body_points, dtype=np.float64), distance_upper_bound=reach)
    return np.unique(dominant_bone(idx, w)[np.isfinite(d)])


def region_triangles(triangles, idx, w, bones) -> np.ndarray:
    """(T,) bool: triangles with a corner dominated by one of ``bones``."""
    return np.isin(dominant_bone(idx, w), bones)[np.asarray(triangles)].any(axis=1)


def submesh(triangles, keep) -> tuple[np.ndarray, np.ndarray]:
    """(vertex ids (m,), triangles re-indexed into them) of the kept triangles."""
    tri = np.asarray(triangles)[keep]
    ids, inverse = np.unique(tri, return_inverse=True)
    return ids, inverse.reshape(-1, 3)
