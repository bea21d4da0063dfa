"""Cantilever heavy elastica: a strip clamped at one end, bending under its own weight.

Reference.  With arc length s from the clamp, theta(s) the slope angle, q = rho g
(N/m^2) and B the bending stiffness (N.m, moment per unit width per unit
curvature), moment balance per unit width gives

    B theta'' = -q (L - s) cos theta,   theta(0) = 0,  theta'(L) = 0,

tip deflection delta = int_0^L sin theta ds (scipy solve_bvp, tol 1e-10).  Small
loads give the linear cantilever delta = q L^4 / (8 B).

Simulation.  Membrane FE (StVK, nu_weft 0, E_weft 1e3 N/m: axial strain ~ qL/E
= 2e-4, negligible), hinge bending dihedral or isometric; the clamp pins the
two first vertex columns (x = -h and x = 0) so it fixes the slope; equilibrium
by backward Euler with huge steps and Newton iterations (Newton on f = 0),
checked by the free-vertex residual.  The measure is the mean z of the
free-end vertices (x = L).

Discretisation of the clamp (O(h), not an error of the bending model): the
first bending hinge sits on the clamp line x = 0 and carries the dual cell
[-h/2, h/2]; with lumped masses the load starts at x = h/2 (the pinned column's
mass is carried by the pin).  The discrete cantilever therefore has the
reference elastica with the clamp at x = -h/2 (length L + h/2) and no load on
its first h: ``heavy_elastica(q, B, L, clamp=h/2, unloaded=h)``.  For the
linear cantilever that shifts the tip by ~2h/L (10 % at h = L/20); the chain
of hinges alone (1-D, exact bending) then agrees with it to O(h^2).

Measured (L = 0.2 m, w = 0.02 m, qL^3/B = 3, elastica delta/L = 0.3396), see
docs/mesh_independence.md for the refinement table and the comments at each
test for the numbers.
"""
from __future__ import annotations

import functools
import os

import numpy as np
import pytest
from scipy.integrate import solve_bvp, solve_ivp
from scipy.optimize import brentq
from scipy.spatial import Delaunay

L, W, RHO, G = 0.2, 0.02, 0.1, 9.81
Q = RHO * G


# ------------------------------------------------------------------ reference

def heavy_elastica(q, B, length, clamp=0.0, unloaded=0.0):
    """Tip deflection (m, > 0 downwards) of the heavy elastica clamped at s = 0,
    free at s = length + clamp, carrying q (N/m^2) on s > unloaded only."""
    total = length + clamp

    def rhs(s, y):        # y = (theta, theta', deflection), theta > 0 downwards
        arm = total - np.maximum(s, unloaded)
        return np.vstack([y[1], -q * arm * np.cos(y[0]) / B, np.sin(y[0])])

    def bc(a, b):
        return np.array([a[0], b[1], a[2]])

    s = np.linspace(0.0, total, 401)
    if unloaded > 0.0:
        s = np.unique(np.append(s, unloaded))
    sol = solve_bvp(rhs, bc, s, np.zeros((3, s.size)), tol=1e-10, max_nodes=200000)
    assert sol.status == 0, sol.message
    return float(sol.sol(total)[2])


def stiffness_for(load):
    """B giving the nondimensional load q L^3 / B."""
    return Q * L ** 3 / load


# ------------------------------------------------------------------ meshes

def strip_mesh(h, width=W, seed=0, jitter=0.3, length=L, clamp=None):
    """Delaunay mesh of [-clamp, length] x [0, width] (clamp defaults to h): a
    jittered square lattice of spacing ~h, Delaunay-triangulated,
    counter-clockwise (normals +z).  The clamp columns x = -clamp, x = 0 and
    the tip column x = length keep their x exactly; boundary vertices slide
    along their edge only."""
    rng = np.random.default_rng(seed)
    nx = int(round(length / h))
    ny = max(2, int(round(width / h)))
    dx, dy = length / nx, width / ny
    xs = np.concatenate([[-(h if clamp is None else clamp)], np.arange(nx + 1) * dx])
    pts = []
    for i, x0 in enumerate(xs):
        for j in range(ny + 1):
            x, y = x0, j * dy
            if 1 < i < len(xs) - 1:
                x += jitter * dx * rng.uniform(-1, 1)
            if 0 < j < ny:
                y += jitter * dy * rng.uniform(-1, 1)
            pts.append((x, y))
    p = np.array(pts)
    tri = Delaunay(p).simplices.astype(np.int64)
    a = p[tri]
    area = 0.5 * ((a[:, 1, 0] - a[:, 0, 0]) * (a[:, 2, 1] - a[:, 0, 1])
                  - (a[:, 1, 1] - a[:, 0, 1]) * (a[:, 2, 0] - a[:, 0, 0]))
    tri[area < 0] = tri[area < 0][:, [0, 2, 1]]
    assert np.abs(area).min() > 1e-3 * dx * dy          # no slivers on the straight boundary
    return np.column_stack([p, np.zeros(len(p))]), tri


