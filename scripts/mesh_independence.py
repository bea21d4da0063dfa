"""Mesh independence of a bending-dominated drape measure on irregular meshes.

The measure is the static tip deflection delta / L of the heavy cantilever of
tests/test_elastica.py (L = 0.2 m, strip width 0.02 m, 0.1 kg/m^2, q L^3 / B = 3,
membrane E = 1e3 N/m) on jittered Delaunay meshes of spacing h, for the FE
membrane with the per-triangle shell bending (dihedral_shell, the default, and
isometric_shell) and the per-hinge dihedral and isometric sums and for mass-spring with
flexion springs across interior edges.  Prints a Markdown table: each model's
delta / L, its relative change from the previous (coarser) resolution, and the
heavy elastica, nominal (clamp at x = 0) and clamp-corrected (the discrete
clamp's O(h) offset, see tests/test_elastica.py).

    scripts/mpiexec.sh 2 .venv/bin/python scripts/mesh_independence.py [--seeds 0 1] [--load 3]
"""
from __future__ import annotations

import argparse
import os
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests"))
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

MODELS = (("FE + dihedral_shell", "fem", "dihedral_shell"),
          ("FE + isometric_shell", "fem", "isometric_shell"),
          ("FE + dihedral", "fem", "dihedral"), ("FE + isometric", "fem", "isometric"),
          ("mass-spring + flexion", "mass_spring", "flexion"))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--spacings", type=float, nargs="+", default=[0.01, 0.005, 0.0025, 0.00125])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0])
    ap.add_argument("--load", type=float, default=3.0, help="q L^3 / B")
    args = ap.parse_args()
    from mpi4py import MPI
    import numpy as np
    import test_elastica as te
    rank = MPI.COMM_WORLD.Get_rank()
    B = te.stiffness_for(args.load)
    nominal = te.heavy_elastica(te.Q, B, te.L) / te.L
    rows = []
    t0 = time.time()
    for h in args.spacings:
        values, worst = [], []
        for _, model, bending in MODELS:
            runs = [te.cantilever(args.load, ("delaunay", h, s), bending, model) for s in args.seeds]
            values.append(float(np.mean([r[0] for r in runs])))
            worst.append(max(r[2] for r in runs))
        corrected = te.heavy_elastica(te.Q, B, te.L, clamp=h / 2, unloaded=h) / te.L
        nv = te.strip_mesh(h)[0].shape[0]
        rows.append((h, nv, values, corrected, worst))
    if rank != 0:
        return
    print(f"q L^3 / B = {args.load:g}, seeds {args.seeds}, elastica delta/L = {nominal:.5f} "
          f"(linear theory {args.load / 8:.5f}); wall {time.time() - t0:.1f} s on "
          f"{MPI.COMM_WORLD.Get_size()} ranks\n")
    head = "| h (m) | vertices | " + " | ".join(f"{m[0]} δ/L | change" for m in MODELS)
    head += " | elastica, clamp-corrected | FE + dihedral_shell error vs corrected | max residual FE / mass-spring |"
    print(head)
    print("|" + "---:|" * (2 + 2 * len(MODELS) + 3))
    prev = None
    for h, nv, values, corrected, worst in rows:
        cells = [f"{h:g}", str(nv)]
        for k, v in enumerate(values):
            change = "" if prev is None else f"{(v - prev[k]) / prev[k]:+.2%}"
            cells += [f"{v:.5f}", change]
        cells += [f"{corrected:.5f}", f"{values[0] / corrected - 1:+.2%}", f"{max(worst[:-1]):.0e} / {worst[-1]:.0e}"]
        print("| " + " | ".join(cells) + " |")
        prev = values


if __name__ == "__main__":
    main()
