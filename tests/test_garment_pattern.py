"""Sewing-pattern input (distcloth.garment.pattern, .curves): edge curves and
their lengths, the GarmentCode specification and the compact form, the
round trip, and the errors a bad pattern gives.

No MPI: every rank runs the same checks.  The two GarmentCode patterns are
read from ../shared/data/patterns (MIT, not copied into the repository).
"""
from __future__ import annotations

import copy
import json
import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.integrate import quad
from scipy.spatial.transform import Rotation

from distcloth.garment import PatternError, load_pattern, read_compact, read_garmentcode, \
    to_compact
from distcloth.garment.curves import Bezier, CircularArc, Line

PATTERNS = Path(__file__).resolve().parents[2] / "shared" / "data" / "patterns"
SKIRT = PATTERNS / "flare_skirt_specification.json"
DRESS = PATTERNS / "dress_pencil_specification.json"
needs_shared = pytest.mark.skipif(not SKIRT.exists() or not DRESS.exists(),
                                  reason="../shared/data/patterns is not beside this checkout")


def spec(path: Path) -> dict:
    return json.loads(path.read_text())


# ------------------------------------------------------------------ curves

def quadratic_length(p0, p1, p2) -> float:
    """Closed form of the quadratic Bézier's arc length, integral of
    sqrt(A t^2 + B t + C) over [0, 1] (a non-degenerate, non-straight curve)."""
    a, b = p0 - 2 * p1 + p2, 2 * (p1 - p0)
    A, B, C = 4 * a @ a, 4 * a @ b, b @ b
    s_abc, s_a, s_c = 2 * math.sqrt(A + B + C), math.sqrt(A), 2 * math.sqrt(C)
    return ((2 * A * s_a * s_abc + s_a * B * (s_abc - s_c)
             + (4 * C * A - B * B) * math.log((2 * s_a + B / s_a + s_abc) / (B / s_a + s_c)))
            / (8 * A * s_a))


def speed_integral(curve: Bezier) -> tuple[float, float]:
    """Arc length as the integral of |B'(t)| over [0, 1] by QUADPACK's adaptive
    Gauss-Kronrod rule (independent of the fixed composite Gauss-Legendre rule
    in curves.py), and QUADPACK's own error estimate."""
    return quad(lambda t: float(np.linalg.norm(curve.derivative(t))), 0.0, 1.0,
                epsabs=0.0, epsrel=1e-13, limit=200)


# The lengths must agree far inside the brief's 0.5 %: curves.py integrates to
# 1e-13 relative and the references are closed forms or QUADPACK to 1e-13;
# 1e-9 leaves room for rounding in the closed form's cancellation.
LENGTH_RTOL = 1e-9


def test_line_length_and_points():
    line = Line([0.1, -0.2], [0.4, 0.2])
    assert line.length() == pytest.approx(0.5, rel=1e-15)
    np.testing.assert_allclose(line.point([0.0, 0.5, 1.0]), [[0.1, -0.2], [0.25, 0.0], [0.4, 0.2]],
                               atol=1e-15)


@pytest.mark.parametrize("large", [False, True])
@pytest.mark.parametrize("right", [False, True])
def test_arc_length_and_side(large, right):
    """Arc length is r times the swept angle, 2 asin(d / 2r) for the small arc
    and 2 pi minus that for the large one; GarmentCode's ``right`` flag puts the
    arc right of the chord walked from start to end (pygarment CircleEdge:
    right = control_y < 0, control_y measured to the chord's left)."""
    a, b, r = np.array([0.0, 0.0]), np.array([0.3, 0.0]), 0.25
    arc = CircularArc(a, b, r, large, right)
    small = 2 * math.asin(0.3 / (2 * r))
    assert arc.length() == pytest.approx(r * (2 * math.pi - small if large else small),
                                         rel=1e-14)
    pts = arc.point(np.linspace(0.0, 1.0, 101))
    np.testing.assert_allclose(np.linalg.norm(pts - arc.center, axis=1), r, rtol=1e-13)
    np.testing.assert_array_equal(pts[[0, -1]], [a, b])
    mid = arc.point(0.5)
    # chord along +x: its right is -y
    assert (mid[1] < 0) == right
    # the large arc reaches further from the chord than the radius
    assert (abs(mid[1]) > r) == large


