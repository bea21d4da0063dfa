#!/usr/bin/env python3
"""Energy and order of implicit midpoint and Newmark (1/4, 1/2) on the swinging
FE sheet of tests/test_energy_momentum.py, with and without the energy-momentum
discrete gradients (time.energy_momentum; integrate/implicit.py).

    .venv/bin/python scripts/energy_conservation.py [--end 3] [--step 0.01]

A 0.5 m square, 9 x 9 vertices, St.Venant-Kirchhoff (or corotated) triangles,
E = 10 N/m, 0.1 kg/m^2, pinned at one corner, released flat under gravity,
no damping.  Table 1: the total energy E = kinetic + gravitational + elastic
over the run, as (E - E0) / |E0|: its largest gain, its largest magnitude and
its value at the end (or the step of a blow-up), Newton iterations per step
and wall time (one rank).  "Converged" is Newton to 1e-10, "one step" the
default single linearised step.  Table 2: observed order, log2 of the ratio of
successive differences of the end state at T = 0.1 s as h halves from 10 ms.
"""
from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests"))
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

from test_energy_momentum import sheet  # noqa: E402
from test_physics import gather_positions  # noqa: E402

CASES = (  # label, integrator, energy_momentum, Newton iterations, strain, bending
    ("midpoint, converged", "implicit_midpoint", False, 40, "stvk", "isometric"),
    ("midpoint + discrete gradient, converged", "implicit_midpoint", True, 40, "stvk", "isometric"),
    ("Newmark, converged", "newmark", False, 40, "stvk", "isometric"),
    ("Newmark + discrete gradient, converged", "newmark", True, 40, "stvk", "isometric"),
    ("midpoint, one step", "implicit_midpoint", True, 1, "stvk", "isometric"),
    ("midpoint + discrete gradient, corotated", "implicit_midpoint", True, 40, "corotated",
     "isometric"),
    ("midpoint + discrete gradient, dihedral bending", "implicit_midpoint", True, 40, "stvk",
     "dihedral"),
)


def energy_run(h, end, integrator, em, newton, strain, bending):
    from distcloth.simulation import SimulationError
    sim = sheet(h, end, integrator, em, newton, strain, bending)
    e0 = sum(sim.energies())
    change, its, failed = [], [], None
    t0 = time.perf_counter()
    for i in range(int(round(end / h))):
        try:
            row = sim.step()
        except SimulationError:
            failed = i + 1
            break
        change.append((row["total_energy"] - e0) / abs(e0))
        its.append(row["newton_iterations"])
    wall = time.perf_counter() - t0
    sim.destroy()
    return np.array(change), np.mean(its), wall / max(len(its), 1), failed


def order(integrator, em, T=0.1, h0=0.01, levels=4):
    ends = []
    for h in [h0 / 2 ** i for i in range(levels)]:
        sim = sheet(h, T, integrator, em)
        for _ in range(int(round(T / h))):
            sim.step()
        ends.append(gather_positions(sim))
        sim.destroy()
    d = np.array([np.abs(a - b).max() for a, b in zip(ends, ends[1:])])
    return np.log2(d[:-1] / d[1:])


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--end", type=float, default=3.0)
    ap.add_argument("--step", type=float, default=0.01)
    a = ap.parse_args()
    print(f"Swinging sheet, h = {a.step * 1e3:g} ms, {a.end:g} s\n")
    print("| scheme | largest gain | largest abs(E - E0) | at the end | Newton its / step | ms / step |")
    print("|---|---:|---:|---:|---:|---:|")
    for label, integ, em, newton, strain, bending in CASES:
        c, its, per_step, failed = energy_run(a.step, a.end, integ, em, newton, strain, bending)
        end = f"blow-up at step {failed}" if failed else f"{c[-1]:+.2e}"
        print(f"| {label} | {c.max():+.2e} | {np.abs(c).max():.2e} | {end} | {its:.1f} "
              f"| {per_step * 1e3:.1f} |", flush=True)
    print("\n| scheme | observed orders (h = 10 → 5 → 2.5 → 1.25 ms) |")
    print("|---|---|")
    for integ in ("implicit_midpoint", "newmark"):
        for em in (False, True):
            p = order(integ, em)
            print(f"| {integ}{' + discrete gradient' if em else ''} | "
                  f"{', '.join(f'{x:.2f}' for x in p)} |", flush=True)


if __name__ == "__main__":
    main()
