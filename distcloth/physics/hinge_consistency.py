"""How far a mesh is from the ones on which per-hinge bending is the plate.

For a small bend of a flat hinge by a curvature tensor K, the hinge angle is
c . kappa with kappa = (K_uu, K_vv, sqrt2 K_uv) and c from the rest geometry
(``bending_shell``'s jump weights: exact for every quadratic surface), so a
vertex star's share of the per-hinge energy sum_h 1/2 C_HINGE B |e|^2/A_h
theta_h^2 is kappa^T S kappa with S = sum over the star's hinges of half of
1/2 kb c c^T.  Cloth bends without stretching, and for such bends det K = 0;
the quadratic forms that vanish on all of them are the multiples of
N = [[0, 1, 0], [1, 0, 0], [0, 0, -1]] (kappa^T N kappa = 2 det K).  So the
hinge sum is the plate energy B/2 |K|^2 (bending Poisson ratio 0) on every
stretch-free bend iff each star's S is B/2 A_v I modulo N: five conditions
per interior vertex (docs/mesh_independence.md).

The equilateral mesh meets them with the calibrated C_HINGE; right-angled
grids cannot (a strip bent along a grid axis relaxes its diagonal hinges by
twisting).  ``star_residual`` is the RMS of the five conditions over the
interior vertices, relative to B A_v: measured on the Peirce strips (tests/
test_peirce.py, docs/fidelity.md) it is 0.13-0.24 on the garment panel
mesher's Frontal-Delaunay meshes, where the per-hinge models give the
bending length within 1.5 %, and 0.41-0.56 on jittered-lattice Delaunay
meshes, where they are 1.3-4.1 % short.  ``POOR_STAR_RESIDUAL`` separates
the two.

Curved rest shapes: each star is measured in its vertex's tangent plane (the
area-weighted normal), the hinge points projected onto it; exact for flat
meshes, an estimate for curved ones (the conditions are about the local
geometry only).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .bending import C_HINGE, hinges
from .bending_shell import hinge_jump_weights

SQ2 = np.sqrt(2.0)
N_HAT = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]]) / np.sqrt(3.0)

POOR_STAR_RESIDUAL = 0.3
"""Above this star residual, per-hinge bending is measurably short (scene note)."""


def sym_basis_modulo_n() -> np.ndarray:
    """An orthonormal basis (Frobenius) (5, 3, 3) of the symmetric 3x3 matrices
    orthogonal to N."""
    basis = []
    for i in range(3):
        e = np.zeros((3, 3))
        e[i, i] = 1.0
        basis.append(e)
    for i, j in ((0, 1), (0, 2), (1, 2)):
        e = np.zeros((3, 3))
        e[i, j] = e[j, i] = 1.0 / SQ2
        basis.append(e)
    flat = np.array([(b - np.sum(b * N_HAT) * N_HAT).ravel() for b in basis])
    return np.linalg.svd(flat)[2][:5].reshape(5, 3, 3)


def _vertex_frames(x: np.ndarray, triangles: np.ndarray):
    """Unit tangent bases (nv, 2, 3) from area-weighted vertex normals, and the
    lumped vertex areas (nv,)."""
    t = x[triangles]
    cross = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    nv = x.shape[0]
    normal = np.zeros((nv, 3))
    for k in range(3):
        np.add.at(normal, triangles[:, k], cross)
    length = np.linalg.norm(normal, axis=1)
    normal = normal / np.where(length > 0, length, 1.0)[:, None]
    # any vector not parallel to the normal gives the first tangent
    helper = np.where(np.abs(normal[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    t1 = np.cross(normal, helper)
    t1 /= np.linalg.norm(t1, axis=1)[:, None]
    t2 = np.cross(normal, t1)
    area = np.bincount(triangles.ravel(), np.repeat(0.5 * np.linalg.norm(cross, axis=1) / 3.0, 3),
                       nv)
    return np.stack([t1, t2], axis=1), area


def star_conditions(x_rest, triangles, hinge=None):
    """(G, rhs, interior): for hinge stiffness scales s (one per hinge), the
    residual of the five conditions per interior vertex is G @ s - rhs,
    relative to B A_v (B drops out).  ``hinge`` defaults to ``hinges(triangles)``."""
    x = np.asarray(x_rest, dtype=np.float64)
    tri = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    hinge = hinges(tri) if hinge is None else np.asarray(hinge, dtype=np.int64)
    frames, vertex_area = _vertex_frames(x, tri)
    nv, nh = x.shape[0], hinge.shape[0]
    basis = sym_basis_modulo_n()
    rows, vals = [], []
    for end in (0, 1):
        v = hinge[:, end]
        # the hinge's four points in the tangent plane of the star's centre
        pts = [np.c_[np.einsum("hj,hkj->hk", x[hinge[:, a]] - x[v], frames[v]), np.zeros(nh)]
               for a in range(4)]
        w = hinge_jump_weights(*pts)
        M = sum(w[:, a, None, None] * pts[a][:, :2, None] * pts[a][:, None, :2] for a in range(4))
        c = 0.5 * np.stack([M[:, 0, 0], M[:, 1, 1], SQ2 * M[:, 0, 1]], axis=1)
        e = pts[1] - pts[0]
        area = 0.5 * (np.abs(np.cross(e, pts[2] - pts[0])[:, 2])
                      + np.abs(np.cross(pts[3] - pts[0], e)[:, 2]))
        kb = C_HINGE * np.einsum("ij,ij->i", e, e) / area             # per unit B
        s5 = np.einsum("kij,hi,hj->hk", basis, c, c) * kb[:, None]
        rows.append(5 * v[:, None] + np.arange(5))
        vals.append(0.5 * s5 / vertex_area[v, None])
    cols = np.tile(np.repeat(np.arange(nh), 5), 2)
    G = sp.csr_matrix((np.concatenate(vals).ravel(), (np.concatenate(rows).ravel(), cols)),
                      shape=(5 * nv, nh))
    edges = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
    unique, count = np.unique(edges, axis=0, return_counts=True)
    interior = np.ones(nv, dtype=bool)
    interior[unique[count == 1].ravel()] = False
    keep = np.flatnonzero(np.repeat(interior, 5))
    rhs = np.tile(np.einsum("kij,ij->k", basis, 0.5 * np.eye(3)), nv)
    return G[keep], rhs[keep], interior


def star_residual(x_rest, triangles) -> float:
    """RMS over interior vertices of the five star conditions with the
    calibrated weights (0 on the equilateral mesh; nan without interior
    vertices)."""
    G, rhs, interior = star_conditions(x_rest, triangles)
    if not interior.any():
        return float("nan")
    r = G @ np.ones(G.shape[1]) - rhs
    return float(np.linalg.norm(r) / np.sqrt(interior.sum()))