def test_arc_radius_below_half_chord_is_a_half_circle():
    """As an SVG arc (pygarment hands the params to svgpathtools.Arc), a radius
    too small for the chord is scaled up to half the chord."""
    arc = CircularArc([0.0, 0.0], [1.0, 0.0], 0.2, False, True)
    assert arc.radius == 0.5
    assert arc.length() == pytest.approx(0.5 * math.pi, rel=1e-14)
    np.testing.assert_allclose(arc.point(0.5), [0.5, -0.5], atol=1e-15)


QUADRATICS = [
    [[0.0, 0.0], [0.2, 0.3], [0.5, 0.0]],
    [[0.0, 0.0], [0.9, 0.05], [0.1, 0.4]],        # strongly asymmetric
    [[0.1, 0.2], [0.1, 0.6], [0.5, 0.6]],
]
CUBICS = [
    [[0.0, 0.0], [0.1, 0.35], [0.25, 0.2], [0.5, 0.0]],
    [[0.0, 0.0], [0.5, -0.2], [0.8, -0.35], [0.4, 0.1]],
    [[0.0, 0.0], [0.6, 0.3], [-0.1, 0.3], [0.5, 0.0]],     # an S with a tight turn
]


@pytest.mark.parametrize("control", QUADRATICS)
def test_quadratic_length_against_closed_form(control):
    curve = Bezier(control)
    assert curve.kind == "quadratic"
    assert curve.length() == pytest.approx(quadratic_length(*np.array(control)), rel=LENGTH_RTOL)


@pytest.mark.parametrize("control", CUBICS)
def test_cubic_length_against_quadrature(control):
    """A cubic's length has no closed form (an elliptic integral); the reference
    is the defining integral, evaluated by adaptive quadrature whose error
    estimate is checked to be far below the tolerance.  The integrand |B'(t)| is
    analytic on [0, 1] for these curves (B' has no zero there), the case where
    Gauss-Kronrod converges fast and its estimate is reliable."""
    curve = Bezier(control)
    t = np.linspace(0.0, 1.0, 10001)
    assert np.linalg.norm(curve.derivative(t), axis=1).min() > 1e-3   # no cusp
    reference, error = speed_integral(curve)
    assert error < 1e-12 * reference
    assert curve.length() == pytest.approx(reference, rel=LENGTH_RTOL)


@pytest.mark.parametrize("control", QUADRATICS[1:2] + CUBICS, ids=["q1", "c0", "c1", "c2"])
def test_bezier_parameter_inverts_the_arc_length(control):
    """t = parameter(s) has arc length s L from the start, by QUADPACK on
    |B'| (1e-13): positions along a Bézier edge are exact, not approximate."""
    curve = Bezier(control)
    s = np.linspace(0.0, 1.0, 201)
    done = [quad(lambda x: float(np.linalg.norm(curve.derivative(x))), 0.0, t, epsabs=0.0,
                 epsrel=1e-13, limit=200)[0] for t in curve.parameter(s)]
    np.testing.assert_allclose(np.array(done) / curve.length(), s, rtol=0, atol=1e-12)


def max_curvature(curve) -> float:
    if isinstance(curve, CircularArc):
        return 1.0 / curve.radius
    t, dt = np.linspace(0.0, 1.0, 20001), 1e-6
    d1 = curve.derivative(t)
    d2 = (curve.derivative(t + dt) - curve.derivative(t - dt)) / (2 * dt)  # exact: B'' is linear
    return float(np.max(np.abs(d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0])
                        / np.linalg.norm(d1, axis=1) ** 3))


@pytest.mark.parametrize("curve", [
    CircularArc([0.0, 0.0], [0.3, 0.1], 0.2, True, False),
    Bezier(QUADRATICS[1]), Bezier(CUBICS[2])], ids=["arc", "quadratic", "cubic"])
