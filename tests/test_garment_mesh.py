"""Panel meshes (distcloth.garment.mesh, .discretize): quality, orientation,
placement, which vertices lie on which edge, and the pairing of the two
sides of every stitch; on the two shared GarmentCode patterns and on small
hand-made ones.

Every rank meshes the same patterns and runs the same checks; MPI only
compares the ranks' meshes (they must be the same).
"""
from __future__ import annotations

import ctypes
import hashlib
import math
import signal

import numpy as np
import pytest
import yaml
from scipy.spatial import cKDTree

from distcloth.garment import MeshError, load_pattern, mesh_pattern, read_compact
from distcloth.garment import mesh as garment_mesh
from distcloth.garment.curves import Bezier
from distcloth.garment.discretize import Outlines

from test_garment_pattern import DRESS, SKIRT, needs_shared

H = 0.02            # target edge length for the shared patterns, m
MIN_ANGLE = 25.0
# Gmsh bounds no edge length: its target is h (Mesh.MeshSizeMax) and its frontal
# insertion leaves edges up to 1.31 h at 2 cm (1.39 h at 1 cm) on these patterns.
LONGEST = 1.5
# Shortest edge: nothing is inserted much closer than the outline's own segments;
# on these inputs the shortest edge is 0.67 of the shortest outline segment (or of
# h), so 0.5.
SHORTEST = 0.5
SIGINT_AT_COLLECTION = signal.getsignal(signal.SIGINT)     # before gmsh is imported


def angles(points, tris):
    """Corner angles (degrees) by the law of cosines, independent of
    mesh.triangle_angles."""
    a, b, c = (np.linalg.norm(points[tris[:, (k + 1) % 3]] - points[tris[:, (k + 2) % 3]],
                              axis=1) for k in range(3))
    A = np.degrees(np.arccos(np.clip((b * b + c * c - a * a) / (2 * b * c), -1, 1)))
    B = np.degrees(np.arccos(np.clip((a * a + c * c - b * b) / (2 * a * c), -1, 1)))
    return np.stack([A, B, 180.0 - A - B], axis=1)


def unique_edges(tris):
    e = np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]])
    return np.unique(np.sort(e, axis=1), axis=0)


def polygon_area(poly):
    x, y = poly[:, 0], poly[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


@pytest.fixture(scope="module")
def garments():
    if not SKIRT.exists() or not DRESS.exists():
        pytest.skip("../shared/data/patterns is not beside this checkout")
    return {name: mesh_pattern(load_pattern(str(path)), H)
            for name, path in (("skirt", SKIRT), ("dress", DRESS))}


def every_panel(garments):
    for mesh in garments.values():
        yield from mesh.panels


# ------------------------------------------------------------------ each panel

@needs_shared
def test_min_angle_and_edge_lengths(garments):
    for p in every_panel(garments):
        assert angles(p.vertices, p.triangles).min() >= MIN_ANGLE - 1e-9, p.panel.name
        e = unique_edges(p.triangles)
        length = np.linalg.norm(p.vertices[e[:, 0]] - p.vertices[e[:, 1]], axis=1)
        outline = p.vertices[:p.n_outline]
        seg = np.linalg.norm(np.roll(outline, -1, axis=0) - outline, axis=1)
        assert length.max() <= LONGEST * H, p.panel.name
        assert length.min() >= SHORTEST * min(seg.min(), H), p.panel.name
        # the outline keeps the target spacing (no segment was split at this h)
        assert seg.max() <= H * (1 + 1e-12), p.panel.name


@needs_shared
def test_mesh_covers_the_panel_once(garments):
    """Boundary edges are exactly the outline's segments, every interior edge
    has one triangle on each side, each directed edge appears once (a
    consistent orientation), and the triangles' areas add up to the
    outline polygon's."""
    for p in every_panel(garments):
        t = p.triangles
        directed = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
        assert np.unique(directed, axis=0).shape[0] == directed.shape[0], p.panel.name
        und, count = np.unique(np.sort(directed, axis=1), axis=0, return_counts=True)
        ring = np.arange(p.n_outline)
        outline_edges = np.sort(np.stack([ring, np.roll(ring, -1)], axis=1), axis=1)
        boundary = und[count == 1]
        assert np.array_equal(boundary, np.unique(outline_edges, axis=0)), p.panel.name
        assert count.max() == 2
        v = p.vertices
        area = 0.5 * np.abs(np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])).sum()
        assert area == pytest.approx(abs(polygon_area(v[:p.n_outline])), rel=1e-12)