def _mesh_dir():
    """A per-process directory for the OBJ files (each rank writes its own
    identical copy: the meshes are deterministic)."""
    from mpi4py import MPI
    import tempfile
    path = os.path.join(tempfile.gettempdir(), f"distcloth-elastica-{os.getpid()}-"
                        f"r{MPI.COMM_WORLD.Get_rank()}")
    os.makedirs(path, exist_ok=True)
    return path


# ------------------------------------------------------------------ simulation

def cantilever(load, mesh, bending_model="dihedral", model="fem", width=W):
    """Static tip deflection / L of the strip.  ``mesh``: ("grid", nx, ny,
    pattern) with nx cells along the free length, or ("delaunay", h, seed).
    Returns (delta / L, h, free-vertex residual / weight).  Collective; cached
    (every rank calls it with the same arguments in the same order)."""
    return _cantilever(float(load), tuple(mesh), bending_model, model, float(width))


@functools.lru_cache(maxsize=None)
def _cantilever(load, mesh, bending_model, model, width):
    from test_physics import gather_positions, grid_scene, make_sim
    from distcloth.integrate.drape import Relaxation
    from distcloth.scene.meshio import write_obj
    B = stiffness_for(load)
    if model == "fem":
        material = {"model": "fem", "density": RHO, "E_weft": 1e3, "nu_weft": 0.0,
                    "strain": "stvk", "bending": B, "bending_model": bending_model,
                    "shear": 0.0}   # shear: only read by the (unused) grid spring check
    else:
        material = {"model": "mass_spring", "density": RHO, "stretch": 1e3, "bending": B}
    raw = grid_scene(time={"end": 1e7, "step": 1e3, "newton_iterations": 60,
                           "newton_tolerance": 1e-11},
                     solver={"ksp_rtol": 1e-12, "ksp_norm_type": "unpreconditioned"})
    if mesh[0] == "grid":
        _, nx, ny, pattern = mesh
        h = L / nx
        raw["cloth"][0]["mesh"] = {"grid": {"size": [L + h, width], "resolution": [nx + 2, ny],
                                            "pattern": pattern},
                                   "center": [(L - h) / 2, 0.0, 0.0]}
    else:
        _, h, seed = mesh
        v, tri = strip_mesh(h, width, seed)
        path = os.path.join(_mesh_dir(), f"strip-{h:g}-{seed}-{width:g}.obj")
        write_obj(path, v, tri, header="cantilever strip, tests/test_elastica.py")
        raw["cloth"][0]["mesh"] = {"file": path, "center": [(L - h) / 2, width / 2, 0.0]}
    raw["cloth"][0]["material"] = material
    raw["cloth"][0]["pins"] = [{"box": {"min": [-1, -1, -1], "max": [1e-9, 1, 1]}}]
    sim = make_sim(raw)
    rest = sim.model.rest_positions
    assert abs(rest[:, 0].min() + h) < 1e-12 and abs(rest[:, 0].max() - L) < 1e-12
    for _ in range(3):
        sim.step()
    residual = Relaxation(sim, sim.cfg.drape).residual()
    x = gather_positions(sim)
    sim.destroy()
    tip = rest[:, 0] > L - 1e-9
    return -float(x[tip, 2].mean()) / L, h, residual