def test_points_are_spaced_by_arc_length(curve):
    """point(s) is parametrised by arc length: 2000 equal steps in s give
    chords of the step's arc length c, shortened by at most c^3 k^2 / 24 for
    the largest curvature k (with 10 % margin on k from its sampling).  Steps
    equal in the Bézier parameter t instead vary the chords by more than 10 %."""
    s = np.linspace(0.0, 1.0, 2001)
    chords = np.linalg.norm(np.diff(curve.point(s), axis=0), axis=1)
    c = curve.length() / 2000
    shortening = (c * 1.1 * max_curvature(curve)) ** 2 / 24
    assert chords.max() <= c * (1 + 1e-9)
    assert chords.min() >= c * (1 - shortening - 1e-9)
    np.testing.assert_array_equal(curve.point(np.array([0.0, 1.0])),
                                  [curve.point(0.0), curve.point(1.0)])
    if isinstance(curve, Bezier):
        by_t = np.linalg.norm(np.diff(curve.at(s), axis=0), axis=1)
        assert by_t.max() > 1.1 * by_t.min()


@pytest.mark.parametrize("curve", [
    Line([0.0, 0.0], [0.3, 0.4]), CircularArc([0.0, 0.0], [0.3, 0.1], 0.2, True, True),
    Bezier(QUADRATICS[0]), Bezier(CUBICS[1])], ids=["line", "arc", "quadratic", "cubic"])
def test_tangent_is_the_derivative_of_point(curve):
    """Unit tangent against a central difference of point(s) (step 1e-6 of the
    length: truncation 1e-12, rounding 1e-10)."""
    s = np.linspace(0.05, 0.95, 19)
    eps = 1e-6
    fd = (curve.point(s + eps) - curve.point(s - eps)) / (2 * eps * curve.length())
    np.testing.assert_allclose(curve.tangent(s), fd, atol=1e-7)


# ------------------------------------------------------------------ GarmentCode

def square_spec(**props) -> dict:
    """A 10 x 10 (cm) front panel and its mirror image as a back panel, sewn
    along both sides."""
    front = {"translation": [0, 0, 10], "rotation": [0, 0, 0],
             "vertices": [[0, 0], [10, 0], [10, 10], [0, 10]],
             "edges": [{"endpoints": [0, 1]}, {"endpoints": [1, 2]},
                       {"endpoints": [2, 3]}, {"endpoints": [3, 0]}]}
    back = copy.deepcopy(front)
    back["translation"] = [0, 0, -10]
    back["vertices"] = [[0, 0], [0, 10], [10, 10], [10, 0]]
    return {"pattern": {"panels": {"front": front, "back": back},
                        "stitches": [[{"panel": "front", "edge": 1}, {"panel": "back", "edge": 2}],
                                     [{"panel": "front", "edge": 3}, {"panel": "back", "edge": 0}]]},
            "properties": {"curvature_coords": "relative", "units_in_meter": 100, **props}}


@needs_shared
def test_shared_patterns_read():
    skirt, dress = load_pattern(str(SKIRT)), load_pattern(str(DRESS))
    assert skirt.name == "flare_skirt" and dress.name == "dress_pencil"
    assert (len(skirt.panels), len(skirt.stitches)) == (4, 6)
    assert (len(dress.panels), len(dress.stitches)) == (6, 23)
    # panel_order is kept
    assert skirt.panel_names == ("wb_back", "skirt_back", "skirt_front", "wb_front")
    raw = spec(SKIRT)["pattern"]["panels"]["skirt_front"]
    front = skirt.panel("skirt_front")
    # centimetres to metres
    np.testing.assert_allclose(front.vertices, np.array(raw["vertices"]) / 100, rtol=1e-15)
    np.testing.assert_allclose(front.translation, np.array(raw["translation"]) / 100,
                               rtol=1e-15)
    assert front.label == "leg"
    assert dress.panel("skirt_back").edges[3].label == "lower_interface"
    np.testing.assert_array_equal(front.grain, [1.0, 0.0])
    kinds = {e.curve.kind for p in dress.panels for e in p.edges}
    assert kinds == {"line", "quadratic", "cubic"}
    assert {e.curve.kind for p in skirt.panels for e in p.edges} == {"line", "arc"}