@needs_shared
def test_triangles_face_outwards(garments):
    """Counter-clockwise seen from the outside: the skirt's front panels face
    +z (the front, where the body faces), its back panels -z; in general every
    triangle's normal is the panel's outside normal."""
    skirt = garments["skirt"]
    expected = {"skirt_front": 1, "wb_front": 1, "skirt_back": -1, "wb_back": -1}
    for name, sign in expected.items():
        p = skirt.panel(name)
        x = p.positions[p.triangles]
        n = np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0])
        assert np.all(sign * n[:, 2] > 0), name
    for p in every_panel(garments):
        x = p.positions[p.triangles]
        n = np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0])
        assert np.all(n @ p.panel.normal > 0), p.panel.name


@needs_shared
def test_placed_positions_and_edge_vertices(garments):
    for p in every_panel(garments):
        np.testing.assert_allclose(p.positions, p.panel.place(p.vertices), atol=1e-15)
        for k, (edge, idx, s) in enumerate(zip(p.panel.edges, p.edge_vertices,
                                               p.edge_fractions)):
            assert idx.size == s.size and s[0] == 0.0 and s[-1] == 1.0
            np.testing.assert_allclose(p.vertices[idx], edge.curve.point(s), atol=1e-14)
            # corners are the pattern's own vertices, shared with the next edge
            np.testing.assert_array_equal(p.vertices[idx[0]], p.panel.vertices[edge.start])
            assert idx[-1] == p.edge_vertices[(k + 1) % len(p.edge_vertices)][0]
        assert np.array_equal(np.unique(np.concatenate(p.edge_vertices)),
                              np.arange(p.n_outline))


@needs_shared
def test_outline_is_exactly_the_discretized_one(garments):
    """The outline vertices are those discretize.py places, bit for bit, and no
    vertex is added on the outline: the boundary edges' vertices are exactly
    the outline's, and every interior vertex keeps a distance from the outline
    (measured at least 0.43 h)."""
    for mesh in garments.values():
        outlines = Outlines(mesh.pattern, H)
        for p in mesh.panels:
            fractions = outlines.panel(p.panel.name)
            outline = np.concatenate([e.curve.point(s[:-1])
                                      for e, s in zip(p.panel.edges, fractions)])
            assert p.n_outline == outline.shape[0], p.panel.name
            np.testing.assert_array_equal(p.vertices[:p.n_outline], outline)
            for got, want in zip(p.edge_fractions, fractions):
                np.testing.assert_array_equal(got, want)
            t = p.triangles
            directed = np.sort(np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1)
            und, count = np.unique(directed, axis=0, return_counts=True)
            assert np.array_equal(np.unique(und[count == 1]), np.arange(p.n_outline))
            a, d = outline, np.roll(outline, -1, axis=0) - outline
            q = p.vertices[p.n_outline:]
            lam = np.clip(np.einsum("qnd,nd->qn", q[:, None] - a[None], d)
                          / np.einsum("nd,nd->n", d, d), 0.0, 1.0)
            gap = np.linalg.norm(q[:, None] - (a[None] + lam[..., None] * d[None]), axis=2)
            assert gap.min() > 0.3 * H, p.panel.name


def digest(mesh):
    return hashlib.sha1(mesh.positions.tobytes() + mesh.triangles.tobytes()).hexdigest()


@needs_shared
def test_meshing_is_deterministic_across_calls_and_ranks(garments, comm):
    """Meshing the dress again gives the same arrays bit for bit, also after
    other code has drawn from the C library's random generator (Gmsh reseeds
    its own from Mesh.RandomSeed at every meshing), and every rank builds
    the same mesh."""
    libc = ctypes.CDLL(None)
    libc.srand(12345)
    libc.rand()
    dress = garments["dress"]
    again = mesh_pattern(dress.pattern, H)
    np.testing.assert_array_equal(again.positions, dress.positions)
    np.testing.assert_array_equal(again.triangles, dress.triangles)
    for a, b in zip(again.seams, dress.seams):
        np.testing.assert_array_equal(a.pairs, b.pairs)
    digests = comm.allgather([digest(m) for m in garments.values()])
    assert all(d == digests[0] for d in digests)


# ------------------------------------------------------------------ stitches

def dense_fraction(curve, n=20001):
    """Points along a curve and their arc-length fractions, by a polyline
    through n points in the curve's own parameter (t for a Bézier, not the
    arc-length inversion being tested)."""
    t = np.linspace(0.0, 1.0, n)
    pts = curve.at(t) if isinstance(curve, Bezier) else curve.point(t)
    run = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
    return pts, run / run[-1]


