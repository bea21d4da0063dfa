"""The clearance cloth keeps from a closed body's vertices in the triangle
pipeline (distcloth.collision.sagitta, impulses.pair_thickness): curvature
against the sphere's exact 1/R, and the repulsion leaving a cloth triangle
alone when its corners rest at the contact offset over a curved body (the
pump it made before) while still stopping one that comes closer."""
from __future__ import annotations

import numpy as np
from serial_oracles import serial_candidates

from distcloth.collision import impulses as I
from distcloth.collision.proximity import mesh_edges
from distcloth.collision.sagitta import body_clearance, convex_curvature


def icosphere(radius, levels=4):
    """A closed, outward-oriented geodesic sphere (icosahedron split
    ``levels`` times), turned so that vertex 0 is the north pole."""
    p = (1 + 5 ** 0.5) / 2
    x = np.array([[-1, p, 0], [1, p, 0], [-1, -p, 0], [1, -p, 0], [0, -1, p], [0, 1, p],
                  [0, -1, -p], [0, 1, -p], [p, 0, -1], [p, 0, 1], [-p, 0, -1], [-p, 0, 1]],
                 float)
    tri = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9],
                    [5, 11, 4], [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2],
                    [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10],
                    [8, 6, 7], [9, 8, 1]])
    for _ in range(levels):
        e = mesh_edges(tri)
        mid = {(int(a), int(b)): x.shape[0] + k for k, (a, b) in enumerate(e)}
        x = np.vstack([x, 0.5 * (x[e[:, 0]] + x[e[:, 1]])])
        m = lambda a, b: mid[(min(a, b), max(a, b))]               # noqa: E731
        tri = np.array([t for a, b, c in tri for t in
                        ([a, m(a, b), m(c, a)], [b, m(b, c), m(a, b)], [c, m(c, a), m(b, c)],
                         [m(a, b), m(b, c), m(c, a)])])
    x /= np.linalg.norm(x, axis=1)[:, None]
    # turn vertex 0 to +z (Rodrigues)
    a, z = x[0], np.array([0.0, 0.0, 1.0])
    v, c = np.cross(a, z), float(a @ z)
    K = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    rot = np.eye(3) + K + K @ K / (1 + c)
    return radius * x @ rot.T, tri


def test_curvature_of_a_sphere_plane_and_hollow():
    R = 0.05
    x, tri = icosphere(R)
    k = convex_curvature(x, tri)
    # kappa_ij = (n_i - n_j).(x_i - x_j) / |x_i - x_j|^2 is exactly 1/R with
    # exact normals; area-weighted normals of a geodesic sphere (5120
    # triangles, 1.4 degrees between neighbours) differ from the exact ones
    # by a small fraction of that angle, which is up to 4 % of kappa here
    np.testing.assert_allclose(k, 1.0 / R, rtol=0.05)
    assert np.all(convex_curvature(x, tri[:, ::-1]) < 0.02 / R)    # inside-out: concave
    flat = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0.0]])
    assert np.allclose(convex_curvature(flat, np.array([[0, 1, 2], [0, 2, 3]])), 0.0)


def test_clearance_is_thickness_less_face_sagitta_with_floor():
    R, d = 0.05, 0.003
    x, tri = icosphere(R)
    keep = body_clearance(x, tri, d, 0.02, 0.1 * d)
    # 5 % on kappa (above) is 0.07 mm on the 1.33 mm sagitta: 4 % of the clearance
    np.testing.assert_allclose(keep, d - 0.02 ** 2 / (6 * R), rtol=0.05)
    assert np.all(body_clearance(x, tri, d, 0.05, 0.1 * d) == 0.1 * d)   # sag > d: the floor


def _triangle_over_pole(R, d, L, drop=0.0):
    """An equilateral cloth triangle of edge L centred over the sphere's north
    pole, its corners at distance d (less ``drop``) from the sphere."""
    rc = L / np.sqrt(3.0)
    ang = np.array([0.1, 0.1 + 2 * np.pi / 3, 0.1 + 4 * np.pi / 3])
    z = np.sqrt((R + d - drop) ** 2 - rc ** 2)
    return np.stack([rc * np.cos(ang), rc * np.sin(ang), np.full(3, z)], axis=1)