@needs_shared
def test_flare_skirt_geometry_follows_the_conventions():
    """The skirt is a circle sector: hem and waist arcs bulge down (away from
    the waist), both centred on one point; front panels run counter-clockwise
    with their outside towards +z (the front), back panels clockwise with their
    outside towards -z."""
    skirt = load_pattern(str(SKIRT))
    front = skirt.panel("skirt_front")
    hem, waist = front.edges[1].curve, front.edges[3].curve
    assert hem.kind == waist.kind == "arc"
    np.testing.assert_allclose(hem.center, waist.center, atol=1e-9)
    for arc in (hem, waist):
        assert arc.point(0.5)[1] < min(arc.start[1], arc.end[1])
    assert (front.orientation, skirt.panel("skirt_back").orientation) == (1, -1)
    np.testing.assert_allclose(front.normal, [0, 0, 1], atol=1e-15)
    np.testing.assert_allclose(skirt.panel("skirt_back").normal, [0, 0, -1], atol=1e-15)
    # stitches sew the first side's start to the second side's end
    st = skirt.stitches[0]
    assert (st.a.panel, st.a.edges, st.a.reverse) == ("skirt_front", (0,), False)
    assert (st.b.panel, st.b.edges, st.b.reverse) == ("skirt_back", (3,), True)


def test_placement_is_rotation_then_translation():
    """p3 = R (x, y, 0) + t with R of Maya's xyz Euler angles (pygarment
    rotation.py euler_xyz_to_R = Rz Ry Rx), checked against scipy's extrinsic
    'xyz' rotation."""
    s = square_spec()
    s["pattern"]["panels"]["front"]["rotation"] = [30.0, -45.0, 60.0]
    s["pattern"]["panels"]["front"]["translation"] = [5.0, 100.0, 20.0]
    panel = read_garmentcode(s).panel("front")
    R = Rotation.from_euler("xyz", [30.0, -45.0, 60.0], degrees=True).as_matrix()
    local = np.array([[0.0, 0.0], [0.1, 0.0], [0.1, 0.1]])
    expected = np.c_[local, np.zeros(3)] @ R.T + [0.05, 1.0, 0.2]
    np.testing.assert_allclose(panel.place(local), expected, atol=1e-15)


def test_curvature_coordinates():
    """Relative control points: u along the edge, v to its left, in units of
    the edge's straight length (pygarment utils.rel_to_abs_2d); absolute ones
    are points of the panel's frame; the bare [u, v] is a quadratic."""
    s = square_spec()
    edges = s["pattern"]["panels"]["front"]["edges"]
    edges[0]["curvature"] = {"type": "quadratic", "params": [[0.5, -0.2]]}
    edges[1]["curvature"] = {"type": "cubic", "params": [[0.25, 0.1], [0.75, -0.1]]}
    edges[2]["curvature"] = [0.5, 0.3]
    front = read_garmentcode(s).panel("front")
    # edge 0 runs (0,0) -> (10,0): left is +y
    np.testing.assert_allclose(front.edges[0].curve.control[1], [0.05, -0.02], atol=1e-15)
    # edge 1 runs (10,0) -> (10,10): left is -x
    np.testing.assert_allclose(front.edges[1].curve.control[1:3], [[0.09, 0.025], [0.11, 0.075]],
                               atol=1e-15)
    # edge 2 runs (10,10) -> (0,10): left is -y
    assert front.edges[2].curve.kind == "quadratic"
    np.testing.assert_allclose(front.edges[2].curve.control[1], [0.05, 0.07], atol=1e-15)

    s = square_spec(curvature_coords="absolute")
    s["pattern"]["panels"]["front"]["edges"][0]["curvature"] = {
        "type": "quadratic", "params": [[5.0, -2.0]]}
    front = read_garmentcode(s).panel("front")
    np.testing.assert_allclose(front.edges[0].curve.control[1], [0.05, -0.02], atol=1e-15)