def side_fractions_by_geometry(mesh, side, global_idx):
    """Arc-length fraction along the seam side of each (global) vertex, found
    by the nearest point of a dense polyline of each edge."""
    pm = mesh.panel(side.panel)
    edges = [pm.panel.edges[e] for e in side.edges]
    lengths = np.array([e.length() for e in edges])
    before = np.concatenate([[0.0], np.cumsum(lengths)])[:-1]
    local = global_idx - pm.offset
    out = np.full(local.size, np.nan)
    for k, (e, ei) in enumerate(zip(edges, side.edges)):
        on_edge = np.isin(local, pm.edge_vertices[ei])
        pts, frac = dense_fraction(e.curve)
        _, near = cKDTree(pts).query(pm.vertices[local[on_edge]])
        out[on_edge] = (before[k] + frac[near] * lengths[k]) / lengths.sum()
    return 1.0 - out if side.reverse else out


@needs_shared
def test_seams_pair_vertices_at_equal_arc_length(garments):
    """Both sides of every stitch have the same number of vertices, and the
    k-th of each lies at the same fraction of its side's arc length.  The
    fractions are measured on a 20,000-segment polyline of each edge: to
    1/20,000 of the edge, so 2e-4 of the side."""
    for mesh in garments.values():
        for seam in mesh.seams:
            st = seam.stitch
            fa = side_fractions_by_geometry(mesh, st.a, seam.pairs[:, 0])
            fb = side_fractions_by_geometry(mesh, st.b, seam.pairs[:, 1])
            assert not np.isnan(fa).any() and not np.isnan(fb).any()
            np.testing.assert_allclose(fa, fb, atol=2e-4)
            np.testing.assert_allclose(seam.fractions[:, 0], fa, atol=2e-4)
            assert fa[0] == pytest.approx(0.0, abs=1e-12)
            assert fa[-1] == pytest.approx(1.0, abs=1e-12)
            np.testing.assert_array_equal(np.diff(fa) > 0, True)
            # the longer side sets the count: no segment longer than h on it
            longer = max(sum(mesh.pattern.panel(s.panel).edges[e].length() for e in s.edges)
                         for s in (st.a, st.b))
            assert seam.pairs.shape[0] - 1 == math.ceil(longer / H)


@needs_shared
def test_seam_ends_follow_the_garmentcode_orientation(garments):
    """A stitch sews side a's start to side b's end (pygarment's default swap):
    where the two choices differ, the stitch's pairing brings paired vertices
    nearer each other in the panels' 3D placement than the other one would."""
    decided = 0
    for mesh in garments.values():
        x = mesh.positions
        for seam in mesh.seams:
            a, b = seam.pairs[:, 0], seam.pairs[:, 1]
            ours = np.linalg.norm(x[a] - x[b], axis=1).mean()
            other = np.linalg.norm(x[a] - x[b[::-1]], axis=1).mean()
            if abs(ours - other) > 0.05 * max(ours, other):
                assert ours < other, seam.stitch
                decided += 1
    assert decided >= 20        # of 29 stitches; the rest are too short or too far apart


@needs_shared
def test_dart_tip_is_sewn_to_itself(garments):
    """skirt_back's darts are stitches between consecutive edges of one panel:
    their shared vertex (the tip) is paired with itself."""
    dress = garments["dress"]
    darts = [s for s in dress.seams if s.stitch.a.panel == s.stitch.b.panel == "skirt_back"]
    assert len(darts) == 4
    for s in darts:
        assert s.pairs[-1, 0] == s.pairs[-1, 1]
        assert np.all(s.pairs[:-1, 0] != s.pairs[:-1, 1])


# The stitched lengths (side a, side b, cm) and their mismatch (a - b) / max(a, b)
# as docs/garments.md reports them; the gathered waist seams of the dress are
# 23 % longer on the bodice.
SEAM_LENGTHS = {
    "skirt": [(40.54, 40.54), (40.54, 40.54), (3.52, 3.52), (3.52, 3.52), (45.88, 42.17),
              (41.33, 42.17)],
    "dress": [(19.02, 19.02), (21.14, 21.14), (21.14, 21.14), (19.02, 19.02), (25.64, 25.64),
              (23.57, 24.78), (23.57, 24.78), (25.64, 25.64), (4.71, 4.71), (33.80, 33.71),
              (4.71, 4.71), (33.80, 33.71), (42.83, 42.83), (51.65, 51.65), (28.69, 22.03),
              (28.69, 22.03), (1.48, 1.14), (10.64, 8.17), (5.94, 4.56), (8.17, 6.27),
              (9.64, 7.41), (5.94, 4.56), (10.64, 8.17)],
}


