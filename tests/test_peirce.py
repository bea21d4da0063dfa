"""Peirce cantilever (ASTM D1388) on coarse meshes: helpers and setup in
tests/peirce.py, the fine table in docs/fidelity.md (scripts/peirce_study.py).

Tolerance: 2 % on the bending length c, the figure ASTM D1388 users read
(c ~ B^(1/3), so 2 % on c is 6 % on B).  The reference for the bending model
is the exact heavy elastica of the discrete clamp (clamp at -h/2, no load
on the first h): the discretised clamp shifts the chord at O(h) whatever the
bending model (asserted below: halving h halves that offset), and that is
not what these tests judge.  The strip is L* = 93.4 mm (0.8, 1.0, 1.2 L*)
long, 25 mm wide, h = 10 mm: 8-11 cells along, 3 across.
"""
import math

import pytest

import peirce as p

COARSE = 0.01
FRACTIONS = (0.8, 1.0, 1.2)


def test_reference_overhang_and_formula():
    """L* puts the exact chord at 41.5 deg; w L*^3 / B = 8.004 (the Peirce
    formula's c = L/2 would give 8 exactly: at 41.5 deg it gives c = 0.509 L);
    the exact chord rises with the overhang."""
    L = p.astm_overhang()
    assert abs(p.chord_angle(*p.elastica_tip(L)) - 41.5) <= 1e-8
    assert abs(p.WEIGHT * L ** 3 / p.B_STRIP - 8.004) <= 1e-3
    assert abs(p.bending_length(L, 41.5) / L - 0.5094) <= 1e-4
    angles = [p.chord_angle(*p.elastica_tip(f * L)) for f in FRACTIONS]
    assert angles[0] < angles[1] < angles[2]
    # the discrete-clamp reference tends to the nominal one at first order in h
    d1, d2 = (p.chord_angle(*p.elastica_tip(L, clamp=h / 2, unloaded=h)) - 41.5
              for h in (1e-3, 1e-4))
    assert 0.3 <= d1 <= 1.0 and 8.0 <= d1 / d2 <= 12.0, (d1, d2)


@pytest.mark.parametrize("kind", ["alternating", "regular", "delaunay"])
def test_dihedral_shell_bending_length_within_two_percent(kind):
    """FE + dihedral_shell, h = 10 mm.  Measured c error against the discrete
    clamp's elastica at 0.8 / 1.0 / 1.2 L*: alternating -0.97 / -0.97 /
    -0.95 %, regular +1.85 / +1.45 / +1.18 % (the curvature-jump penalty's
    bias, docs/fidelity.md), Delaunay -0.10 / -0.22 / -0.25 %.  (On the
    Frontal-Delaunay strip it is +2.40 / +2.00 / +1.58 % at 10 mm and within
    1.6 % from 5 mm on: the same stiff bias, not tested here.)"""
    for frac in FRACTIONS:
        r = p.peirce_row(frac, COARSE, kind, "fem", "dihedral_shell")
        assert r["residual"] <= 1e-6
        assert abs(r["c_error_clamp"]) <= 0.02, (frac, r)


def test_clamp_offset_is_first_order():
    """Against the nominal elastica (clamp exactly at x = 0) the coarse strip
    is too compliant by the clamp's O(h) offset: dihedral_shell on the
    alternating grid -8.27 % at h = 10 mm, -3.74 % at 5 mm (ratio 0.45), while
    its error against the discrete clamp stays within 1 %."""
    coarse = p.peirce_row(1.0, COARSE, "alternating", "fem", "dihedral_shell")
    fine = p.peirce_row(1.0, COARSE / 2, "alternating", "fem", "dihedral_shell")
    assert 0.35 <= fine["c_error"] / coarse["c_error"] <= 0.6
    assert abs(fine["c_error_clamp"]) <= 0.01


@pytest.mark.parametrize("kind", ["alternating", "regular"])
def test_grid_lines_bending_length_within_half_a_percent(kind):
    """FE + grid_lines (the fem default on grids: line and twist elements),
    h = 10 mm: measured c error against the discrete clamp's elastica
    -0.34 % at L* on both patterns (the triangulation does not enter),
    -0.07 % at 5 mm; the bound is 0.5 %, a quarter of the standard's 2 %."""
    for frac in FRACTIONS:
        r = p.peirce_row(frac, COARSE, kind, "fem", "grid_lines")
        assert r["residual"] <= 1e-6
        assert abs(r["c_error_clamp"]) <= 0.005, (frac, r)