def errors(load, meshes, bending_model="dihedral", width=W):
    """Relative errors of the tip deflection against the nominal elastica and
    against the clamp-corrected one, for each mesh."""
    B = stiffness_for(load)
    nominal = heavy_elastica(Q, B, L) / L
    out = []
    for mesh in meshes:
        d, h, residual = cantilever(load, mesh, bending_model, width=width)
        assert residual <= 1e-6, (mesh, residual)
        corrected = heavy_elastica(Q, B, L, clamp=h / 2, unloaded=h) / L
        out.append((d, d / nominal - 1.0, d / corrected - 1.0))
    return nominal, out


# ------------------------------------------------------------------ tests

def test_heavy_elastica_reference():
    """The BVP solution against shooting (solve_ivp + brentq on theta'(L) = 0)
    and against the linear cantilever q L^4 / (8 B) at a small load."""
    for load in (0.01, 3.0):
        B = stiffness_for(load)

        def shoot(slope0, dense=False):
            def rhs(s, y):
                return [y[1], -Q * (L - s) * np.cos(y[0]) / B, np.sin(y[0])]
            return solve_ivp(rhs, (0.0, L), [0.0, slope0, 0.0], rtol=1e-12, atol=1e-14)
        slope0 = brentq(lambda k: shoot(k).y[1, -1], 0.0, Q * L ** 2 / (2 * B) * 1.01, xtol=1e-14)
        assert abs(heavy_elastica(Q, B, L) - shoot(slope0).y[2, -1]) <= 1e-8 * L
    # geometric nonlinearity: at q L^3 / B = 3 the tip rises 9.4 % above linear theory
    assert abs(heavy_elastica(Q, stiffness_for(0.01), L) / (0.01 / 8 * L) - 1) <= 1e-5
    assert abs(heavy_elastica(Q, stiffness_for(3.0), L) / L - 0.339648) <= 1e-6


# grid with cells 8x longer than wide (dx = h, dy = h / 8, width 0.01 m):
# hinges across the bend are all aligned with the bend axis
ALIGNED = [("grid", 10, 5, "alternating"), ("grid", 20, 9, "alternating")]


@pytest.mark.parametrize("bending_model", ["dihedral", "isometric"])
def test_cantilever_large_deflection_aligned_grid(bending_model):
    """q L^3 / B = 3, delta / L = 0.34 (9 % below linear theory).  Measured
    (h = L/10, L/20), dihedral: error vs the nominal elastica +17.5 %, +8.7 %
    (the clamp's O(h) offset), vs the clamp-corrected elastica -0.4 %, -0.1 %;
    isometric the same to 0.2 %.  The isometric model is linear in the
    positions but exact for isometric deformations of a flat sheet (Bergou et
    al. 2006), which the nearly inextensible strip undergoes: large rotations
    do not spoil it."""
    nominal, out = errors(3.0, ALIGNED, bending_model, width=0.01)
    (_, nom_c, cor_c), (_, nom_f, cor_f) = out
    assert 0.3 <= nominal <= 0.35                     # large deflection
    assert abs(cor_f) <= 0.01 and abs(cor_f) <= abs(cor_c)
    assert abs(cor_c) <= 0.01
    # the nominal error is first order in h: halving h halves it
    assert 0.4 <= nom_f / nom_c <= 0.6


def test_isometric_small_load_matches_linear_cantilever():
    """q L^3 / B = 0.3 (delta / L = 0.0375): the linear formula q L^4 / (8 B)
    and the elastica differ by 0.1 %; both models within 1 % of the
    clamp-corrected elastica and of the clamp-corrected linear formula."""
    load, mesh = 0.3, ALIGNED[0]
    B = stiffness_for(load)
    h = L / mesh[1]
    elastica = heavy_elastica(Q, B, L, clamp=h / 2, unloaded=h) / L
    tiny = 1e-4
    linear = heavy_elastica(Q, stiffness_for(tiny), L, clamp=h / 2, unloaded=h) / L * load / tiny
    assert abs(heavy_elastica(Q, B, L) / L / (load / 8) - 1) <= 2e-3
    for bending_model in ("isometric", "dihedral"):
        d = cantilever(load, mesh, bending_model, width=0.01)[0]
        assert abs(d / elastica - 1) <= 0.01, bending_model
        assert abs(d / linear - 1) <= 0.01, bending_model