@needs_shared
def test_stitched_lengths_as_documented(garments):
    """Side lengths measured on the meshes' seam polylines (which fall short of
    the curves by under 0.1 % at this h) against the documented ones (0.01 cm
    rounding plus that)."""
    for name, mesh in garments.items():
        x = mesh.positions
        got = [tuple(100 * np.linalg.norm(np.diff(x[s.pairs[:, k]], axis=0), axis=1).sum()
                     for k in (0, 1)) for s in mesh.seams]
        np.testing.assert_allclose(got, SEAM_LENGTHS[name], rtol=1e-3, atol=0.006)


def test_meshing_is_deterministic():
    """Every rank builds the same model: two meshings are identical, bit for
    bit (also without the shared patterns)."""
    p = read_compact(yaml.safe_load(BODICE))
    m1, m2 = mesh_pattern(p, 0.04), mesh_pattern(p, 0.04)
    np.testing.assert_array_equal(m1.positions, m2.positions)
    np.testing.assert_array_equal(m1.triangles, m2.triangles)


def test_gmsh_leaves_ctrl_c_alone():
    """Debian's gmsh resets SIGINT to the default action when imported;
    mesh.py puts the handler back, so Ctrl-C still raises KeyboardInterrupt."""
    mesh_pattern(read_compact(yaml.safe_load(STRIP)), 0.05)
    assert SIGINT_AT_COLLECTION is not signal.SIG_DFL
    assert signal.getsignal(signal.SIGINT) is SIGINT_AT_COLLECTION


# ------------------------------------------------------------------ hand-made patterns

BODICE = """
units_in_meter: 100
panels:
  front:
    vertices: [[0, 0], [40, 0], [40, 30], [30, 50], [10, 50], [0, 30]]
    edges:
      2: {quad: [[0.5, -0.1]]}
      4: {arc: {radius: 12, right: true}}
      5: {cubic: [[0.3, 0.05], [0.7, -0.05]]}
    translation: [-20, 100, 15]
  back:
    vertices: [[0, 0], [0, 45], [40, 45], [40, 0]]
    translation: [-20, 100, -15]
seams:
  - [front:0-1, back:3]         # two edges (40 + 30 cm) sewn to one (40 cm)
  - [front:5, back:0]
"""


def test_a_side_of_several_edges():
    """Side a has a corner at 4/7 of its length; side b gets a vertex at the
    same fraction, and the counts match though the sides differ by 30 cm."""
    mesh = mesh_pattern(read_compact(yaml.safe_load(BODICE)), 0.03)
    seam = mesh.seams[0]
    front = mesh.panel("front")
    corner = front.edge_vertices[0][-1] + front.offset
    k = int(np.flatnonzero(seam.pairs[:, 0] == corner)[0])
    assert seam.fractions[k, 0] == pytest.approx(4 / 7, abs=1e-15)
    assert seam.fractions[k, 1] == pytest.approx(4 / 7, abs=1e-15)
    np.testing.assert_allclose(seam.fractions[:, 0], seam.fractions[:, 1], atol=1e-15)
    # 70 cm at 3 cm: 40 cm -> 14 segments, 30 cm -> 10
    assert seam.pairs.shape[0] == 14 + 10 + 1
    for p in mesh.panels:
        assert angles(p.vertices, p.triangles).min() >= MIN_ANGLE - 1e-9


NEAR_CORNERS = """
units_in_meter: 100
panels:
  a: {vertices: [[0, 0], [30, 0], [40, 0], [40, 20], [0, 20]]}
  b: {vertices: [[0, 0], [0, 20], [40.1, 20], [40.1, 0], [30.03, 0]], translation: [0, 0, -10]}
seams:
  - [a:0-1, b:3-4]
"""