@pytest.mark.parametrize("bending_model", ["dihedral", "isometric"])
def test_per_hinge_models_within_two_percent_on_the_panel_meshers_meshes(bending_model):
    """The per-hinge sums, `dihedral` the fem default on sewing patterns and
    mesh files, are the plate where every vertex star meets five conditions
    (physics/hinge_consistency.py), which near-equilateral triangles nearly
    do.  On the strip meshed as distcloth meshes a garment panel (Gmsh's
    Frontal-Delaunay, tests/peirce.py ``frontal_strip_mesh``) the measured c
    error against the discrete clamp's elastica at 0.8 / 1.0 / 1.2 L* is
    -0.71 / -0.03 / -0.13 % at h = 10 mm and -1.27 / -0.85 / +0.21 % at 5 mm
    (dihedral; isometric within 0.2 % of it), -1.41 / 0.00 / -0.86 % at
    2.5 mm (docs/fidelity.md): within the standard's 2 % at every size,
    where the same models on jittered or right-angled meshes are 1.3-6 %
    short (below)."""
    for h in (COARSE, COARSE / 2):
        for frac in FRACTIONS:
            r = p.peirce_row(frac, h, "frontal", "fem", bending_model)
            assert r["residual"] <= 1e-6
            assert abs(r["c_error_clamp"]) <= 0.02, (h, frac, r)


@pytest.mark.parametrize("bending_model", ["dihedral", "isometric"])
def test_per_hinge_models_are_too_compliant_on_poorly_shaped_meshes(bending_model):
    """KNOWN DEFECT, characterised (docs/fidelity.md, docs/mesh_independence.md):
    on meshes far from equilateral the per-hinge sums leave c 3-5 % short (B
    9-15 % low) at h = 5 mm: measured dihedral alternating -5.03 %, regular
    -4.81 %, jittered Delaunay -2.93 % (isometric within 0.1 % of it), and
    the error does not shrink with h on the grids (where the default is
    grid_lines).  A scene whose mesh file is like that is warned at load
    (tests/test_hinge_consistency.py).  If this fails because the error fell
    under 2 %, the model improved: update it and docs/fidelity.md."""
    for kind in ("alternating", "regular", "delaunay"):
        r = p.peirce_row(1.0, COARSE / 2, kind, "fem", bending_model)
        assert -0.07 <= r["c_error_clamp"] <= -0.02, (kind, r)


@pytest.mark.parametrize("kind", ["alternating", "regular"])
def test_mass_spring_flexion_bending_length_within_two_percent(kind):
    """Mass-spring grids, flexion line elements (FlexionLineTerm): measured c
    error against the discrete clamp at h = 10 mm, 0.8 / 1.0 / 1.2 L*:
    -0.28 / -0.34 / -0.39 % (the triangulation does not enter: the same on
    both patterns; -0.02 % at 2.5 mm, docs/fidelity.md).  The flexion springs these replace hung nearly vertical
    (chord 86-87 deg, c 4-5x too short)."""
    for frac in FRACTIONS:
        r = p.peirce_row(frac, COARSE, kind, "mass_spring", "flexion")
        assert r["residual"] <= 1e-6
        assert abs(r["c_error_clamp"]) <= 0.02, (frac, r)
        assert math.isfinite(r["angle"])


def test_mass_spring_strip_with_one_newton_step_per_step():
    """The flexion springs' strip was stopped by the energy guard at step 1-2
    with one linearised Newton step per step.  With the line elements (linear,
    exact constant Jacobian) the dynamic hang from flat, backward Euler, 10 ms
    steps, one Newton step each, runs its 400 steps (the guard would raise)
    and after 4 s is within 1 deg of the equilibrium (measured 47.96 vs 47.73
    deg, residual 1 % of the weight; after 2 s it still swings, 50.4 deg and
    38 %: linearised at the predictor, the step damps less than one
    linearised at the start state did)."""
    L = p.astm_overhang()
    static, _ = p.simulate(L, COARSE, "regular", "mass_spring", "flexion")
    dynamic, _ = p.simulate(L, COARSE, "regular", "mass_spring", "flexion",
                            newton_iterations=1, step=0.01, steps=400)
    assert abs(dynamic - static) <= 1.0, (dynamic, static)


def test_mass_spring_mesh_file_bends_like_the_per_hinge_model():
    """A mass-spring mesh file bends by dihedral angles on its hinges: on the
    Delaunay strip at h = 5 mm c is -2.99 % off the discrete clamp's elastica
    (FE + dihedral -2.93 %: the same bending, another membrane).  With flexion
    springs across the edges it hung at 86 deg (c -63 %) or was stopped by the
    energy guard at step 1."""
    ms = p.peirce_row(1.0, COARSE / 2, "delaunay", "mass_spring", "flexion")
    fe = p.peirce_row(1.0, COARSE / 2, "delaunay", "fem", "dihedral")
    assert -0.05 <= ms["c_error_clamp"] <= -0.01, ms
    assert abs(ms["c_error_clamp"] - fe["c_error_clamp"]) <= 0.005, (ms, fe)
