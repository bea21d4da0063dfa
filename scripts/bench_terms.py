#!/usr/bin/env python3
"""Cost of the force-term kernels alone, one process, no MPI and no PETSc.

* FE membrane (distcloth/physics/membrane_fem.py) on a 316 x 316-cell grid
  (199,712 triangles): forces alone and forces + Hessian blocks, for both
  strain models, with and without the per-element PSD projection, on a
  gently stretched state (2 % + noise of 3 % of an edge) and a rough one
  (noise of 30 % of an edge); and the discrete-gradient force of a step
  between the state and a copy moved by noise of 1 % of an edge
  (``evaluate_between`` without the Jacobian: the energy-momentum midpoint's
  residual, integrate/implicit.py);
* hinge bending (distcloth/physics/bending.py) on a 320 x 320-cell grid
  (306,560 hinges) rolled onto a cylinder with noise: ``evaluate`` (forces +
  Jacobian), ``stiffness_product``, ``add_to_system`` and ``energy`` of the
  isometric model and of the dihedral model with its Gauss-Newton and its
  exact Hessian.

Each figure is the mean of ``--reps`` calls after one warm-up call (numba
compilation).  Prints two Markdown tables.

    .venv/bin/python scripts/bench_terms.py [--reps 3] [--only membrane|bending]
"""
from __future__ import annotations

import argparse
import itertools
import platform
import time

import numpy as np

from distcloth.linalg.pattern import BlockPattern
from distcloth.physics.bending import DihedralBendingTerm, IsometricBendingTerm, hinges
from distcloth.physics.membrane_fem import MembraneFEMTerm, orthotropic_plane_stress


def split_grid(nx, ny, lx=1.0, ly=1.0, interleave=False):
    """Flat (nx+1) x (ny+1) vertex sheet in z = 0, each cell cut along one
    diagonal (consistent winding, normals +z).  Triangle order: all first
    halves of the cells, then all second halves, or with ``interleave`` the
    two halves of each cell in turn (the orders the unit tests' meshes use)."""
    u, v = np.meshgrid(np.linspace(0, lx, nx + 1), np.linspace(0, ly, ny + 1), indexing="ij")
    x = np.stack([u.ravel(), v.ravel(), np.zeros(u.size)], axis=1)
    idx = np.arange((nx + 1) * (ny + 1)).reshape(nx + 1, ny + 1)
    a, b = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel()
    c, d = idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    first, second = np.column_stack([a, b, c]), np.column_stack([a, c, d])
    if interleave:
        tris = np.stack([first, second], axis=1).reshape(-1, 3)
    else:
        tris = np.vstack([first, second])
    return x, tris.astype(np.int64)


def mean_ms(call, reps):
    t0 = time.perf_counter()
    for _ in range(reps):
        call()
    return (time.perf_counter() - t0) / reps * 1e3


def membrane(reps):
    x0, tris = split_grid(316, 316)                       # 199,712 triangles
    n = len(x0)
    rng = np.random.default_rng(0)
    # orthotropic, symmetric: E_weft nu_warp = 20 * 0.1 = nu_weft E_warp = 0.4 * 5
    C = orthotropic_plane_stress(20.0, 5.0, 0.4, 0.1, 3.0)
    states = {"stretched 2 % + noise 3 % of an edge": 1.02 * x0 + 1e-4 * rng.normal(size=x0.shape),
              "rough: noise 30 % of an edge": 1.02 * x0 + 1e-3 * rng.normal(size=x0.shape)}
    print(f"FE membrane, {len(tris)} triangles, mean of {reps} calls (ms):\n")
    print("| state | strain | PSD projection | forces | forces + Hessian | discrete gradient |")
    print("|---|---|---|---:|---:|---:|")
    for (label, x), model, project in itertools.product(states.items(), ("stvk", "corotated"),
                                                         (False, True)):
        term = MembraneFEMTerm(tris, x0, None, C, model, np.ones(len(tris)), project=project)
        f = np.zeros((n, 3))
        term.evaluate(x, None, f, True)                   # compile, warm up
        if not np.isfinite(f).all():
            raise SystemExit(f"membrane {model}: non-finite forces")
        t_f = mean_ms(lambda: term.evaluate(x, None, np.zeros((n, 3)), False), reps)
        t_h = mean_ms(lambda: term.evaluate(x, None, np.zeros((n, 3)), True), reps)
        x1 = x + 3e-5 * rng.normal(size=x.shape)
        term.evaluate_between(x, x1, None, np.zeros((n, 3)), False)      # warm up
        t_g = mean_ms(lambda: term.evaluate_between(x, x1, None, np.zeros((n, 3)), False), reps)
        print(f"| {label} | {model} | {'yes' if project else 'no'} | {t_f:.1f} | {t_h:.1f} "
              f"| {t_g:.1f} |")
    print()


def bending(reps):
    x, tris = split_grid(320, 320, interleave=True)
    hg = hinges(tris)                                      # 3 * 320^2 - 2 * 320 = 306,560
    n = len(x)
    s = x[:, 0]                                            # roll onto a cylinder, R = 0.7 m
    y = x.copy()
    y[:, 0], y[:, 2] = 0.7 * np.sin(s / 0.7), 0.7 * (1.0 - np.cos(s / 0.7))
    y += 1e-3 * np.random.default_rng(0).normal(size=x.shape)
    pattern = BlockPattern(n, n, [hg])
    w = np.ones((n, 3))
    terms = (("isometric", IsometricBendingTerm(hg, x, 1.0, 1.0)),
             ("dihedral (Gauss-Newton)", DihedralBendingTerm(hg, x, 1.0, 1.0)),
             ("dihedral (exact Hessian)", DihedralBendingTerm(hg, x, 1.0, 1.0, hessian="exact")))
    print(f"Hinge bending, {hg.shape[0]} hinges, mean of {reps} calls (ms):\n")
    print("| model | evaluate | stiffness_product | add_to_system | energy |")
    print("|---|---:|---:|---:|---:|")
    for label, term in terms:
        term.bind(pattern)
        data = pattern.new_values()
        f = np.zeros_like(y)
        term.evaluate(y, y, f, True)                       # compile, warm up
        term.stiffness_product(w, f)
        term.add_to_system(data, 1.0, 0.0)
        term.energy(y)
        if not np.isfinite(f).all():
            raise SystemExit(f"bending {label}: non-finite forces")
        times = [mean_ms(lambda: term.evaluate(y, y, f, True), reps),
                 mean_ms(lambda: term.stiffness_product(w, f), reps),
                 mean_ms(lambda: term.add_to_system(data, 1.0, 0.0), reps),
                 mean_ms(lambda: term.energy(y), reps)]
        print(f"| {label} | " + " | ".join(f"{t:.1f}" for t in times) + " |")
    print()


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--reps", type=int, default=3, help="timed calls per figure (default 3)")
    ap.add_argument("--only", choices=("membrane", "bending"), default=None)
    args = ap.parse_args()
    print(f"{platform.node()}: {platform.platform()}, Python {platform.python_version()}, "
          f"numpy {np.__version__}\n")
    if args.only in (None, "membrane"):
        membrane(args.reps)
    if args.only in (None, "bending"):
        bending(args.reps)


if __name__ == "__main__":
    main()