def _resolve(cloth, u_cloth, sphere, keep):
    x_s, tri_s = sphere
    n_c = cloth.shape[0]
    x0 = np.vstack([cloth, x_s])
    tri = np.vstack([[[0, 1, 2]], tri_s + n_c]).astype(np.int64)
    edges = mesh_edges(tri)
    inv = np.r_[np.ones(n_c), np.zeros(x_s.shape[0])]
    u = np.vstack([u_cloth, np.zeros_like(x_s)])
    th, h = 0.003, 0.01
    un, _ = I.resolve(x0, u, h, inv, tri, edges, th, 0.0, serial_candidates(tri, edges, th),
                      keep=keep)
    return un[:n_c]


def test_resting_triangle_is_not_lifted_but_an_approaching_one_is_stopped():
    R, d, L = 0.05, 0.003, 0.02
    sphere = icosphere(R)
    cloth = _triangle_over_pole(R, d, L)
    # the triangle's centre is ~1.7 mm over the pole vertex: inside the 3 mm
    # thickness, outside the clearance 3 - L^2 / 6R = 1.67 mm
    centre_gap = np.linalg.norm(cloth.mean(axis=0)) - R
    assert 0.0017 < centre_gap < 0.003
    full = np.full(3 + sphere[0].shape[0], 0.003)
    keep = np.r_[np.full(3, 0.003), body_clearance(*sphere, 0.003, L, 0.0003)]
    at_rest = np.zeros((3, 3))
    # full thickness: the pipeline lifts a triangle whose corners the contact
    # holds at d (the pump); with the clearance it leaves it at rest
    assert _resolve(cloth, at_rest, sphere, full)[:, 2].min() > 0.01
    np.testing.assert_array_equal(_resolve(cloth, at_rest, sphere, keep), at_rest)
    # a triangle that comes down fast is still stopped at the clearance, not
    # let through: its centre ends the step above the pole by at least the
    # clearance there (to the CCD's 1 % margin)
    down = np.tile([0.0, 0.0, -1.0], (3, 1))                         # 10 mm in the step
    u = _resolve(cloth, down, sphere, keep)
    end = cloth + 0.01 * u
    gap = end.mean(axis=0)[2] - R
    assert gap > 0.99 * keep[3]


def test_pairs_between_layers_keep_the_lower_layers_clearance():
    # vertex-face stencils (coef[:, 0] = 1) and edge-edge ones (coef[:, 0] < 0)
    # over vertices 0-1 (a body, priority -1), 2-5 (layer 0), 6-9 (layer 1);
    # keep: the body's clearance 1, the inner garment's 2, thickness 3
    priority = np.array([-1, -1, 0, 0, 0, 0, 1, 1, 1, 1], float)
    keep = np.array([1.0, 1.0, 2.0, 2.0, 2.0, 2.0, 3.0, 3.0, 3.0, 3.0])
    vf = np.array([1.0, -0.3, -0.3, -0.4])
    ee = np.array([-0.5, -0.5, 0.5, 0.5])
    ids = np.array([[2, 6, 7, 8],      # inner vertex under an outer face: the inner's
                    [6, 2, 3, 4],      # outer vertex over an inner face: thickness
                    [2, 3, 4, 5],      # one layer: thickness
                    [0, 2, 3, 4],      # body vertex under the inner garment: the body's
                    [2, 3, 6, 7],      # inner edge under an outer edge: the inner's
                    [6, 7, 2, 3],      # the same pair the other way round
                    [2, 3, 4, 5],      # edges of one layer: thickness
                    [0, 1, 6, 7]])     # a body edge under the outer garment: the body's
    coef = np.array([vf, vf, vf, vf, ee, ee, ee, ee])
    np.testing.assert_array_equal(I.pair_thickness(ids, coef, 3.0, keep, priority),
                                  [2.0, 3.0, 3.0, 1.0, 2.0, 2.0, 3.0, 1.0])
    # without layers, the per-vertex rule: a vertex-face pair its vertex's, an
    # edge-edge pair the smaller of its four
    np.testing.assert_array_equal(I.pair_thickness(ids, coef, 3.0, keep),
                                  [2.0, 3.0, 2.0, 1.0, 2.0, 2.0, 2.0, 1.0])