def test_units_and_normalized_translation():
    """units_in_meter scales vertices, translations and radii alike; with
    normalize_panel_translation each panel's vertex mean moves to its origin
    and into translation x, y (pygarment core.py _normalize_template), control
    points follow, and an unrotated panel stays where it was."""
    s = square_spec(curvature_coords="absolute")
    s["pattern"]["panels"]["front"]["edges"][0]["curvature"] = {
        "type": "quadratic", "params": [[5.0, -2.0]]}
    s["pattern"]["panels"]["front"]["edges"][2]["curvature"] = {
        "type": "circle", "params": [8.0, 0, 1]}
    base = read_garmentcode(s).panel("front")

    mm = copy.deepcopy(s)
    mm["properties"]["units_in_meter"] = 1000
    for p in mm["pattern"]["panels"].values():
        p["vertices"] = [[10 * x, 10 * y] for x, y in p["vertices"]]
        p["translation"] = [10 * x for x in p["translation"]]
    mm["pattern"]["panels"]["front"]["edges"][0]["curvature"]["params"] = [[50.0, -20.0]]
    mm["pattern"]["panels"]["front"]["edges"][2]["curvature"]["params"] = [80.0, 0, 1]
    in_mm = read_garmentcode(mm).panel("front")
    np.testing.assert_allclose(in_mm.vertices, base.vertices, atol=1e-15)
    assert in_mm.edges[2].length() == pytest.approx(base.edges[2].length(), rel=1e-14)

    s["properties"]["normalize_panel_translation"] = True
    moved = read_garmentcode(s).panel("front")
    np.testing.assert_allclose(moved.vertices.mean(axis=0), 0.0, atol=1e-15)
    np.testing.assert_allclose(moved.translation, [0.05, 0.05, 0.1], atol=1e-15)
    for e0, e1 in zip(base.edges, moved.edges):
        s_ = np.linspace(0.0, 1.0, 7)
        np.testing.assert_allclose(moved.place(e1.curve.point(s_)), base.place(e0.curve.point(s_)),
                                   atol=1e-15)


def test_right_wrong_stitch_is_not_reversed():
    s = square_spec()
    s["pattern"]["stitches"][1].append("right_wrong")
    st = read_garmentcode(s).stitches
    assert (st[0].b.reverse, st[1].b.reverse) == (True, False)


# ------------------------------------------------------------------ compact form

COMPACT = """
name: bodice
units_in_meter: 100
panels:
  front:
    vertices: [[0, 0], [40, 0], [40, 30], [30, 50], [10, 50], [0, 30]]
    edges:
      2: {quad: [[0.5, -0.1]], label: armhole}
      3: {label: shoulder}
      4: {arc: {radius: 12, large: false, right: true}, label: neck}
      5: {cubic: [[0.3, 0.05], [0.7, -0.05]]}
    translation: [-20, 100, 15]
    grain: [0, 1]
    label: body
  back:
    vertices: [[0, 0], [0, 30], [10, 50], [30, 50], [40, 30], [40, 0]]
    translation: [-20, 100, -15]
    rotation: [0, 180, 0]
    label: body
seams:
  - [front:1-2, back:4-5]
  - {sides: [front:5, "back:0"], label: side}
  - [front:3, back:2, right_wrong]
  - [{panel: front, edges: [0]}, {panel: back, edges: 1}]
"""


def assert_same_pattern(p, q):
    """Same panels (vertices, curves, placement, grain, labels) and stitches."""
    assert p.panel_names == q.panel_names
    for a, b in zip(p.panels, q.panels):
        assert (a.label, len(a.edges)) == (b.label, len(b.edges))
        np.testing.assert_allclose(a.rotation, b.rotation, atol=1e-15)
        np.testing.assert_allclose(a.translation, b.translation, atol=1e-15)
        np.testing.assert_allclose(a.grain, b.grain, atol=1e-15)
        for ea, eb in zip(a.edges, b.edges):
            assert (ea.curve.kind, ea.label) == (eb.curve.kind, eb.label)
            s = np.linspace(0.0, 1.0, 9)
            np.testing.assert_allclose(ea.curve.point(s), eb.curve.point(s), atol=1e-14)
    assert [(s.a, s.b, s.label) for s in p.stitches] == [(s.a, s.b, s.label) for s in q.stitches]


