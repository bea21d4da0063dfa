"""Closest-point / signed-distance queries against mesh colliders
(distcloth.collision.mesh_query): BVH search against a brute-force oracle,
the pseudo-normal sign against a winding-number inside test, surface
velocities of moving and deforming colliders, open two-sided panels and the
analytic sphere."""
from __future__ import annotations

from pathlib import Path

import numpy as np
from meshes import icosphere, winding_number
import pytest
from numba import njit

from distcloth.collision.colliders import (AnalyticCollider, MeshCollider, RigidMotion, Sphere,
                                           load_mesh_collider)
from distcloth.collision.mesh_query import MeshProximity
from distcloth.collision.proximity import point_triangle

ROOT = Path(__file__).resolve().parents[1]
TORSO = ROOT / "configs" / "meshes" / "torso.obj"


# ---------------------------------------------------------------- helpers

@njit(cache=True)
def _brute(pts, x, tri, dist, face):
    for i in range(pts.shape[0]):
        best = np.inf
        for f in range(tri.shape[0]):
            d = point_triangle(pts[i], x[tri[f, 0]], x[tri[f, 1]], x[tri[f, 2]])[0]
            if d < best:
                best = d
                face[i] = f
        dist[i] = best


def brute_force(pts, x, tri):
    """Oracle: point_triangle against every triangle, (distance, face)."""
    pts = np.ascontiguousarray(pts, dtype=np.float64)
    dist = np.empty(pts.shape[0])
    face = np.empty(pts.shape[0], np.int64)
    _brute(pts, np.ascontiguousarray(x), np.ascontiguousarray(tri, dtype=np.int64), dist, face)
    return dist, face


def random_directions(rng, n):
    d = rng.normal(size=(n, 3))
    return d / np.linalg.norm(d, axis=1)[:, None]


def feature_probes(rng, x, tri, scale, per=2):
    """Points just off vertices and edge midpoints (both sides, random
    directions), where the closest feature is a vertex or an edge."""
    e = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    base = np.concatenate([x, 0.5 * (x[e[:, 0]] + x[e[:, 1]])])
    base = np.repeat(base, per, axis=0)
    delta = scale * np.array([1e-2, 1e-4, 1e-7])[rng.integers(0, 3, base.shape[0])]
    return base + delta[:, None] * random_directions(rng, base.shape[0])


@pytest.fixture(scope="module")
def torso():
    return load_mesh_collider(TORSO)


def open_soup(rng):
    """A jittered height-field panel plus a soup of random triangles (open)."""
    n = 12
    s = np.linspace(-0.5, 0.5, n)
    gx, gy = np.meshgrid(s, s, indexing="ij")
    grid = np.stack([gx.ravel(), gy.ravel(), 0.05 * rng.normal(size=n * n)], axis=1)
    grid[:, :2] += rng.uniform(-0.01, 0.01, (n * n, 2))
    q = np.arange(n * n).reshape(n, n)
    a, b, c, d = q[:-1, :-1].ravel(), q[1:, :-1].ravel(), q[1:, 1:].ravel(), q[:-1, 1:].ravel()
    tri = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    soup = rng.uniform(-0.6, 0.6, (150, 1, 3)) + rng.normal(scale=0.08, size=(150, 3, 3))
    x = np.concatenate([grid, soup.reshape(-1, 3)])
    tri = np.concatenate([tri, n * n + np.arange(450).reshape(150, 3)])
    return x, tri


# ---------------------------------------------------------------- oracle