def test_nearly_matching_corners_are_merged():
    """Side a's corner is at 3/4 of its length, side b's at 30.03/40.1 = 0.7489:
    0.05 cm apart, under h/4, so one vertex pair stands for both corners (their
    fractions differ by that much) instead of leaving a 0.05 cm segment."""
    h = 0.02
    mesh = mesh_pattern(read_compact(yaml.safe_load(NEAR_CORNERS)), h)
    seam = mesh.seams[0]
    gap = np.abs(seam.fractions[:, 0] - seam.fractions[:, 1])
    assert 0.0 < gap.max() <= 0.25 * h / 0.401
    corner_a = mesh.panel("a").edge_vertices[0][-1] + mesh.panel("a").offset
    corner_b = mesh.panel("b").edge_vertices[3][-1] + mesh.panel("b").offset
    assert [corner_a, corner_b] in seam.pairs.tolist()
    for p in mesh.panels:
        o = p.vertices[:p.n_outline]
        assert np.linalg.norm(np.roll(o, -1, axis=0) - o, axis=1).min() > 0.4 * h
        assert angles(p.vertices, p.triangles).min() >= MIN_ANGLE - 1e-9


STRIP = """
units_in_meter: 100
panels:
  band:
    vertices: [[0, 0], [45, 0], [45, 3.5], [0, 3.5]]
  skirt:
    vertices: [[0, 0], [40, -30], [85, -30], [45, 0]]
    translation: [0, -40, 0]
seams:
  - [band:0, skirt:3]
"""


@pytest.mark.parametrize("h", [0.1, 0.2, 0.5])
def test_coarse_target_refines_the_outline_where_needed(h):
    """A 3.5 cm band at h >= 10 cm cannot be meshed to 25 degrees on h-spaced
    outline vertices by any of Gmsh's algorithms; the outline segments that
    the bad triangles encroach are split, on both sides of the stitch."""
    mesh = mesh_pattern(read_compact(yaml.safe_load(STRIP)), h)
    band = mesh.panel("band")
    assert band.edge_vertices[0].size - 1 > math.ceil(0.45 / h)
    seam = mesh.seams[0]
    np.testing.assert_allclose(seam.fractions[:, 0], seam.fractions[:, 1], atol=1e-15)
    for p in mesh.panels:
        assert angles(p.vertices, p.triangles).min() >= MIN_ANGLE - 1e-9


@pytest.mark.parametrize("degrees", [10.0, 15.0, 24.0])
def test_sharp_corner_is_left_alone(degrees):
    """A corner sharper than 25 degrees cannot be meshed to 25 degrees: the
    triangles below the bound are those spanning the wedge (a vertex on each
    of its two edges), and none is sharper than the corner itself (less a
    degree for the wedge's triangles not being isosceles)."""
    c, s = math.cos(math.radians(degrees)), math.sin(math.radians(degrees))
    mesh = mesh_pattern(read_compact({"panels": {"wedge": {"vertices": [[0, 0], [1, 0],
                                                                        [c, s]]}}}), 0.05)
    p = mesh.panels[0]
    a = angles(p.vertices, p.triangles).min(axis=1)
    low = a < MIN_ANGLE - 1e-9
    assert low.any()
    on = [np.isin(p.triangles[low], p.edge_vertices[e]).any(axis=1) for e in (0, 2)]
    assert np.all(on[0] & on[1])
    assert a.min() >= degrees - 1.0


def test_bad_target_edge():
    p = read_compact(yaml.safe_load(STRIP))
    for h in (0.0, -0.1, math.nan):
        with pytest.raises(ValueError, match="target edge length"):
            mesh_pattern(p, h)
    with pytest.raises(ValueError, match="min_angle"):
        mesh_pattern(p, 0.05, min_angle=40.0)


def test_mesh_error_is_a_runtime_error():
    assert issubclass(MeshError, RuntimeError)


def test_no_algorithm_reaching_the_bound_is_an_error(monkeypatch):
    """Where no Gmsh algorithm reaches the bound and splitting the outline is
    not possible (here: made so), the error names the panel and the angle
    instead of returning the mesh."""
    monkeypatch.setattr(garment_mesh, "_encroached", lambda *args: np.empty(0, dtype=int))
    with pytest.raises(MeshError, match=r"panel 'band': no Gmsh algorithm reached 25 "
                                        r"degrees \(best: .*, an angle of 21\.3 degrees\)"):
        mesh_pattern(read_compact(yaml.safe_load(STRIP)), 0.1)


def test_gmsh_failure_is_a_mesh_error():
    """A crossing outline makes Gmsh fail: a MeshError with Gmsh's message,
    not the abort of the process that Gmsh's default error handling (an
    exception thrown inside its OpenMP region) would cause."""
    bow = np.array([[0.0, 0.0], [1.0, 1.0], [1.0, 0.0], [0.0, 1.0]])
    for algorithm, _ in garment_mesh.ALGORITHMS:
        with pytest.raises(MeshError, match="panel 'bow'.*Unable to recover the edge"):
            garment_mesh._triangulate(bow, 0.1, algorithm, "bow")
