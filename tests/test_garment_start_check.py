"""Start-state checks (distcloth/garment/start_check.py): inside test and
signed distance against exact answers, triangle crossings on constructed
meshes, and the real body offset along its normals."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from meshes import grid_mesh, icosphere, winding_number
from distcloth.garment.start_check import (BodyIntersections, ClosedMesh, StartReport,
                                           body_intersections, boundary_edges, check_start,
                                           describe, inside_closed_mesh, self_intersections,
                                           signed_distance_to_closed_mesh)

BODY = Path("/work/shared/data/bodies/mean_all.obj")


def unit_cube():
    """[0, 1]^3, 12 outward triangles."""
    x = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], float)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    tri = np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))], np.int64)
    return x, tri


def box_sdf(p):
    """Exact signed distance to [0, 1]^3."""
    q = np.abs(p - 0.5) - 0.5
    return np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0)


def sagitta(x, tri):
    """1 - (smallest distance of a face plane from the origin): every point of
    a mesh inscribed in the unit sphere has radius in [1 - s, 1], and every
    sphere point is within s of the mesh radially, so s bounds the Hausdorff
    distance between the mesh and the sphere, hence also the difference of
    their (signed) distance functions."""
    a, b, c = (x[tri[:, k]] for k in range(3))
    n = np.cross(b - a, c - a)
    return 1.0 - np.min(np.abs(np.einsum("ij,ij->i", n, a)) / np.linalg.norm(n, axis=1))


# ------------------------------------------------------------------ inside test

def test_cube_lattice_exact_including_surface_points():
    # lattice points sit on the cube's faces, edges, vertices and face
    # diagonals: every ray grazing one must be detected and replaced
    x, tri = unit_cube()
    g = np.arange(-2, 7) / 4.0
    p = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
    expected = np.all((p >= 0.0) & (p <= 1.0), axis=1)          # closed set
    assert np.array_equal(inside_closed_mesh(p, x, tri), expected)
    # an inward oriented copy is the same solid
    assert np.array_equal(inside_closed_mesh(p, x, tri[:, ::-1]), expected)


def test_icosphere_inside_outside():
    x, tri = icosphere(3)
    s = sagitta(x, tri)
    rng = np.random.default_rng(3)
    d = rng.normal(size=(3000, 3))
    r = rng.uniform(0.0, 2.0, 3000)
    p = d / np.linalg.norm(d, axis=1)[:, None] * r[:, None]
    sure = (r < 1.0 - s) | (r > 1.0)          # the shell between face and sphere is the mesh's call
    mesh = ClosedMesh(x, tri)
    assert mesh.closed and mesh.n_boundary_edges == 0
    assert np.array_equal(mesh.inside(p[sure]), r[sure] < 1.0)


@pytest.mark.parametrize("t", [0.25, 1.0])
def test_rays_through_vertices_and_edges(t):
    # points whose first ray passes through a vertex or an edge midpoint (to
    # rounding): most of these rays are not certified (measured 714 and 915
    # of 1122) and a later direction decides
    x, tri = icosphere(2)
    mesh = ClosedMesh(x, tri)
    e = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    p = np.concatenate([x, 0.5 * (x[e[:, 0]] + x[e[:, 1]])]) - t * mesh.directions[0]
    r = np.linalg.norm(p, axis=1)
    sure = (r < 1.0 - sagitta(x, tri)) | (r > 1.0)
    assert np.array_equal(mesh.inside(p[sure]), r[sure] < 1.0)


def test_winding_number_of_open_and_overlapping_meshes():
    x, tri = icosphere(2)
    holed = tri[5:]                                          # a hole of 5 faces
    assert boundary_edges(holed).shape[0] > 0
    mesh = ClosedMesh(x, holed)
    assert not mesh.closed
    rng = np.random.default_rng(4)
    p = rng.uniform(-1.5, 1.5, size=(200, 3))
    # the exact generalized winding number, brute force over all faces
    assert np.allclose(mesh.winding_number(p), winding_number(p, x, holed), atol=1e-9)
    # two overlapping spheres: w = 2 in the lens, still inside
    both_x = np.concatenate([x, x + [1.0, 0.0, 0.0]])
    both_t = np.concatenate([tri, tri + x.shape[0]])
    w = ClosedMesh(both_x, both_t).winding_number([[0.5, 0, 0], [-0.5, 0, 0], [3.0, 0, 0]])
    assert np.array_equal(w, [2.0, 1.0, 0.0])


# ------------------------------------------------------------------ signed distance

def test_signed_distance_to_sphere_within_sagitta():
    x, tri = icosphere(4)
    s = sagitta(x, tri)                                      # 1.1e-3 at level 4
    rng = np.random.default_rng(5)
    d = rng.normal(size=(2000, 3))
    r = rng.uniform(0.2, 2.0, 2000)
    p = d / np.linalg.norm(d, axis=1)[:, None] * r[:, None]
    sd = signed_distance_to_closed_mesh(p, x, tri)
    assert np.all(np.abs(sd - (r - 1.0)) <= s + 1e-12)
    assert np.all(sd[r < 1.0 - s] < 0.0) and np.all(sd[r > 1.0] > 0.0)


def test_signed_distance_to_cube_exact():
    x, tri = unit_cube()
    p = np.random.default_rng(6).uniform(-0.5, 1.5, size=(2000, 3))
    assert np.allclose(signed_distance_to_closed_mesh(p, x, tri), box_sdf(p), atol=1e-12)


# ------------------------------------------------------------------ crossings

def test_two_crossing_triangles():
    x = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0],
                  [0.2, 0.2, -0.5], [0.3, 0.2, 0.5], [0.2, 0.3, 0.5]], float)
    tri = np.array([[0, 1, 2], [3, 4, 5]])
    assert self_intersections(x, tri).tolist() == [[0, 1]]
    # moved off the first triangle's plane they are apart
    lifted = x + np.repeat([[0.0, 0.0, 0.0], [0.0, 0.0, 0.6]], 3, axis=0)
    assert self_intersections(lifted, tri).shape == (0, 2)


def test_separated_sheets_do_not_cross():
    a, ta = grid_mesh(6, 6, h=0.1)
    x = np.concatenate([a, a + [0.03, 0.02, 0.01]])
    tri = np.concatenate([ta, ta + a.shape[0]])
    assert self_intersections(x, tri).shape == (0, 2)


def test_strip_folded_through_itself():
    # centre line P0 -> P1 -> P2 -> P3 in the xz-plane, extruded over y in
    # [0, 1] with one quad per segment; segment P2P3 crosses segment P0P1
    # along the line x = 2.5, z = 0 (at 5/8 of P0P1, 1/2 of P2P3)
    P = np.array([[0.0, 0.0], [4.0, 0.0], [3.0, 1.0], [2.0, -1.0]])
    x = np.array([[px, y, pz] for px, pz in P for y in (0.0, 1.0)])
    tri = []
    for i in range(3):
        a0, a1, b0, b1 = 2 * i, 2 * i + 1, 2 * i + 2, 2 * i + 3      # (P_i, y0/y1), (P_i+1, y0/y1)
        tri += [[a0, b0, b1], [a0, b1, a1]]                          # A_i: y <= t, B_i: y >= t
    # on the crossing line A0 covers y in [0, 5/8], B0 [5/8, 1], A2 [0, 1/2],
    # B2 [1/2, 1]: A0-A2, A0-B2, B0-B2 overlap, B0-A2 does not
    assert self_intersections(x, np.array(tri)).tolist() == [[0, 4], [0, 5], [1, 5]]


def two_panels(angle):
    """Two unit squares with a seam along x = 1 (vertices duplicated, not
    welded), the second turned by ``angle`` about the seam; canonical ids."""
    a, ta = grid_mesh(1, 1)                       # vertices (0,0) (0,1) (1,0) (1,1)
    c, s = np.cos(angle), np.sin(angle)
    b = np.array([[1.0 + u * c, v, u * s] for u, v in ((0, 0), (0, 1), (1, 0), (1, 1))])
    x = np.concatenate([a, b])
    tri = np.concatenate([ta, ta + 4])
    same = np.array([0, 1, 2, 3, 2, 3, 6, 7])     # b's seam vertices are a's 2 and 3
    return x, tri, same


@pytest.mark.parametrize("angle", [0.0, np.pi / 2])
def test_same_map_excludes_unsewn_seam_pairs(angle):
    x, tri, same = two_panels(angle)
    assert self_intersections(x, tri).shape[0] > 0            # closed triangles touch at the seam
    assert self_intersections(x, tri, same).shape == (0, 2)
    # a real crossing is still found: a triangle through the first panel
    x2 = np.concatenate([x, [[0.2, 0.3, -0.5], [0.3, 0.3, 0.5], [0.2, 0.4, 0.5]]])
    tri2 = np.concatenate([tri, [[8, 9, 10]]])
    same2 = np.concatenate([same, [8, 9, 10]])
    pairs = self_intersections(x2, tri2, same2)
    assert pairs.shape[0] > 0 and np.all(pairs[:, 1] == 4)


def test_body_intersections_sheet_through_sphere():
    bx, bt = icosphere(3)
    s = sagitta(bx, bt)
    g, gt = grid_mesh(10, 10, h=0.3)
    g = g - [1.5, 1.5, -0.1]                     # 3 m square at z = 0.1 through the unit sphere
    r = body_intersections(g, gt, bx, bt)
    r_g = np.linalg.norm(g, axis=1)
    sure = (r_g < 1.0 - s) | (r_g > 1.0)
    assert set(r.vertices) & set(np.flatnonzero(sure)) == set(np.flatnonzero(r_g < 1.0 - s))
    assert np.all(np.abs(r.depth - (1.0 - r_g[r.vertices])) <= s + 1e-12)
    # every garment triangle with corners on both sides crosses some body triangle
    straddle = np.flatnonzero(np.any(r_g[gt] < 1.0 - s, axis=1) & np.any(r_g[gt] > 1.0, axis=1))
    assert set(straddle) <= set(r.triangle_pairs[:, 0])
    assert not r.ok


def test_body_clearance():
    bx, bt = icosphere(3)
    patch, pt = grid_mesh(4, 4, h=0.05)
    patch = patch - [0.1, 0.1, -1.05]            # just above the north pole, outside
    clear = body_intersections(patch, pt, bx, bt)
    assert clear.ok and describe(clear) == "no garment vertex inside the body, no triangle crossing"
    near = body_intersections(patch, pt, bx, bt, clearance=0.1)   # all within 0.06 + sagitta
    assert near.vertices.tolist() == list(range(patch.shape[0]))
    assert np.all(near.depth < 0.0) and near.triangle_pairs.shape == (0, 2)


def test_describe():
    body = BodyIntersections(np.array([17, 18, 305, 400]), np.array([0.001, 0.0042, 0.002, 0.0]),
                             np.empty((0, 2), np.int64))
    pairs = np.array([[10, 44], [12, 50]])
    assert describe(StartReport(body, pairs), limit=3) == (
        "4 garment vertices inside the body (deepest 4.2 mm: vertices 18, 305, 17, ...) "
        "and 2 triangle pairs crossing each other (triangles 10 & 44, 12 & 50)")
    assert describe(pairs[:1]) == "1 triangle pair crossing each other (triangles 10 & 44)"
    x, tri, same = two_panels(0.0)
    assert check_start(x, tri, same=same).ok


# ------------------------------------------------------------------ the real body

@pytest.fixture(scope="module")
def body():
    if not BODY.exists():
        pytest.skip(f"{BODY} not present")
    # only this test needs the OBJ reader (and the scene package it is in)
    from distcloth.scene.meshio import read_mesh
    x, tri = read_mesh(str(BODY))
    return np.asarray(x, float), np.asarray(tri, np.int64)


def vertex_normals(x, tri):
    """Angle-weighted unit vertex normals."""
    c = [x[tri[:, k]] for k in range(3)]
    fn = np.cross(c[1] - c[0], c[2] - c[0])
    fn /= np.linalg.norm(fn, axis=1)[:, None]
    n = np.zeros_like(x)
    for k in range(3):
        e1, e2 = c[(k + 1) % 3] - c[k], c[(k + 2) % 3] - c[k]
        ang = np.arctan2(np.linalg.norm(np.cross(e1, e2), axis=1), np.einsum("ij,ij->i", e1, e2))
        np.add.at(n, tri[:, k], ang[:, None] * fn)
    return n / np.linalg.norm(n, axis=1)[:, None]


def test_body_vertices_offset_along_normals(body):
    x, tri = body
    mesh = ClosedMesh(x, tri)
    assert mesh.closed and mesh.orientation == 1.0             # watertight, outward
    n, h = vertex_normals(x, tri), 0.005
    out, inn = x + h * n, x - h * n
    bad_out = np.flatnonzero(mesh.inside(out))
    bad_in = np.flatnonzero(~mesh.inside(inn))
    # Measured: 160 outward and 132 inward of 23,752 fail (eyes, lips,
    # nostrils, ears, armpits, crotch).  Where the surface within h of a
    # vertex is flat or convex and the body thicker than h, the pushed point's
    # closest surface point is the vertex itself, at distance h, and the test
    # must get it right.  A failure must show that this does not hold: the
    # pushed point is nearer than h to the surface (a crease or another
    # sheet within reach: eyelids, lips, armpit folds) ...
    assert bad_out.size < 0.01 * x.shape[0] and bad_in.size < 0.01 * x.shape[0]
    assert np.all(mesh.distance(inn[bad_in]) < 0.99 * h)        # measured max 0.36 h
    d = mesh.distance(out[bad_out])
    # ... or the vertex itself lies inside another part of the body (the
    # mesh self-intersects at the lips and armpits): brute-force solid
    # angles just outside those few vertices (4 measured, d > 0.999 h)
    buried = bad_out[d >= 0.99 * h]
    assert buried.size <= 10
    assert np.all(winding_number(x[buried] + 1e-5 * n[buried], x, tri) > 0.5)