@pytest.mark.parametrize("mesh", ["torso", "open"])
def test_closest_matches_brute_force(mesh, torso):
    rng = np.random.default_rng(1)
    if mesh == "torso":
        col = torso
        x, tri = col.vertices(0.0), col.triangles
    else:
        x, tri = open_soup(rng)
        col = MeshCollider.static(x, tri)
    prox = MeshProximity(col)
    assert prox.closed == (mesh == "torso")
    lo, hi = x.min(0), x.max(0)
    size = float(np.max(hi - lo))
    pts = np.concatenate([rng.uniform(lo - 0.3 * size, hi + 0.3 * size, (2000, 3)),
                          feature_probes(rng, x, tri, size, per=1)[rng.permutation(1000)]])
    ref, _ = brute_force(pts, x, tri)
    face, w, dist = prox.closest(pts, 0.0)
    assert (face >= 0).all()
    np.testing.assert_allclose(dist, ref, rtol=1e-12, atol=1e-15 * size)
    # the reported face and weights reproduce the distance
    c = np.einsum("ij,ijk->ik", w, x[tri[face]])
    np.testing.assert_allclose(np.linalg.norm(pts - c, axis=1), ref, rtol=1e-9, atol=1e-14 * size)
    assert np.allclose(w.sum(axis=1), 1.0) and (w >= 0).all()
    # cutoff: everything beyond max_distance is dropped, the rest is unchanged
    srt = np.sort(ref)
    cut = 0.5 * (srt[900] + srt[901])                  # 901 points within, none on the cutoff
    keep = ref <= cut
    face_c, w_c, dist_c = prox.closest(pts, 0.0, max_distance=cut)
    np.testing.assert_array_equal(face_c >= 0, keep)
    np.testing.assert_allclose(dist_c[keep], ref[keep], rtol=1e-12, atol=1e-15 * size)
    assert np.isinf(dist_c[~keep]).all() and (w_c[~keep] == 0).all()
    phi, normal, vel = prox.query(pts, 0.0, max_distance=cut)
    assert np.isposinf(phi[~keep]).all() and (normal[~keep] == 0).all() and (vel[~keep] == 0).all()
    np.testing.assert_allclose(np.abs(phi[keep]), ref[keep], rtol=1e-12, atol=1e-15 * size)
    np.testing.assert_allclose(np.linalg.norm(normal[keep], axis=1), 1.0, atol=1e-12)
    # closest point is points - phi * normal
    np.testing.assert_allclose(pts[keep] - phi[keep, None] * normal[keep], c[keep],
                               atol=1e-10 * size)
    # max_distance = 0: nothing off the surface
    assert (prox.closest(pts, 0.0, 0.0)[0] == -1).all()
    with pytest.raises(ValueError):
        prox.closest(pts, 0.0, -1.0)


# ---------------------------------------------------------------- sign