@pytest.mark.parametrize("bending_model", ["dihedral", "isometric"])
def test_cantilever_square_cell_grid_is_too_compliant(bending_model):
    """KNOWN DEFECT, characterised: on the split-square grid with square cells
    (width 0.02 m) both hinge models are 15-17 % too compliant against the
    clamp-corrected elastica, and refining (h = L/20 -> L/40) does not help
    (measured +15.0 %, +16.8 %).  The prescribed cylinder has the right energy
    (tests/test_bending.py), but the split triangulation couples the bend to
    mesh-scale twists of the cells that lower the hinge energy, so the
    minimiser is softer than the continuum: the hinge energy is not mesh
    independent.  If this test fails because the error went below 10 %, the
    bending model improved: update it."""
    _, out = errors(3.0, [("grid", 20, 3, "alternating"), ("grid", 40, 5, "alternating")],
                    bending_model)
    for d, nom, cor in out:
        assert 0.10 <= cor <= 0.22, (d, nom, cor)


DELAUNAY = [("delaunay", 0.01, 0), ("delaunay", 0.005, 0), ("delaunay", 0.0025, 0)]


@pytest.mark.parametrize("bending_model", ["dihedral", "isometric"])
def test_cantilever_delaunay_mesh(bending_model):
    """Jittered Delaunay meshes (width 0.02 m, h = 5 and 2.5 mm), q L^3 / B = 3.
    Measured (seed 0), both models: +10.4 %, +9.9 % against the nominal
    elastica, +5.8 %, +7.6 % against the clamp-corrected one (seed 1: +10.9 %,
    +7.5 %).  The clamp's first-order offset is gone but a mesh-dependent
    excess compliance of 6-11 % stays (as on the square grid, weaker): the
    finer mesh is NOT closer to the elastica.  Asserted: too compliant by
    3-12 % at both resolutions (a regression bound, not convergence), and the
    two hinge models agree to 0.2 %."""
    _, out = errors(3.0, DELAUNAY[1:], bending_model)
    for d, nom, cor in out:
        assert 0.03 <= cor <= 0.12, (d, nom, cor)
    for mesh in DELAUNAY[1:]:
        dih = cantilever(3.0, mesh, "dihedral")[0]
        iso = cantilever(3.0, mesh, "isometric")[0]
        assert abs(iso / dih - 1) <= 2e-3


def test_mesh_independence_fe_dihedral_converges():
    """scripts/mesh_independence.py on one seed: the FE + dihedral tip
    deflection settles under refinement (measured changes -7.3 % from h = 10
    to 5 mm, -0.4 % from 5 to 2.5 mm) -- to a value 7-8 % above the elastica,
    see test_cantilever_delaunay_mesh."""
    d = [cantilever(3.0, mesh, "dihedral")[0] for mesh in DELAUNAY]
    assert abs(d[2] - d[1]) < abs(d[1] - d[0])


@pytest.mark.parametrize("bending_model", ["dihedral_shell", "isometric_shell"])
def test_shell_bending_matches_elastica_on_every_mesh_family(bending_model):
    """Per-triangle curvature bending with the curvature-jump penalty (gamma = 10,
    bending_shell.py) on the meshes that leave the per-hinge models 6-17 % too
    compliant.  Measured against the clamp-corrected elastica (dihedral_shell /
    isometric_shell): split-square grid h = L/20, L/40: -1.21 / -1.66 %, -0.80 /
    -1.13 % (the penalty's O(h) bias, shrinking); alternating grid +2.30 / +2.34 %,
    +1.70 / +1.55 %; Delaunay h = 10, 5 mm: -0.18 / -0.36 %, -0.65 / -0.86 %.
    2.5 % bounds them all with the trend asserted on the grids."""
    for pattern in ("regular", "alternating"):
        _, out = errors(3.0, [("grid", 20, 3, pattern), ("grid", 40, 5, pattern)], bending_model)
        (_, _, coarse), (_, _, fine) = out
        assert abs(coarse) <= 0.025 and abs(fine) <= 0.025, (pattern, coarse, fine)
        assert abs(fine) < abs(coarse), (pattern, coarse, fine)
    _, out = errors(3.0, DELAUNAY[:2], bending_model)
    for d, nom, cor in out:
        assert abs(cor) <= 0.025, (d, nom, cor)
