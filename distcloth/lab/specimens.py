"""Specimen meshes of the fabric tests, as arrays (points, triangles).

The drape specimen is a disc meshed as distcloth meshes a garment panel
(Gmsh's Frontal-Delaunay, ``garment.mesh.triangulate``), in two regions
that share the clamp circle's vertices: the clamped disc, and the annulus
around it with that circle as a hole.  The clamp then holds exactly the
standard's disc at every resolution, and the triangles are near-equilateral,
on which the per-hinge bending models (the default on meshes) are the plate
(hinge-star residual 0.08-0.10, physics/hinge_consistency.py; the rings of
points triangulated before gave 0.43-0.46, where the Peirce strips bend
1-4 % short, docs/fidelity.md).
"""
from __future__ import annotations

import numpy as np

from ..garment.mesh import triangulate


def _circle(radius: float, h: float) -> np.ndarray:
    """A regular polygon on the circle, counter-clockwise, sides ~h (at least 6)."""
    count = max(6, int(round(2.0 * np.pi * radius / h)))
    phi = np.arange(count) * (2.0 * np.pi / count)
    return radius * np.column_stack([np.cos(phi), np.sin(phi)])


def disc(radius: float, clamp_radius: float, h: float) -> tuple[np.ndarray, np.ndarray]:
    """(points (n, 3) in the z = 0 plane, centred on the origin; triangles (m, 3)
    counter-clockwise seen from +z).  The clamp circle's vertices lie at
    ``clamp_radius`` to round-off, the outline's at ``radius``."""
    rim, clamp = _circle(radius, h), _circle(clamp_radius, h)
    outer_pts, outer_tri = triangulate(rim, h, holes=(clamp,), name="drape specimen")
    inner_pts, inner_tri = triangulate(clamp, h, name="drape specimen's clamped disc")
    # the inner mesh's first vertices are the clamp circle's, which the outer
    # mesh holds right after the rim: renumber them onto those
    shared = clamp.shape[0]
    index = np.concatenate([rim.shape[0] + np.arange(shared),
                            outer_pts.shape[0] + np.arange(inner_pts.shape[0] - shared)])
    p2 = np.concatenate([outer_pts, inner_pts[shared:]])
    tri = np.concatenate([outer_tri, index[inner_tri]])
    return np.column_stack([p2, np.zeros(len(p2))]), tri


def write_obj(path: str, points: np.ndarray, triangles: np.ndarray) -> None:
    with open(path, "w", encoding="ascii") as f:
        f.write("".join(f"v {x:.17g} {y:.17g} {z:.17g}\n" for x, y, z in points))
        f.write("".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in triangles))