def cube_mesh():
    """Unit cube, 12 outward triangles."""
    x = np.array([[i, j, k] for i in (0.0, 1.0) for j in (0.0, 1.0) for k in (0.0, 1.0)])
    tri = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                    [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    return x, tri


@pytest.mark.parametrize("mesh", ["spiky", "cube", "torso", "inward"])
def test_sign_matches_winding_number(mesh, torso):
    rng = np.random.default_rng(2)
    if mesh == "torso":
        x, tri = torso.vertices(0.0), torso.triangles
    elif mesh == "cube":
        x, tri = cube_mesh()
    else:
        # star-shaped, sharp convex and concave edges and vertices
        unit, tri = icosphere(2)
        x = np.array([0.1, 0.2, -0.3]) + 0.4 * unit * rng.uniform(0.6, 1.4, (unit.shape[0], 1))
        if mesh == "inward":                       # inward oriented: flipped automatically
            tri = tri[:, ::-1].copy()
    prox = MeshProximity(MeshCollider.static(x, tri))
    assert prox.closed
    lo, hi = x.min(0), x.max(0)
    size = float(np.max(hi - lo))
    pts = np.concatenate([rng.uniform(lo - 0.1 * size, hi + 0.1 * size, (1000, 3)),
                          feature_probes(rng, x, tri, size, per=1 if mesh == "torso" else 20)])
    pts = pts[rng.permutation(pts.shape[0])[:3000]]
    wn = winding_number(pts, x, tri)
    assert np.all((np.abs(wn) < 1e-6) | (np.abs(np.abs(wn) - 1) < 1e-6))
    inside = np.abs(wn) > 0.5
    assert 0.1 < inside.mean() < 0.9
    phi, normal, _ = prox.query(pts, 0.0)
    np.testing.assert_array_equal(phi < 0, inside)
    # on the spiky mesh (dihedral angles beyond 90 degrees) the test exercises
    # edges and vertices: with the closest face's normal alone some of these
    # points get the wrong sign
    face, w, dist = prox.closest(pts, 0.0)
    c = np.einsum("ij,ijk->ik", w, x[tri[face]])
    a, b, cc = (x[tri[face, k]] for k in range(3))
    fnormal = np.cross(b - a, cc - a) * (-1.0 if mesh == "inward" else 1.0)
    naive_inside = np.einsum("ij,ij->i", pts - c, fnormal) < 0
    if mesh in ("spiky", "inward"):
        assert (naive_inside != inside).sum() > 10
    # normals are outward: a small step along the normal increases phi
    far = np.abs(phi) > 1e-3 * size
    step = 1e-5 * size
    phi2, _, _ = prox.query(pts[far] + step * normal[far], 0.0)
    np.testing.assert_allclose(phi2 - phi[far], step, rtol=1e-6)


# ---------------------------------------------------------------- motion

def fd_material_velocity(col, face, w, t, h=1e-5):
    tri = col.triangles[face]
    pos = lambda s: np.einsum("ij,ijk->ik", w, col.vertices(s)[tri])
    return (pos(t + h) - pos(t - h)) / (2 * h)


def test_rigidly_moving_collider(torso):
    x, tri = torso.vertices(0.0), torso.triangles
    motion = RigidMotion([0.0, 1.0, 2.0], [[0, 0, 0], [0.2, -0.1, 0.3], [0.1, 0.3, 0.0]],
                         [[0, 0, 0], [0.3, -0.2, 0.5], [-0.4, 0.1, 1.2]])
    col = MeshCollider.static(x, tri, motion=motion)
    prox = MeshProximity(col)
    body = MeshProximity(MeshCollider.static(x, tri))
    rng = np.random.default_rng(3)
    pts_body = x[rng.integers(0, x.shape[0], 1500)] + rng.normal(scale=0.02, size=(1500, 3))
    for t in (0.4, 1.3):
        pts = motion.to_world(pts_body, t)
        phi, normal, vel = prox.query(pts, t)
        # rigid invariance: same distances as the body-frame query
        phi_b, normal_b, _ = body.query(pts_body, 0.0)
        np.testing.assert_allclose(phi, phi_b, atol=1e-12)
        R, _ = motion.transform(t)
        np.testing.assert_allclose(normal, normal_b @ R.T, atol=1e-8)
        face, w, _ = prox.closest(pts, t)
        np.testing.assert_allclose(vel, fd_material_velocity(col, face, w, t), atol=1e-7)
        # and equal to the rigid velocity field at the closest point
        np.testing.assert_allclose(vel, motion.point_velocity(pts - phi[:, None] * normal, t),
                                   atol=1e-12)


def test_deforming_collider_and_cache(torso):
    x0, tri = torso.vertices(0.0), torso.triangles
    centre = x0.mean(axis=0)
    x1 = centre + (x0 - centre) * np.array([1.1, 0.9, 1.05]) + np.array([0.02, 0.0, -0.01])
    x1 += 0.003 * np.sin(20 * x0[:, [1, 2, 0]])
    col = MeshCollider.sequence([x0, x1], tri, [0.0, 0.5])
    prox = MeshProximity(col)
    rng = np.random.default_rng(4)
    pts = x0[rng.integers(0, x0.shape[0], 1500)] + rng.normal(scale=0.03, size=(1500, 3))
    t = 0.2
    phi, normal, vel = prox.query(pts, t)
    assert prox.n_refits == 1
    again = prox.query(pts, t)
    assert prox.n_refits == 1                                   # cached at the same t
    for a, b in zip(again, (phi, normal, vel)):
        np.testing.assert_array_equal(a, b)
    face, w, dist = prox.closest(pts, t)
    np.testing.assert_allclose(vel, fd_material_velocity(col, face, w, t), atol=1e-9)
    xt = col.vertices(t)
    ref, _ = brute_force(pts, xt, tri)
    np.testing.assert_allclose(np.abs(phi), ref, rtol=1e-12)
    np.testing.assert_array_equal(phi < 0, winding_number(pts, xt, tri) > 0.5)
    prox.query(pts, 0.7)                                        # held after the last frame
    assert prox.n_refits == 2
    _, _, vel_end = prox.query(pts, 0.7)
    assert (vel_end == 0).all()
    back = prox.query(pts, t)                      # a step's start again: kept, not refit
    assert prox.n_refits == 2
    for a, b in zip(back, (phi, normal, vel)):
        np.testing.assert_array_equal(a, b)
    for k, s in enumerate((0.1, 0.3, 0.4)):        # KEEP_TIMES = 3 times kept: the oldest goes
        prox.query(pts, s)
        assert prox.n_refits == 3 + k
    again = prox.query(pts, t)                     # pushed out: refit, the same answer
    assert prox.n_refits == 6
    for a, b in zip(again, (phi, normal, vel)):
        np.testing.assert_array_equal(a, b)
    static = MeshProximity(torso)
    static.query(pts, 0.0)
    static.query(pts, 3.0)
    assert static.n_refits == 0


def test_a_static_mesh_moved_answers_as_one_built_there(torso):
    # move_to refits the tree built for the first pose: the closest points
    # and signed distances at the second pose are bitwise those of a mesh
    # built there (the tree's shape differs, the distances are exact minima)
    x0, tri = torso.vertices(0.0), torso.triangles
    centre = x0.mean(axis=0)
    x1 = centre + (x0 - centre) * np.array([1.05, 0.95, 1.1]) + 0.002 * np.sin(30 * x0)
    rng = np.random.default_rng(9)
    pts = x1[rng.integers(0, x1.shape[0], 800)] + rng.normal(scale=0.02, size=(800, 3))
    moved = MeshProximity(MeshCollider.static(x0, tri))
    moved.query(pts)
    moved.move_to(x1)
    built = MeshProximity(MeshCollider.static(x1, tri))
    for a, b in zip(moved.query(pts), built.query(pts)):
        np.testing.assert_array_equal(a, b)
    assert moved.n_refits == 1
    with pytest.raises(ValueError):
        MeshProximity(MeshCollider.sequence([x0, x1], tri, [0.0, 1.0])).move_to(x0)


# ---------------------------------------------------------------- open panel

def test_open_panel_is_two_sided():
    x = np.array([[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]])
    tri = np.array([[0, 1, 2], [0, 2, 3]])
    motion = RigidMotion([0.0, 1.0], [[0, 0, 0], [0.0, 0.0, 0.5]])
    prox = MeshProximity(MeshCollider.static(x, tri, motion=motion))
    assert not prox.closed
    pts = np.array([[0.2, 0.3, 0.25], [0.2, 0.3, -0.25], [1.5, 0.0, 0.0], [1.3, 0.2, -0.4],
                    [0.0, 0.0, 0.0], [0.4, -0.4, 0.0], [2.0, 2.0, 1.0]])
    phi, normal, vel = prox.query(pts, 0.0)
    np.testing.assert_allclose(phi, [0.25, 0.25, 0.5, 0.5, 0.0, 0.0, np.sqrt(3.0)], atol=1e-15)
    np.testing.assert_allclose(normal[:4], [[0, 0, 1], [0, 0, -1], [1, 0, 0], [0.6, 0, -0.8]],
                               atol=1e-15)
    np.testing.assert_allclose(np.abs(normal[4:6, 2]), 1.0)     # on the panel: ± face normal
    np.testing.assert_allclose(normal[6], np.ones(3) / np.sqrt(3.0), atol=1e-15)
    np.testing.assert_allclose(vel, np.tile([0.0, 0.0, 0.5], (7, 1)), atol=1e-15)
    # tiny offsets below the panel still point down
    _, n_small, _ = prox.query([[0.1, 0.1, -1e-14], [0.1, 0.1, 1e-14]], 0.0)
    np.testing.assert_allclose(n_small, [[0, 0, -1], [0, 0, 1]], atol=1e-15)
    phi_cut, _, _ = prox.query(pts, 0.0, max_distance=0.3)
    assert np.isinf(phi_cut[2:4]).all() and np.isinf(phi_cut[6])


# ---------------------------------------------------------------- analytic sphere

def test_matches_analytic_sphere():
    centre, radius = np.array([0.1, -0.05, 0.2]), 0.3
    unit, tri = icosphere(4)
    x = centre + radius * unit
    a, b, c = (x[tri[:, k]] for k in range(3))
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n, axis=1)[:, None]
    chord = radius - np.einsum("ij,ij->i", n, a - centre).min()   # largest sagitta
    # body frame centred on the sphere: it translates and spins about its centre
    motion = RigidMotion([0.0, 1.0], [centre, centre + [0.3, 0.1, -0.2]],
                         [[0, 0, 0], [0.5, -1.0, 2.0]])
    mesh = MeshProximity(MeshCollider.static(x - centre, tri, motion=motion))
    sphere = AnalyticCollider(Sphere(radius=radius), motion=motion)
    rng = np.random.default_rng(5)
    t = 0.35
    r = rng.uniform(0.3, 1.6, 3000) * radius
    pts = sphere.motion.to_world(random_directions(rng, 3000) * r[:, None], t)
    phi_m, n_m, v_m = mesh.query(pts, t)
    phi_s, n_s, v_s = sphere.query(pts, t)
    assert mesh.closed
    # the inscribed mesh: phi_sphere <= phi_mesh <= phi_sphere + sagitta
    assert (phi_m >= phi_s - 1e-12).all() and (phi_m <= phi_s + chord + 1e-12).all()
    assert np.abs(phi_m - phi_s).max() > 0.5 * chord                 # the bound is not loose
    assert (np.einsum("ij,ij->i", n_m, n_s) > np.cos(0.1)).all()
    omega = np.linalg.norm(sphere.motion.velocity(t)[1])
    assert np.abs(v_m - v_s).max() <= omega * (chord + 0.1 * radius)
