"""Fused interlinings (``garment.fused``, docs/garments.md "Seams, pucker,
fused interlinings"): the region's triangles take the combined material,
the fabric's modulus plus the interlining's (a factor 1 + stretch / E on
every FE triangle), its hinges the combined bending stiffness (a factor
1 + bending / B), its vertices the interlining's mass (density x area).

- bookkeeping on one rotated, translated panel in centimetres with a box
  given in metres in the panel's own 2D frame: the Model's triangle factors,
  hinge factors and added mass against an independent selection of the
  triangles by their centroids, and the factors reaching the force terms
  (membrane and bending energies of the same deformation with and without
  the interlining);
- physics: a strip hanging under gravity, fabric in its upper half and fused
  in its lower half, against the exact elongation of a hanging bar in
  series (the interlining stiffens the lower half and loads the upper one);
- the config errors of a fused entry that names no panel of the pattern, a
  box holding no triangles, or a piece that is not an FE membrane.

Every test runs on every rank (``mpiexec -n 2 python -m pytest``); each rank
writes the same pattern into its own tmp_path and builds the same Model.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
import yaml
from mpi4py import MPI

from conftest import run_cli
from test_physics import gather_positions, make_sim
from distcloth.config import ConfigError
from distcloth.config.load import config_from_dict
from distcloth.parallel.comm import Comm
from distcloth.run import run
from distcloth.scene import build_model

G = 9.81


def write_pattern(tmp, name, pattern):
    path = tmp / name
    path.write_text(yaml.safe_dump(pattern, sort_keys=False))
    return path


def tri_areas(x, tri):
    return 0.5 * np.linalg.norm(np.cross(x[tri[:, 1]] - x[tri[:, 0]],
                                         x[tri[:, 2]] - x[tri[:, 0]]), axis=1)


# ------------------------------------------------------------- bookkeeping

# a 10 x 20 cm panel written in centimetres, turned 30 degrees about z and
# moved; the fused box is in metres in the panel's own frame
PANEL_W, PANEL_H = 0.10, 0.20
TURN = math.radians(30.0)
SHIFT = np.array([0.30, 0.10, 0.05])
BOX_MIN, BOX_MAX = np.array([0.02, 0.05]), np.array([0.08, 0.15])
E_FABRIC, B_FABRIC, RHO_FABRIC = 50.0, 1e-5, 0.1
E_FUSED, B_FUSED, RHO_FUSED = 100.0, 3e-5, 0.2     # factors 3 and 4, exact in binary
H_PANEL = 0.01


def panel_scene(pattern, fused=True, effects=("membrane", "bending")):
    raw = {"cloth": [{"name": "g", "mesh": {"pattern": str(pattern), "edge_length": H_PANEL,
                                             "up_axis": "z"},
                      "material": {"model": "fem", "density": RHO_FABRIC, "stretch": E_FABRIC,
                                   "bending": B_FABRIC, "bending_model": "dihedral"}}],
           "effects": list(effects),
           "output": {"file": "unused.h5", "preview": False}}
    if fused:
        raw["garment"] = {"fused": [{"piece": "g", "panel": "front",
                                     "box": {"min": BOX_MIN.tolist(), "max": BOX_MAX.tolist()},
                                     "stretch": E_FUSED, "bending": B_FUSED,
                                     "density": RHO_FUSED}]}
    return raw


def panel_pattern(tmp):
    cm = 100.0
    return write_pattern(tmp, "panel.yaml", {
        "units_in_meter": 100,
        "panels": {"front": {
            "vertices": [[0, 0], [PANEL_W * cm, 0], [PANEL_W * cm, PANEL_H * cm],
                         [0, PANEL_H * cm]],
            "translation": (SHIFT * cm).tolist(), "rotation": [0, 0, 30]}}})


def to_panel_frame(x):
    """World positions back to the panel's 2D frame: p3 = Rz(30) (u, v, 0) + t,
    written out here rather than taken from the library."""
    c, s = math.cos(TURN), math.sin(TURN)
    d = x - SHIFT
    return np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]], axis=1)


def test_fused_box_factors_and_added_mass(tmp_path):
    pattern = panel_pattern(tmp_path)
    fused = build_model(config_from_dict(panel_scene(pattern), str(tmp_path), "f"))
    plain = build_model(config_from_dict(panel_scene(pattern, fused=False), str(tmp_path), "p"))
    x, tri = fused.rest_positions, fused.triangles
    # Gmsh meshes the same panel the same way: the two models differ only in
    # what the interlining adds
    assert np.array_equal(x, plain.rest_positions) and np.array_equal(tri, plain.triangles)
    assert np.allclose(x[:, 2], SHIFT[2]) and plain.triangle_scale is None
    assert plain.hinge_scale is None

    # the region: the triangles whose centroids, in the panel's frame, lie in the box
    centroid = to_panel_frame(x[tri].mean(axis=1))
    inside = np.all((centroid >= BOX_MIN) & (centroid <= BOX_MAX), axis=1)
    assert 0 < inside.sum() < tri.shape[0]

    # membrane factor 1 + 100 / 50 = 3 inside, 1 outside (exact in floating point)
    expected_scale = np.where(inside, 1.0 + E_FUSED / E_FABRIC, 1.0)
    assert np.array_equal(fused.triangle_scale, expected_scale)

    # hinge factor 1 + 3e-5 / 1e-5 = 4 on the hinges whose two triangles are
    # both inside, 1 on the others; each hinge's triangles found here from its
    # four vertices (i0, i1 the edge, i2 and i3 the opposite corners)
    index = {tuple(sorted(t)): k for k, t in enumerate(tri.tolist())}
    hv = fused.hinge_vertices
    ta = np.array([index[tuple(sorted(h))] for h in hv[:, [0, 1, 2]].tolist()])
    tb = np.array([index[tuple(sorted(h))] for h in hv[:, [0, 1, 3]].tolist()])
    both = inside[ta] & inside[tb]
    assert both.any() and (~both).any()
    assert np.array_equal(fused.hinge_scale, np.where(both, 1.0 + B_FUSED / B_FABRIC, 1.0))

    # added mass: density x the area of the region, a third of each of its
    # triangles to each corner; the fabric's own mass is untouched
    added = fused.vertex_mass - plain.vertex_mass
    region_area = tri_areas(x, tri[inside]).sum()
    in_region = np.zeros(x.shape[0], dtype=bool)
    in_region[tri[inside].ravel()] = True
    assert np.all(added[~in_region] == 0.0) and np.all(added[in_region] > 0.0)
    assert added.sum() == pytest.approx(RHO_FUSED * region_area, rel=1e-12)
    np.testing.assert_allclose(plain.vertex_mass.sum(), RHO_FABRIC * PANEL_W * PANEL_H, rtol=1e-12)
    # against the box's own area: the centroid rule cuts the region along a
    # staircase of triangles of size h, erring by part of a triangle either
    # way along the boundary; the worst case (every straddling triangle, about
    # h^2 / 2, wrong the same way, about one per h of the perimeter) is
    # perimeter * h / 2; we ask for a quarter of it, 0.32 m * 1 cm / 4 = 13 % of
    # the box (measured: 2.0 %)
    box_area = np.prod(BOX_MAX - BOX_MIN)
    perimeter = 2 * np.sum(BOX_MAX - BOX_MIN)
    assert abs(added.sum() - RHO_FUSED * box_area) <= RHO_FUSED * perimeter * H_PANEL / 4


def _elastic(raw, model, x):
    sim = make_sim(raw, model)
    energy = sim.potential_energies(x[sim.layout.local_input])[1]
    sim.destroy()
    return energy


def test_fused_factors_reach_the_membrane_and_bending_terms(tmp_path):
    # the same deformation of the two models, one term at a time: a uniform 1 %
    # stretch along the panel's v axis stores in every triangle its area times
    # one energy density, so the membrane energies are in the ratio
    # (A_out + 3 A_in) / A; a vertex deep in the box lifted 1 mm out of the
    # plane bends only hinges of the region (checked), ratio 4; one far outside,
    # ratio 1.  Both are ratios of the same sums, to round-off (1e-9)
    pattern = panel_pattern(tmp_path)
    models = {f: build_model(config_from_dict(panel_scene(pattern, fused=f), str(tmp_path), "s"))
              for f in (True, False)}
    x0 = models[True].rest_positions
    tri = models[True].triangles
    c, s = math.cos(TURN), math.sin(TURN)
    v_axis = np.array([-s, c, 0.0])
    stretched = x0 + 0.01 * ((x0 - SHIFT) @ v_axis)[:, None] * v_axis
    membrane = {f: _elastic(panel_scene(pattern, fused=f, effects=("membrane",)), m, stretched)
                for f, m in models.items()}
    area = tri_areas(x0, tri)
    inside = models[True].triangle_scale > 1.0
    expected = (area[~inside].sum() + 3.0 * area[inside].sum()) / area.sum()
    assert membrane[False] > 0
    assert membrane[True] / membrane[False] == pytest.approx(expected, rel=1e-9)

    uv = to_panel_frame(x0)
    hv = models[True].hinge_vertices
    centre = np.argmin(np.linalg.norm(uv - (BOX_MIN + BOX_MAX) / 2, axis=1))
    far = np.argmin(np.linalg.norm(uv - [0.09, 0.01], axis=1))
    for vertex, ratio in ((centre, 4.0), (far, 1.0)):
        touched = np.any(hv == vertex, axis=1)
        assert np.all(models[True].hinge_scale[touched] == ratio)
        lifted = x0.copy()
        lifted[vertex, 2] += 1e-3
        bending = {f: _elastic(panel_scene(pattern, fused=f, effects=("bending",)), m, lifted)
                   for f, m in models.items()}
        assert bending[False] > 0
        assert bending[True] / bending[False] == pytest.approx(ratio, rel=1e-9)


# ------------------------------------------------------------------ physics

# A strip W wide and L long hangs from its top edge under gravity, the upper
# half plain fabric, the lower half fused (box in the panel's frame, v <= L/2).
# Poisson ratio 0: every cross-section is in uniaxial tension without lateral
# strain, so the strip is a bar: at the distance s above its bottom, the first
# Piola stress per reference width equals the weight of what hangs below,
#   P(s) = g * (rho + rho_i) * s                            s <= L/2 (fused)
#   P(s) = g * ((rho + rho_i) * L/2 + rho * (s - L/2))      s >= L/2 (fabric)
# and St. Venant-Kirchhoff gives P = k E (lambda^3 - lambda) / 2 with lambda
# the stretch and k the membrane factor (1 + E_i / E below, 1 above).  The
# elongation of each half is the integral of lambda - 1 over it.  With the
# interlining below (its modulus 3 times the fabric's: factor 4; its density
# twice the fabric's), the lower
# half's elongation tests the factor (without it: +292 %), the upper half's
# the added mass (without it: -56 %); without either, +33 % and -56 %.
W, L, H_STRIP = 0.05, 0.40, 0.01
E_STRIP, RHO_STRIP = 20.0, 0.1


def bar_elongations(k, rho_i):
    """(upper half, lower half) elongations of the hanging bar above, exact
    but for the quadrature (2001 points per half; the integrand is smooth and
    the trapezoid error below 1e-8 relative)."""
    def elongation(s, P, stiffness):
        q = 2.0 * P / stiffness
        lam = 1.0 + q / 2.0                   # Newton on lambda^3 - lambda - q = 0
        for _ in range(50):
            lam -= (lam ** 3 - lam - q) / (3 * lam ** 2 - 1)
        assert np.all(np.abs(lam ** 3 - lam - q) < 1e-14)
        return np.trapz(lam - 1.0, s)
    lower = np.linspace(0.0, L / 2, 2001)
    upper = np.linspace(L / 2, L, 2001)
    return (elongation(upper, G * ((RHO_STRIP + rho_i) * L / 2 + RHO_STRIP * (upper - L / 2)),
                       E_STRIP),
            elongation(lower, G * (RHO_STRIP + rho_i) * lower, k * E_STRIP))


def hanging_scene(pattern, stretch, density):
    return {"cloth": [{"name": "strip",
                       "mesh": {"pattern": str(pattern), "edge_length": H_STRIP, "up_axis": "y"},
                       "pins": [{"box": {"min": [-1, -1, L - 1e-9], "max": [1, 1, L + 1e-9]}}],
                       "material": {"model": "fem", "density": RHO_STRIP, "E_weft": E_STRIP,
                                    "nu_weft": 0.0, "bending": 1e-7,
                                    "bending_model": "dihedral"}}],
            "effects": ["gravity", "membrane", "bending"],
            "garment": {"fused": [{"piece": "strip", "panel": "s",
                                   "box": {"min": [-1.0, -1.0], "max": [1.0, L / 2]},
                                   "stretch": stretch, "density": density}]},
            # steps of 100 s: inertia (M / h^2) is negligible, each step a static solve
            "time": {"end": 1000.0, "step": 100.0, "newton_iterations": 30,
                     "newton_tolerance": 1e-10},
            "solver": {"ksp_rtol": 1e-12, "ksp_norm_type": "unpreconditioned"},
            "output": {"file": "unused.h5", "every": 1000.0, "preview": False}}


# (interlining modulus N/m, density kg/m^2): the full interlining, each
# ingredient alone, and an interlining of nothing (the plain fabric), every
# case against its own analytic answer
@pytest.mark.parametrize("stretch,density", [(60.0, 0.2), (0.0, 0.2), (60.0, 0.0), (0.0, 0.0)])
def test_hanging_strip_with_fused_lower_half_matches_the_bar_in_series(tmp_path, stretch,
                                                                       density):
    # The panel's outline has corners at mid-height on both sides, so that the
    # lower half's end is a mesh vertex.  Tolerance 1.5 %: the fused region is
    # the triangles whose centroids are below L/2, a staircase of 1 cm
    # triangles, not the straight line of the bar (measured on 1 and 2 ranks,
    # the same to 1e-5 mm: at most 0.38 % off, and 0.006 % with a plain lower
    # half); Newton and CG at 1e-10 / 1e-12 are far below.  The answers
    # without the factor, the mass or both are at least 33 % away in one half
    # (asserted below: more than 20 %).
    pattern = write_pattern(tmp_path, "strip.yaml", {"units_in_meter": 1, "panels": {"s": {
        "vertices": [[0, 0], [W, 0], [W, L / 2], [W, L], [0, L], [0, L / 2]]}}})
    raw = hanging_scene(pattern, stretch, density)
    model = build_model(config_from_dict(raw, str(tmp_path), "strip"))
    rest = model.rest_positions
    assert np.allclose(rest[:, 1], 0.0) and np.isclose(rest[:, 2].max(), L)
    sim = make_sim(raw, model)
    drops = []
    for _ in range(4):
        sim.step()
        drops.append(rest[:, 2] - gather_positions(sim)[:, 2])
    sim.destroy()
    drop = drops[-1]
    assert np.abs(drops[-1] - drops[-2]).max() < 1e-6 * drop.max()     # at rest
    bottom = np.isclose(rest[:, 2], 0.0)
    middle = np.isclose(rest[:, 2], L / 2) & (np.isclose(rest[:, 0], 0.0)
                                              | np.isclose(rest[:, 0], W))
    assert bottom.sum() >= 5 and middle.sum() == 2
    upper = drop[middle].mean()
    lower = drop[bottom].mean() - upper

    k = 1.0 + stretch / E_STRIP
    want_upper, want_lower = bar_elongations(k, density)
    assert upper == pytest.approx(want_upper, rel=0.015), (upper, want_upper)
    assert lower == pytest.approx(want_lower, rel=0.015), (lower, want_lower)
    # the test separates: a strip whose interlining lost its modulus, its mass
    # or both would be far outside the tolerance in one half or the other
    broken = {(1.0, density), (k, 0.0), (1.0, 0.0)} - {(k, density)}
    for k_lost, rho_lost in broken:
        lost = np.array(bar_elongations(k_lost, rho_lost))
        assert np.max(np.abs(lost / [want_upper, want_lower] - 1)) > 0.2, (k_lost, rho_lost)


# ------------------------------------------------------------ config errors

def error_scene(pattern, tmp, fused, model="fem"):
    material = ({"model": "fem", "stretch": 50.0, "bending_model": "dihedral"}
                if model == "fem" else {"model": "mass_spring", "stretch": 50.0})
    return {"cloth": [{"name": "g", "material": material,
                       "mesh": {"pattern": str(pattern), "edge_length": 0.05, "up_axis": "z"}}],
            "effects": ["gravity", "membrane"],
            "garment": {"fused": [{"piece": "g", "stretch": 10.0, **fused}]},
            "time": {"end": 0.02, "step": 0.01},
            "output": {"file": str(tmp / "never.h5"), "preview": False}}


SQUARE = {"units_in_meter": 1, "panels": {"front": {
    "vertices": [[0, 0], [0.2, 0], [0.2, 0.2], [0, 0.2]]}}}


@pytest.mark.parametrize("fused,model,key,words", [
    ({"panel": "sleeve"}, "fem", "garment.fused.0.panel", ["sleeve", "front"]),
    ({"panel": "front", "box": {"min": [0.5, 0.5], "max": [0.6, 0.6]}}, "fem",
     "garment.fused.0.box", ["front"]),
    ({"panel": "front"}, "mass_spring", "garment.fused.0.piece", ["fem"]),
])
def test_bad_fused_entry_is_a_config_error(tmp_path, fused, model, key, words):
    pattern = write_pattern(tmp_path, "square.yaml", SQUARE)
    raw = error_scene(pattern, tmp_path, fused, model)
    with pytest.raises(ConfigError) as caught:
        build_model(config_from_dict(raw, str(tmp_path), "bad"))
    assert caught.value.key == key
    assert all(w in str(caught.value) for w in words), str(caught.value)
    if model == "fem":
        # the run refuses it on every rank alike, with the command line's exit status
        cfg = config_from_dict(raw, str(tmp_path), "bad")
        assert run(cfg, Comm(MPI.COMM_WORLD), quiet=True, progress=False) == 2
        assert not (tmp_path / "never.h5").exists()


@pytest.mark.rank0_only
def test_unknown_fused_panel_exits_2_from_the_command_line(tmp_path):
    pattern = write_pattern(tmp_path, "square.yaml", SQUARE)
    scene = tmp_path / "bad.yaml"
    scene.write_text(yaml.safe_dump(error_scene(pattern, tmp_path, {"panel": "sleeve"})))
    proc = run_cli(["check", scene], ranks=None, cwd=tmp_path)
    assert proc.returncode == 2, (proc.returncode, proc.stderr[-2000:])
    lines = [ln for ln in proc.stderr.splitlines() if ln.startswith("distcloth: config error")]
    assert len(lines) == 1 and "garment.fused.0.panel" in lines[0], proc.stderr[-2000:]
    assert "sleeve" in lines[0] and "front" in lines[0]