def test_compact_form_reads():
    p = read_compact(yaml.safe_load(COMPACT))
    front, back = p.panel("front"), p.panel("back")
    assert p.name == "bodice"
    assert [e.curve.kind for e in front.edges] == ["line", "line", "quadratic", "line", "arc",
                                                   "cubic"]
    assert front.edges[4].label == "neck" and front.label == "body"
    np.testing.assert_array_equal(front.grain, [0.0, 1.0])
    np.testing.assert_allclose(back.rotation @ [1, 0, 0], [-1, 0, 0], atol=1e-15)
    a, b, c, d = p.stitches
    assert (a.a.edges, a.b.edges, a.b.reverse) == ((1, 2), (4, 5), True)
    assert (b.label, c.b.reverse, c.label) == ("side", False, "shoulder")
    assert a.label == "armhole"          # from an edge of its sides
    assert (d.a.edges, d.b.edges) == ((0,), (1,))


def test_compact_side_may_wrap_around_the_loop():
    spec_ = yaml.safe_load(COMPACT)
    spec_["seams"] = [["front:5-0", "back:0-1"]]
    st = read_compact(spec_).stitches[0]
    assert (st.a.edges, st.b.edges) == ((5, 0), (0, 1))


def test_round_trip_compact_pattern_compact():
    """compact -> Pattern -> compact gives the same pattern, and the written
    form is a fixed point (written again, it is identical)."""
    original = read_compact(yaml.safe_load(COMPACT))
    written = to_compact(original)
    again = read_compact(yaml.safe_load(yaml.safe_dump(written, sort_keys=False)))
    assert_same_pattern(original, again)
    assert to_compact(again) == written


@needs_shared
@pytest.mark.parametrize("path", [SKIRT, DRESS], ids=["skirt", "dress"])
def test_garmentcode_to_compact_keeps_the_pattern(path, tmp_path):
    pattern = load_pattern(str(path))
    out = tmp_path / "pattern.yaml"
    out.write_text(yaml.safe_dump(to_compact(pattern), sort_keys=False))  # panel order
    assert_same_pattern(pattern, load_pattern(str(out)))


# ------------------------------------------------------------------ bad patterns

def _set(d, path, value):
    keys = path.split(".")
    for k in keys[:-1]:
        d = d[int(k) if isinstance(d, list) else k]
    last = keys[-1]
    if value is KeyError:
        del d[last]
    else:
        d[int(last) if isinstance(d, list) else last] = value


P = "pattern.panels.front"
GARMENTCODE_ERRORS = [
    # (key path changed, new value, key path reported, words of the message)
    ("pattern", KeyError, "pattern", "missing"),
    ("properties.units_in_meter", -1, "properties.units_in_meter", "got -1"),
    ("properties.curvature_coords", "polar", "properties.curvature_coords",
     "'relative' or 'absolute', got \"polar\""),
    ("properties.normalize_panel_translation", "yes", "properties.normalize_panel_translation",
     "got \"yes\""),
    (f"{P}.vertices.1", [10, "0"], f"{P}.vertices.1.1", "finite number, got \"0\""),
    (f"{P}.translation", [0, 0], f"{P}.translation", "3 numbers, got [0, 0]"),
    (f"{P}.rotation", [0, 0, math.inf], f"{P}.rotation.2", "finite number"),
    (f"{P}.edges.0.endpoints", KeyError, f"{P}.edges.0.endpoints", "missing"),
    (f"{P}.edges.1.endpoints", [1, 7], f"{P}.edges.1.endpoints.1", "7 does not exist (0 to 3)"),
    (f"{P}.edges.1.endpoints", [1, 3], f"{P}.edges.2.endpoints", "do not form a closed loop"),
    (f"{P}.edges.1.curvature", {"type": "spline", "params": []}, f"{P}.edges.1.curvature.type",
     "unknown curvature type \"spline\""),
    (f"{P}.edges.1.curvature", {"type": "circle", "params": [5, 0]},
     f"{P}.edges.1.curvature.params", "[radius, large_arc, right], got [5, 0]"),
    (f"{P}.edges.1.curvature", {"type": "circle", "params": [-5, 0, 1]},
     f"{P}.edges.1.curvature.params.0", "number > 0, got -5"),
    (f"{P}.edges.1.curvature", {"type": "circle", "params": [5, 2, 1]},
     f"{P}.edges.1.curvature.params.1", "0 or 1"),
    (f"{P}.edges.1.curvature", {"type": "cubic", "params": [[0.5, 0.1]]},
     f"{P}.edges.1.curvature.params", "2 control points"),
    (f"{P}.edges.1.curvature", [0.5], f"{P}.edges.1.curvature", "2 numbers, got [0.5]"),
    (f"{P}.edges.1.curvature", {"params": [[0.5, 0.1]]}, f"{P}.edges.1.curvature",
     "{type, params}"),
    (f"{P}.vertices", [[0, 0], [10, 0], [0, 10], [13, 10]], P, "edges 1 and 3 cross"),
    # a crossing exactly through a point where the outline is sampled
    (f"{P}.vertices", [[0, 0], [10, 0], [0, 10], [14, 10]], P, "edges 1 and 3 touch"),
    (f"{P}.vertices", [[0, 0], [10, 0], [10, 10], [5, 0]], P, "edges 0 and 2 touch"),
    ("pattern.stitches.0.1.panel", "sleeve", "pattern.stitches.0.1.panel",
     "no panel named \"sleeve\""),
    ("pattern.stitches.0.1.edge", 4, "pattern.stitches.0.1.edge", "4 does not exist (0 to 3)"),
    ("pattern.stitches.1.0.edge", 1, "pattern.stitches.1", "also in stitch 0"),
    ("pattern.stitches.0", [{"panel": "front", "edge": 1}], "pattern.stitches.0",
     "joins two edges"),
    ("pattern.stitches.0", {"from": {"panel": "front", "edge": 1}, "to": {}},
     "pattern.stitches.0", "not supported"),
]


