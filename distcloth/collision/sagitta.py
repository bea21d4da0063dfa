"""How close a cloth triangle resting on a curved body comes to the body's
own vertices and edges: arrays in, arrays out.

The distance-field contact (``response.py``) holds every cloth *vertex* at
the offset d from a body.  A cloth triangle of edge L whose corners rest at
d over a body of radius R sags toward it between them: an edge's middle
lies L^2 / (8 R) closer, an equilateral face's centre (circumradius
L / sqrt 3) L^2 / (6 R) (3 mm for 3 cm edges over a 5 cm arm).  The
triangle pipeline (``impulses.py``) measures distances between primitives,
not vertices, and a repulsion that pushed such a triangle back to d from the
body's vertices lifted it every step, for the contact to set its corners
back on the next: a pump (seams on a body stayed 2 to 5 mm open, draped
garments never stopped moving).  So each body vertex gets the distance its
pipeline pairs keep: d minus the face sagitta of the cloth's longest edge
over the body's sharpest convex curvature there, never below a floor that keeps
the CCD's margin (a flat floor or ramp keeps the whole d, which a pile on it
needs).
"""
from __future__ import annotations

import numpy as np

from .imagespace import vertex_normals
from .proximity import mesh_edges


def convex_curvature(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """(n,) the largest convex normal curvature (1/m, >= 0) at each vertex of
    an outward-oriented mesh, over its edges: kappa_ij = (n_i - n_j).(x_i -
    x_j) / |x_i - x_j|^2, the turning of the normal along the edge (exactly
    1/R on a sphere; the two normals' estimation errors largely cancel,
    which the one-normal form 2 n_i.(x_i - x_j) / |x_i - x_j|^2 does not on
    short edges)."""
    x = np.asarray(vertices, dtype=np.float64)
    n = vertex_normals(x, triangles)
    e = mesh_edges(triangles)
    d = x[e[:, 0]] - x[e[:, 1]]
    kappa = np.einsum("ij,ij->i", n[e[:, 0]] - n[e[:, 1]], d) / np.maximum(
        np.einsum("ij,ij->i", d, d), 1e-300)
    out = np.zeros(x.shape[0])
    np.maximum.at(out, e[:, 0], kappa)
    np.maximum.at(out, e[:, 1], kappa)
    return out


def body_clearance(vertices, triangles, thickness: float, cloth_edge: float,
                   floor: float) -> np.ndarray:
    """(n,) the distance cloth primitives keep from each body vertex in the
    triangle pipeline: ``thickness`` minus the face sagitta cloth_edge^2 kappa / 6,
    at least ``floor``."""
    sag = cloth_edge ** 2 * convex_curvature(vertices, triangles) / 6.0
    return np.clip(thickness - sag, floor, thickness)
