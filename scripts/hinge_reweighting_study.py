#!/usr/bin/env python3
"""Can per-hinge weights make the dihedral sum right on irregular meshes?

For a small bend of a flat hinge by a curvature tensor K, the hinge angle is
c . kappa with kappa = (K_uu, K_vv, sqrt2 K_uv) and c from the rest geometry
(``bending_shell``'s jump weights: exact for every quadratic surface), so a
vertex star's energy is kappa^T S kappa with S = sum of half of each incident
hinge's kb c c^T.  Cloth bends without stretching, and for such bends K has
zero determinant; the quadratic forms that vanish on all of them are the
multiples of N = [[0, 1, 0], [1, 0, 0], [0, 0, -1]] (kappa^T N kappa =
2 det K).  So the hinge sum is the plate energy B/2 |K|^2 on every
stretch-free bend iff each star's S is B/2 A_v I modulo N: five conditions
per interior vertex (the equilateral mesh meets them with the calibrated
weights, S = B/2 A_v (I - N/3)).

This study scales each hinge's stiffness by s_h in [0.2, 5], fitted by
bounded least squares to those conditions on the interior vertices (plus a
small pull of s towards 1), and runs the Peirce cantilever of
scripts/peirce_study.py on the Delaunay strips with and without the scales.
It prints the conditions' residual before and after the fit and the bending
length errors.  (About 10 s.)

    .venv/bin/python scripts/hinge_reweighting_study.py [--spacings 0.01 0.005 0.0025]
"""
from __future__ import annotations

import argparse
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests"))
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

SQ2 = np.sqrt(2.0)
N_HAT = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]]) / np.sqrt(3.0)


def plane_coordinates(x):
    """2-D coordinates of a flat rest shape in its best-fit plane."""
    c = x - x.mean(axis=0)
    return c @ np.linalg.svd(c, full_matrices=False)[2][:2].T


def sym_basis_modulo_n():
    """An orthonormal basis (Frobenius) of the symmetric 3x3 matrices orthogonal to N."""
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


def star_conditions(x_rest, triangles, hinge):
    """(G, rhs, interior): G @ s - rhs are the five conditions per interior
    vertex for hinge scales s, relative to B A_v (B drops out)."""
    import scipy.sparse as sp
    from distcloth.physics.bending import C_HINGE
    from distcloth.physics.bending_shell import _hinge_weights
    p = plane_coordinates(np.asarray(x_rest, dtype=np.float64))
    pts = [np.c_[p[hinge[:, a]], np.zeros(len(hinge))] for a in range(4)]
    w = _hinge_weights(*pts)
    M = sum(w[:, a, None, None] * pts[a][:, :2, None] * pts[a][:, None, :2] for a in range(4))
    c = 0.5 * np.stack([M[:, 0, 0], M[:, 1, 1], SQ2 * M[:, 0, 1]], axis=1)
    e = pts[1] - pts[0]
    area = 0.5 * (np.abs(np.cross(e, pts[2] - pts[0])[:, 2])
                  + np.abs(np.cross(pts[3] - pts[0], e)[:, 2]))
    kb = C_HINGE * np.einsum("ij,ij->i", e, e) / area             # per unit B
    basis = sym_basis_modulo_n()
    s5 = np.einsum("kij,hi,hj->hk", basis, c, c) * kb[:, None]
    nv, nh = len(p), len(hinge)
    t = p[triangles]
    tri_area = 0.5 * np.abs(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]))
    vertex_area = np.bincount(triangles.ravel(), np.repeat(tri_area / 3.0, 3), nv)
    edges = np.sort(np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]],
                                    triangles[:, [2, 0]]]), axis=1)
    unique, count = np.unique(edges, axis=0, return_counts=True)
    interior = np.ones(nv, dtype=bool)
    interior[unique[count == 1].ravel()] = False
    rows = np.concatenate([5 * hinge[:, end, None] + np.arange(5) for end in (0, 1)]).ravel()
    cols = np.tile(np.repeat(np.arange(nh), 5), 2)
    vals = np.concatenate([0.5 * s5 / vertex_area[hinge[:, end], None] for end in (0, 1)]).ravel()
    G = sp.csr_matrix((vals, (rows, cols)), shape=(5 * nv, nh))
    keep = np.flatnonzero(np.repeat(interior, 5))
    rhs = np.tile(np.einsum("kij,ij->k", basis, 0.5 * np.eye(3)), nv)
    return G[keep], rhs[keep], interior


def fit_scales(x_rest, triangles, hinge, pull=0.05, bounds=(0.2, 5.0)):
    import scipy.sparse as sp
    from scipy.optimize import lsq_linear
    G, rhs, _ = star_conditions(x_rest, triangles, hinge)
    nh = len(hinge)
    A = sp.vstack([G, np.sqrt(pull) * sp.identity(nh)]).tocsr()
    b = np.concatenate([rhs, np.sqrt(pull) * np.ones(nh)])
    s = lsq_linear(A, b, bounds=bounds, lsmr_tol="auto", max_iter=2000).x
    per_vertex = np.sqrt(len(rhs) / 5)
    return s, np.linalg.norm(G @ np.ones(nh) - rhs) / per_vertex, \
        np.linalg.norm(G @ s - rhs) / per_vertex


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--spacings", type=float, nargs="+", default=[0.01, 0.005, 0.0025])
    args = ap.parse_args(sys.argv[1:])
    sys.argv[1:] = []                      # PETSc reads the command line
    import peirce as p
    import distcloth.physics.terms as terms
    original = terms._hinge_bending
    fitted = {"on": False}

    def reweighted(cfg, model, layout, kind):
        if fitted["on"] and kind == "dihedral" and model.hinge_scale is None:
            s, before, after = fit_scales(model.rest_positions, model.triangles,
                                          model.hinge_vertices)
            fitted["line"] = (f"RMS star residual {before:.3f} -> {after:.3f}, "
                              f"scales {s.min():.2f}..{s.max():.2f} (mean {s.mean():.2f})")
            model.hinge_scale = s
        return original(cfg, model, layout, kind)

    terms._hinge_bending = reweighted
    print("| h (mm) | c error vs discrete clamp, calibrated weights | with fitted weights | fit |")
    print("|---:|---:|---:|---|")
    for h in args.spacings:
        fitted["on"] = False
        plain = p.peirce_row(1.0, h, "delaunay", "fem", "dihedral")
        fitted["on"] = True
        p.simulate.cache_clear()
        refit = p.peirce_row(1.0, h, "delaunay", "fem", "dihedral")
        print(f"| {h * 1e3:g} | {100 * plain['c_error_clamp']:+.2f} % "
              f"| {100 * refit['c_error_clamp']:+.2f} % | {fitted['line']} |", flush=True)


if __name__ == "__main__":
    main()
