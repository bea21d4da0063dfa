"""Specimen meshes of the fabric tests, as arrays (points, triangles).

The drape specimen is a disc meshed in concentric rings, with one ring
exactly on the clamp circle so that the clamp holds whole rings: the
clamped region is then a disc of exactly the standard's size at every
resolution.  Ring k of radius r_k carries round(2 pi r_k / h) vertices
(at least 6), every other ring turned by half a spacing; a Delaunay
triangulation of the points gives well-shaped triangles, angles 41-91 deg
(the rings' convex hull is the disc's outline, so no triangle leaves the
disc).  Their sides line up along rings and spokes, though, and the
per-hinge bending models are not the plate on such a mesh: its hinge-star
residual (physics/hinge_consistency.py) is 0.43-0.46 at h = 10 to 5 mm,
where the Peirce strips with 0.41-0.49 bend 1-4 % short in bending length
(docs/fidelity.md).  A specimen meshed by the panel mesher would need the
clamp circle as a hole in Gmsh's outline; not done.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import Delaunay


def ring_radii(radius: float, clamp_radius: float, h: float) -> np.ndarray:
    """Ring radii from 0 to ``radius`` at spacing ~h, one ring on ``clamp_radius``."""
    inner = max(1, int(round(clamp_radius / h)))
    outer = max(1, int(round((radius - clamp_radius) / h)))
    return np.concatenate([np.linspace(0.0, clamp_radius, inner + 1),
                           np.linspace(clamp_radius, radius, outer + 1)[1:]])


def disc(radius: float, clamp_radius: float, h: float) -> tuple[np.ndarray, np.ndarray]:
    """(points (n, 3) in the z = 0 plane, centred on the origin; triangles (m, 3)
    counter-clockwise seen from +z)."""
    pts = [np.zeros((1, 2))]
    for k, r in enumerate(ring_radii(radius, clamp_radius, h)[1:], start=1):
        count = max(6, int(round(2.0 * np.pi * r / h)))
        phi = (np.arange(count) + 0.5 * (k % 2)) * (2.0 * np.pi / count)
        pts.append(r * np.column_stack([np.cos(phi), np.sin(phi)]))
    p2 = np.concatenate(pts)
    tri = Delaunay(p2).simplices.astype(np.int64)
    a, b, c = p2[tri[:, 0]], p2[tri[:, 1]], p2[tri[:, 2]]
    cw = ((b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0]) < 0.0
    tri[cw] = tri[cw][:, [0, 2, 1]]
    return np.column_stack([p2, np.zeros(len(p2))]), tri


def write_obj(path: str, points: np.ndarray, triangles: np.ndarray) -> None:
    with open(path, "w", encoding="ascii") as f:
        f.write("".join(f"v {x:.17g} {y:.17g} {z:.17g}\n" for x, y, z in points))
        f.write("".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in triangles))
