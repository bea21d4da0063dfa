"""Peirce cantilever (ASTM D1388): helpers shared by tests/test_peirce.py and
scripts/peirce_study.py.

A strip of width W, weight per area w = rho g, overhangs a clamp by a length
L and droops under its own weight.  ASTM D1388 reads the chord angle theta
from the clamp edge to the tip and reports the bending length

    c = L (cos(theta/2) / (8 tan theta))^(1/3)          (Peirce 1930)

and the flexural rigidity G = w c^3.  The formula is itself an approximation
of the heavy elastica (c = L/2 at theta = 41.5 deg, the standard's test
angle), so the simulated strip is compared with the *exact* heavy elastica
at the same L: both chord angles go through the same formula, and the
relative error of c is the bending model's error (3x smaller than B's:
c ~ B^(1/3)).

Reference: B theta'' = -w (L - s) cos theta, theta(0) = 0, theta'(L) = 0
(arc length s, theta the slope below horizontal), solved by scipy solve_bvp.
The overhang at which the exact chord is at 41.5 deg, L*, depends on w and B
only through w L^3 / B (= 8.004).

Simulation: as tests/test_elastica.py (nearly inextensible membrane E = 1e3
N/m, equilibrium by backward Euler with huge steps and Newton), the clamp
pins the two vertex columns x = -h and x = 0 (it fixes the slope), the tip is
the mean of the vertices at x = L, the chord is measured from (0, 0).
"""
from __future__ import annotations

import functools
import math
import os

import numpy as np
from scipy.integrate import solve_bvp
from scipy.optimize import brentq

WIDTH, RHO, GRAV = 0.025, 0.1, 9.81
WEIGHT = RHO * GRAV                     # w, N/m^2
B_STRIP = 1.0e-4                        # N.m: bending length c = (B/w)^(1/3) = 46.7 mm
ASTM_ANGLE = 41.5                       # degrees
MODELS = (("fem", "grid_lines"), ("fem", "dihedral_shell"), ("fem", "isometric_shell"),
          ("fem", "dihedral"), ("fem", "isometric"), ("mass_spring", "flexion"))
MESH_KINDS = ("alternating", "regular", "delaunay", "frontal")


# ------------------------------------------------------------------ reference

def elastica_tip(length, B=B_STRIP, w=WEIGHT, clamp=0.0, unloaded=0.0):
    """(x, z) of the tip of the exact heavy elastica (z > 0 downwards),
    relative to the point at arc length ``clamp`` from the clamp: the strip
    is clamp + length long and carries w only on s > unloaded (the discrete
    clamp, tests/test_elastica.py: clamp = h/2, unloaded = h)."""
    total = length + clamp

    def rhs(s, y):        # y = (theta, theta', x, z)
        arm = total - np.maximum(s, unloaded)
        return np.vstack([y[1], -w * arm * np.cos(y[0]) / B, np.cos(y[0]), np.sin(y[0])])

    def bc(a, b):
        return np.array([a[0], b[1], a[2], a[3]])

    s = np.unique(np.concatenate([np.linspace(0.0, total, 401), [clamp, unloaded]]))
    guess = np.zeros((4, s.size))
    guess[2] = s
    sol = solve_bvp(rhs, bc, s, guess, tol=1e-10, max_nodes=200000)
    assert sol.status == 0, sol.message
    y, y0 = sol.sol(total), sol.sol(clamp)
    return float(y[2] - y0[2]), float(y[3] - y0[3])


def chord_angle(x, z):
    """Chord angle below horizontal, degrees."""
    return math.degrees(math.atan2(z, x))


def bending_length(length, angle_deg):
    """ASTM D1388: c = L (cos(theta/2) / (8 tan theta))^(1/3)."""
    t = math.radians(angle_deg)
    if not 0.0 < t < math.pi / 2:
        return math.nan                     # hanging past vertical: no bending length
    return length * (math.cos(t / 2) / (8 * math.tan(t))) ** (1.0 / 3.0)


@functools.lru_cache(maxsize=None)
def astm_overhang(B=B_STRIP, w=WEIGHT):
    """L*: the overhang whose exact elastica chord is at 41.5 degrees."""
    c = (B / w) ** (1.0 / 3.0)
    return brentq(lambda L: chord_angle(*elastica_tip(L, B, w)) - ASTM_ANGLE, 1.2 * c, 3.0 * c,
                  xtol=1e-12)


# ------------------------------------------------------------------ meshes

def _mesh_dir():
    from mpi4py import MPI
    import tempfile
    path = os.path.join(tempfile.gettempdir(), f"distcloth-peirce-{os.getpid()}-"
                        f"r{MPI.COMM_WORLD.Get_rank()}")
    os.makedirs(path, exist_ok=True)
    return path


