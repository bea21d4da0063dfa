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

from distcloth.physics.hinge_consistency import star_conditions  # noqa: E402


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