@pytest.mark.parametrize("where,value,path,words", GARMENTCODE_ERRORS,
                         ids=[f"{e[0]}={e[1]!r}"[:60] for e in GARMENTCODE_ERRORS])
def test_bad_garmentcode_names_the_key_path(where, value, path, words):
    s = square_spec()
    _set(s, where, value)
    with pytest.raises(PatternError) as err:
        read_garmentcode(s)
    assert err.value.path == path
    assert words in err.value.message


COMPACT_ERRORS = [
    ("panels.front.colour", "red", "panels.front.colour", "unknown key (allowed:"),
    ("panels.front.vertices", [[0, 0], [1, 0]], "panels.front.vertices", "at least 3"),
    ("panels.front.vertices.1", [0, 0], "panels.front.vertices", "zero length"),
    ("panels.front.edges.9", {"quad": [[0.5, 0.1]]}, "panels.front.edges.9",
     "9 does not exist (0 to 5)"),
    ("panels.front.edges.2", {"quad": [[0.5, 0.1]], "arc": {"radius": 1}},
     "panels.front.edges.2", "one of arc, quad, cubic"),
    ("panels.front.edges.4", {"arc": {"large": True}}, "panels.front.edges.4.arc.radius",
     "missing"),
    ("panels.front.grain", [0, 0], "panels.front.grain", "must not be [0, 0]"),
    ("curve_coords", "polar", "curve_coords", "got \"polar\""),
    ("seams.0.0", "front-1", "seams.0.0", "expected 'panel:edge'"),
    ("seams.0.0", "front:1-3", "seams.2", "also in stitch 0"),
    ("seams.0.1", "sleeve:1", "seams.0.1", "no panel named \"sleeve\""),
    ("seams.3.1", {"panel": "back", "edges": [1, 3]}, "seams.3.1", "not consecutive"),
    ("seams.2.2", "wrong_right", "seams.2.2", "expected right_wrong"),
    ("seams.1.sides", ["front:5"], "seams.1.sides", "joins two sides: got 1"),
]


@pytest.mark.parametrize("where,value,path,words", COMPACT_ERRORS,
                         ids=[f"{e[0]}={e[1]!r}"[:60] for e in COMPACT_ERRORS])
def test_bad_compact_names_the_key_path(where, value, path, words):
    s = yaml.safe_load(COMPACT)
    _set(s, where, value)
    with pytest.raises(PatternError) as err:
        read_compact(s)
    assert err.value.path == path
    assert words in err.value.message


def test_bad_file_names_the_file(tmp_path):
    bad = tmp_path / "broken.yaml"
    bad.write_text("panels: [unclosed\n")
    with pytest.raises(PatternError, match="broken.yaml: not valid YAML"):
        load_pattern(str(bad))
    with pytest.raises(PatternError, match="No such file"):
        load_pattern(str(tmp_path / "missing.json"))
