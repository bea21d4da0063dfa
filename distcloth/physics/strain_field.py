"""Per-triangle strain for the result file: the largest principal engineering
strain (principal stretch - 1) of each linear triangle, from its rest shape.

With rest edges E1, E2 and current edges e1, e2 of a triangle, A and B the
2x2 Gram matrices of the rest and the current edges (A_ij = Ei . Ej,
B_ij = ei . ej) and A = L L^T (Cholesky), C = L^-1 B L^-T is F^T F for the
deformation gradient F of the triangle in an orthonormal in-plane rest
frame; its larger eigenvalue is the squared largest principal stretch.  So
only L^-1 is kept per triangle and no 3-D frame is built.  (The closed form
through det(B - l A) = 0 loses half the digits where the two stretches are
equal, an unstrained triangle among them; the symmetric 2x2 C does not.)
This is the measure the FE membrane's ``max_strain`` reports (stvk, corotated and tabulated laws alike), per triangle; for a
mass-spring cloth it is the same geometric measure of its triangles.  Negative
where the triangle is compressed in both directions; NaN for a rest triangle
of zero area.
"""
from __future__ import annotations

import numpy as np


def _gram(corners: np.ndarray) -> np.ndarray:
    """(m, 3) [e1.e1, e2.e2, e1.e2] of triangles given as (m, 3, 3) corners."""
    e1 = corners[:, 1] - corners[:, 0]
    e2 = corners[:, 2] - corners[:, 0]
    return np.stack([np.einsum("ij,ij->i", e1, e1), np.einsum("ij,ij->i", e2, e2),
                     np.einsum("ij,ij->i", e1, e2)], axis=1)


def rest_metric(rest_corners: np.ndarray) -> np.ndarray:
    """(m, 3) [1/l11, -l21/(l11 l22), 1/l22]: the inverse of the Cholesky factor
    L of each rest Gram matrix, from (m, 3, 3) rest corners, computed once;
    NaN for a triangle of zero area."""
    a11, a22, a12 = _gram(np.asarray(rest_corners, dtype=np.float64).reshape(-1, 3, 3)).T
    with np.errstate(divide="ignore", invalid="ignore"):
        l11 = np.sqrt(a11)
        l21 = a12 / l11
        l22 = np.sqrt(np.maximum(a22 - l21 * l21, 0.0))
        out = np.stack([1.0 / l11, -l21 / (l11 * l22), 1.0 / l22], axis=1)
    out[~np.all(np.isfinite(out), axis=1)] = np.nan
    return out


def principal_strain(corners: np.ndarray, metric: np.ndarray) -> np.ndarray:
    """(m,) largest principal stretch - 1 of triangles with current corners
    (m, 3, 3) and ``metric`` = rest_metric(rest corners) (see the module)."""
    m11, m21, m22 = metric.T
    b11, b22, b12 = _gram(np.asarray(corners, dtype=np.float64).reshape(-1, 3, 3)).T
    c11 = m11 * m11 * b11
    c12 = m11 * (m21 * b11 + m22 * b12)
    c22 = m21 * m21 * b11 + 2.0 * m21 * m22 * b12 + m22 * m22 * b22
    lam = 0.5 * (c11 + c22) + np.hypot(0.5 * (c11 - c22), c12)
    return np.sqrt(np.maximum(lam, 0.0)) - 1.0
