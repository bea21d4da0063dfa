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
and wall time (one rank).  "Converged" is Newton to 1e-10 (at most 40
iterations), "one step" the single linearised step (before the energy-momentum
change, the default of every implicit scheme), "the defaults" the scheme's
own now (at most 30 iterations to 1e-8); the linear solves use ksp_rtol 1e-12.  Table 2: observed order, log2 of the ratio of
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

CASES = (  # label, integrator, energy_momentum, Newton iterations, strain, bending, tolerance[,
    #         more time: keys]
    ("midpoint, converged", "implicit_midpoint", False, 40, "stvk", "isometric", 1e-10),
    ("midpoint + discrete gradient, converged", "implicit_midpoint", True, 40, "stvk",
     "isometric", 1e-10),
    ("Newmark, converged", "newmark", False, 40, "stvk", "isometric", 1e-10),
    ("Newmark + discrete gradient, converged", "newmark", True, 40, "stvk", "isometric", 1e-10),
    ("midpoint, one step (the old default)", "implicit_midpoint", False, 1, "stvk", "isometric",
     1e-10),
    ("midpoint + discrete gradient, the defaults (at most 30 iterations to 1e-8)",
     "implicit_midpoint", True, None, "stvk", "isometric", 1e-8),
    ("the defaults, adaptive and require_newton_convergence", "implicit_midpoint", True, None,
     "stvk", "isometric", 1e-8, {"adaptive": True, "require_newton_convergence": True}),
    ("midpoint + discrete gradient, corotated", "implicit_midpoint", True, 40, "corotated",
     "isometric", 1e-10),
    ("midpoint + discrete gradient, dihedral bending", "implicit_midpoint", True, 40, "stvk",
     "dihedral", 1e-10),
)


def energy_run(h, end, integrator, em, newton, strain, bending, tol, time_keys=None):
    from distcloth.simulation import SimulationError
    sim = sheet(h, end, integrator, em, newton, strain, bending, tol, **(time_keys or {}))
    e0 = sum(sim.energies())
    change, its, failed = [], [], None
    t0 = time.perf_counter()
    while sim.state.t < end - 1e-9 * h:     # adaptive: a step may be taken as halves
        try:
            row = sim.step()
        except SimulationError:
            failed = len(its) + 1
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
    ap.add_argument("--no-orders", action="store_true", help="skip table 2")
    a = ap.parse_args()
    print(f"Swinging sheet, h = {a.step * 1e3:g} ms, {a.end:g} s\n")
    print("| scheme | largest gain | largest abs(E - E0) | at the end | Newton its / step | ms / step |")
    print("|---|---:|---:|---:|---:|---:|")
    for label, *case in CASES:
        c, its, per_step, failed = energy_run(a.step, a.end, *case)
        end = f"blow-up at step {failed}" if failed else f"{c[-1]:+.2e}"
        print(f"| {label} | {c.max():+.2e} | {np.abs(c).max():.2e} | {end} | {its:.1f} "
              f"| {per_step * 1e3:.1f} |", flush=True)
    if a.no_orders:
        return
    print("\n| scheme | observed orders (h = 10 → 5 → 2.5 → 1.25 ms) |")
    print("|---|---|")
    for integ in ("implicit_midpoint", "newmark"):
        for em in (False, True):
            p = order(integ, em)
            print(f"| {integ}{' + discrete gradient' if em else ''} | "
                  f"{', '.join(f'{x:.2f}' for x in p)} |", flush=True)


if __name__ == "__main__":
    main()