def frontal_strip_mesh(h, width, length, clamp):
    """The strip as distcloth meshes a garment panel: the overhang [0, length]
    x [0, width] by the panel mesher (Gmsh's Frontal-Delaunay, outline split
    evenly at spacing ~h), and one column of vertices at x = -clamp joined to
    the mesher's column at x = 0 by split quads (the clamp)."""
    from distcloth.garment.mesh import triangulate
    nx = int(round(length / h))
    ny = max(2, int(round(width / h)))
    xs = np.linspace(0.0, length, nx + 1)
    ys = np.linspace(0.0, width, ny + 1)
    # counter-clockwise outline from (0, 0): bottom, tip, top, clamp line
    outline = np.concatenate([
        np.column_stack([xs[:-1], np.zeros(nx)]),
        np.column_stack([np.full(ny, length), ys[:-1]]),
        np.column_stack([xs[::-1][:-1], np.full(nx, width)]),
        np.column_stack([np.zeros(ny), ys[::-1][:-1]])])
    v2, tri = triangulate(outline, h, name="peirce strip")
    n = v2.shape[0]
    # the clamp line's vertices in the outline, bottom to top
    line = np.concatenate([[0], np.arange(outline.shape[0] - 1, outline.shape[0] - ny - 1, -1)])
    assert np.allclose(v2[line, 0], 0.0) and np.all(np.diff(v2[line, 1]) > 0)
    back = n + np.arange(ny + 1)
    quads = [(back[j], back[j + 1], line[j + 1]) for j in range(ny)] + \
            [(back[j], line[j + 1], line[j]) for j in range(ny)]
    v = np.concatenate([v2, np.column_stack([np.full(ny + 1, -clamp), ys])])
    tri = np.concatenate([tri, np.array(quads, dtype=np.int64)])
    a = v[tri]
    area = ((a[:, 1, 0] - a[:, 0, 0]) * (a[:, 2, 1] - a[:, 0, 1])
            - (a[:, 1, 1] - a[:, 0, 1]) * (a[:, 2, 0] - a[:, 0, 0]))
    tri[area < 0] = tri[area < 0][:, [0, 2, 1]]
    return np.column_stack([v, np.zeros(len(v))]), tri


# ------------------------------------------------------------------ simulation

@functools.lru_cache(maxsize=None)
def simulate(length, h, kind, model="fem", bending_model="dihedral_shell", B=B_STRIP,
             newton_iterations=60, step=1e3, steps=3):
    """Equilibrium of the strip of overhang ``length`` on a mesh of spacing ~h
    (``kind``: alternating, regular or delaunay).  Returns (chord angle deg,
    free-vertex residual / weight).  Default: equilibrium by backward Euler
    with 3 huge steps of up to 60 Newton iterations; ``newton_iterations``,
    ``step`` and ``steps`` give a dynamic run instead.  Collective; cached."""
    from test_physics import gather_positions, grid_scene, make_sim
    from distcloth.integrate.drape import Relaxation
    from distcloth.scene.meshio import write_obj
    if model == "fem":
        material = {"model": "fem", "density": RHO, "E_weft": 1e3, "nu_weft": 0.0,
                    "strain": "stvk", "bending": B, "bending_model": bending_model}
    else:
        material = {"model": "mass_spring", "density": RHO, "stretch": 1e3, "bending": B}
    raw = grid_scene(time={"end": 1e7, "step": step, "newton_iterations": newton_iterations,
                           "newton_tolerance": 1e-11},
                     solver={"ksp_rtol": 1e-12, "ksp_norm_type": "unpreconditioned"})
    if kind in ("regular", "alternating"):
        nx = max(2, int(round(length / h)))
        ny = max(2, int(round(WIDTH / h)))
        dx = length / nx
        raw["cloth"][0]["mesh"] = {"grid": {"size": [length + dx, WIDTH],
                                            "resolution": [nx + 2, ny + 1], "pattern": kind},
                                   "center": [(length - dx) / 2, 0.0, 0.0]}
    else:
        dx = length / int(round(length / h))
        if kind == "frontal":
            v, tri = frontal_strip_mesh(h, WIDTH, length, dx)
        else:
            from test_elastica import strip_mesh
            v, tri = strip_mesh(h, WIDTH, length=length, clamp=dx)
        path = os.path.join(_mesh_dir(), f"strip-{length:.6g}-{h:g}.obj")
        write_obj(path, v, tri, header="Peirce strip, tests/peirce.py")
        raw["cloth"][0]["mesh"] = {"file": path, "center": [(length - dx) / 2, WIDTH / 2, 0.0]}
    raw["cloth"][0]["material"] = material
    raw["cloth"][0]["pins"] = [{"box": {"min": [-1, -1, -1], "max": [1e-9, 1, 1]}}]
    sim = make_sim(raw)
    rest = sim.model.rest_positions
    for _ in range(steps):
        sim.step()
    residual = Relaxation(sim, sim.cfg.drape).residual()
    x = gather_positions(sim)
    sim.destroy()
    tip = rest[:, 0] > length - 1e-9
    return chord_angle(float(x[tip, 0].mean()), -float(x[tip, 2].mean())), residual


def peirce_row(fraction, h, kind, model, bending_model, B=B_STRIP):
    """One cell of the Peirce table: overhang L = fraction * L*, the simulated
    chord angle, the exact one (nominal clamp) and the exact one of the
    discrete clamp (clamp at -dx/2, no load on the first dx: an O(h)
    boundary discretisation, not a bending-model error), bending lengths c and
    rigidities G = w c^3, and the errors of c against both references."""
    length = fraction * astm_overhang(B)
    angle, residual = simulate(length, h, kind, model, bending_model, B)
    dx = length / max(2, int(round(length / h)))
    exact = chord_angle(*elastica_tip(length, B))
    clamped = chord_angle(*elastica_tip(length, B, clamp=dx / 2, unloaded=dx))
    c_sim, c_ex, c_cl = (bending_length(length, a) for a in (angle, exact, clamped))
    return {"L": length, "dx": dx, "angle": angle, "exact_angle": exact,
            "clamp_angle": clamped, "c": c_sim, "c_exact": c_ex, "c_clamp": c_cl,
            "G": WEIGHT * c_sim ** 3, "G_exact": WEIGHT * c_ex ** 3,
            "c_error": c_sim / c_ex - 1.0, "c_error_clamp": c_sim / c_cl - 1.0,
            "residual": residual}
