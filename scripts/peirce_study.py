#!/usr/bin/env python3
"""Peirce cantilever (ASTM D1388) for every bending model, mesh kind and size.

A 25 mm strip (0.1 kg/m^2, B = 1e-4 N.m, nearly inextensible membrane)
overhangs a clamp by 0.8, 1.0 and 1.2 times L*, the overhang at which the
exact heavy elastica's chord is at 41.5 deg (the standard's angle); at
equilibrium the chord angle from the clamp edge to the tip gives the bending
length c = L (cos(theta/2) / (8 tan theta))^(1/3) and the flexural rigidity
G = w c^3 (w = rho g).  Each is compared with the same formula applied to the
exact heavy elastica, nominal (clamp at x = 0) and for the discrete clamp
(clamped at -h/2, unloaded over the first h: tests/test_elastica.py).  Setup
and helpers: tests/peirce.py.  Prints one Markdown table.

    .venv/bin/python scripts/peirce_study.py [--spacings 0.01 0.005 0.0025] [--fractions 0.8 1 1.2]
        [--kinds regular] [--models dihedral_shell] [--jump-gamma 0]
"""
from __future__ import annotations

import argparse
import os
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests"))
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--spacings", type=float, nargs="+", default=[0.01, 0.005, 0.0025])
    ap.add_argument("--fractions", type=float, nargs="+", default=[0.8, 1.0, 1.2])
    ap.add_argument("--kinds", nargs="+", default=None)
    ap.add_argument("--models", nargs="+", default=None, help="bending models to run")
    ap.add_argument("--jump-gamma", type=float, default=None,
                    help="study knob: the shell models' curvature-jump weight (default JUMP_GAMMA)")
    args = ap.parse_args(sys.argv[1:])
    sys.argv[1:] = []                      # PETSc reads the command line
    import peirce as p
    from distcloth.simulation import SimulationError
    kinds = args.kinds or p.MESH_KINDS
    if args.jump_gamma is not None:
        import distcloth.physics.terms as terms
        terms.JUMP_GAMMA = args.jump_gamma
        print(f"curvature-jump weight gamma = {args.jump_gamma:g}")
    models = [m for m in p.MODELS if args.models is None or m[1] in args.models]
    t0 = time.time()
    print(f"L* = {p.astm_overhang() * 1e3:.2f} mm (w L*^3 / B = "
          f"{p.WEIGHT * p.astm_overhang() ** 3 / p.B_STRIP:.3f}), B = {p.B_STRIP:g} N.m, "
          f"w = {p.WEIGHT:.4f} N/m^2, width {p.WIDTH * 1e3:g} mm\n")
    print("| model | mesh | h (mm) | L / L* | chord ° | exact ° | discrete-clamp exact ° "
          "| c mm | c exact mm | c error | c error vs discrete clamp | G µN·m | G exact µN·m "
          "| residual / weight |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for model, bending in models:
        name = "mass-spring + flexion" if model == "mass_spring" else f"FE + {bending}"
        for kind in kinds:
            if bending == "grid_lines" and kind not in ("regular", "alternating"):
                continue                           # grids only
            for h in args.spacings:
                for frac in args.fractions:
                    try:
                        r = p.peirce_row(frac, h, kind, model, bending)
                    except SimulationError as exc:
                        print(f"| {name} | {kind} | {h * 1e3:g} | {frac:g} | refused: {exc} "
                              "|  |  |  |  |  |  |  |  |  |", flush=True)
                        continue
                    if r["c"] != r["c"]:           # NaN: the strip hangs past vertical
                        print(f"| {name} | {kind} | {h * 1e3:g} | {frac:g} | {r['angle']:.2f} "
                              f"| {r['exact_angle']:.2f} | {r['clamp_angle']:.2f} | past vertical "
                              f"| {r['c_exact'] * 1e3:.2f} |  |  |  | {r['G_exact'] * 1e6:.1f} "
                              f"| {r['residual']:.0e} |", flush=True)
                        continue
                    print(f"| {name} | {kind} | {h * 1e3:g} | {frac:g} | {r['angle']:.2f} "
                          f"| {r['exact_angle']:.2f} | {r['clamp_angle']:.2f} "
                          f"| {r['c'] * 1e3:.2f} | {r['c_exact'] * 1e3:.2f} "
                          f"| {100 * r['c_error']:+.2f} % | {100 * r['c_error_clamp']:+.2f} % "
                          f"| {r['G'] * 1e6:.1f} | {r['G_exact'] * 1e6:.1f} "
                          f"| {r['residual']:.0e} |", flush=True)
    print(f"\nwall {time.time() - t0:.0f} s")


if __name__ == "__main__":
    main()
