"""Image-space body collision (Vassilev et al. 2001 §4–5): software-rendered depth,
normal and velocity maps of a sphere mesh against the analytic sphere, the
inside test within the Eq. 14 error, and the Eq. 15/16 responses."""
from __future__ import annotations

from pathlib import Path

import numpy as np
from meshes import icosphere
import pytest

from distcloth.collision.imagespace import (lookup, render_maps, resolution_for_error,
                                            velocity_response, xy_error_bound)
from distcloth.scene.meshio import read_mesh

ROOT = Path(__file__).resolve().parents[1]
CENTER = np.array([0.1, -0.05, 0.2])
RADIUS = 0.3
V0 = np.array([0.2, -0.4, 0.1])          # rigid body velocity field V0 + W x (y - CENTER)
W = np.array([1.0, 0.5, -2.0])


@pytest.fixture(scope="module")
def sphere_mesh():
    unit, tri = icosphere(4)
    vertices = CENTER + RADIUS * unit
    velocities = V0 + np.cross(W, vertices - CENTER)
    a, b, c = (vertices[tri[:, i]] for i in range(3))
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n, axis=1)[:, None]
    assert (np.einsum("ij,ij->i", n, a - CENTER) > 0).all()          # outward
    # largest gap between the inscribed mesh and the sphere (plane distance of a face)
    chord = RADIUS - np.einsum("ij,ij->i", n, a - CENTER).min()
    return vertices, tri, velocities, chord


def sphere_bounds(axis: int, margin: float = 0.07) -> np.ndarray:
    u, v = (axis + 1) % 3, (axis + 2) % 3
    return np.array([[CENTER[u] - RADIUS - margin, CENTER[u] + RADIUS + margin],
                     [CENTER[v] - RADIUS - margin * 0.5, CENTER[v] + RADIUS + margin * 1.3]])


def to_world(axis, u, v, w):
    out = np.zeros(np.broadcast(u, v, w).shape + (3,))
    out[..., (axis + 1) % 3], out[..., (axis + 2) % 3], out[..., axis] = u, v, w
    return out


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_rendered_sphere_matches_analytic(sphere_mesh, axis):
    vertices, tri, velocities, chord = sphere_mesh
    maps = render_maps(vertices, tri, velocities, sphere_bounds(axis), (70, 90), axis=axis)
    uc, vc = maps.pixel_centres()
    U, V = np.meshgrid(uc, vc, indexing="ij")
    lateral = np.hypot(U - CENTER[(axis + 1) % 3], V - CENTER[(axis + 2) % 3])
    covered = maps.covered
    # pixel centres well inside the silhouette are covered, outside it are not
    assert covered[lateral < RADIUS - chord - 1e-9].all()
    assert not covered[lateral > RADIUS].any()
    assert np.isinf(maps.back_depth[~covered]).all() and not maps.front_normal[~covered].any()
    for depth, normal, vel in ((maps.front_depth, maps.front_normal, maps.front_velocity),
                               (maps.back_depth, maps.back_normal, maps.back_velocity)):
        y = to_world(axis, U, V, depth)[covered]
        r = np.linalg.norm(y - CENTER, axis=1)
        # the sampled surface point lies on the mesh, within the chord error of the sphere
        assert (r <= RADIUS + 1e-12).all() and (r >= RADIUS - chord - 1e-12).all()
        radial = (y - CENTER) / r[:, None]
        n = normal[covered]
        np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-12)
        assert (np.einsum("ij,ij->i", n, radial) > 0.995).all()
        # velocity field is linear in position: barycentric interpolation is exact
        np.testing.assert_allclose(vel[covered], V0 + np.cross(W, y - CENTER), atol=1e-12)
    assert (maps.front_depth[covered] > maps.back_depth[covered]).all()
    # front normals face the +axis viewer, back normals away from it
    assert (maps.front_normal[covered][:, axis] > 0).mean() > 0.99
    assert (maps.back_normal[covered][:, axis] < 0).mean() > 0.99


def test_face_normals_option(sphere_mesh):
    vertices, tri, velocities, _ = sphere_mesh
    maps = render_maps(vertices, tri, None, sphere_bounds(2), (40, 40), smooth_normals=False)
    n = maps.front_normal[maps.covered]
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-12)
    assert not maps.front_velocity.any()


@pytest.mark.parametrize("axis", [0, 2])
def test_lookup_classifies_within_eq14_bound(sphere_mesh, axis):
    vertices, tri, velocities, chord = sphere_mesh
    bounds = sphere_bounds(axis)
    maps = render_maps(vertices, tri, velocities, bounds, (64, 72), axis=axis)
    rng = np.random.default_rng(11)
    y = CENTER + rng.uniform(-1.3, 1.3, size=(20000, 3)) * RADIUS
    hit = lookup(maps, y)
    r = np.linalg.norm(y - CENTER, axis=1)
    wrong = hit.inside != (r < RADIUS)
    # nearest-pixel sampling: the body is read at most half a pixel diagonal away
    # laterally (< the Eq. 14 pitch), plus the mesh's own chord error
    dx = xy_error_bound(bounds, (64, 72))
    tolerance = 0.5 * np.hypot(*dx) + chord
    assert dx.max() < RADIUS / 20
    assert (np.abs(r[wrong] - RADIUS) <= tolerance + 1e-12).all()
    assert wrong.mean() < 0.05 and hit.inside.sum() > 1000
    # no-contact points carry nothing
    assert not hit.depth[~hit.inside].any() and not hit.normal[~hit.inside].any()
    # depth: distance along the axis to the nearer of the front/back surfaces
    i = np.flatnonzero(hit.inside)
    w = y[i, axis]
    u_idx = ((y[i, (axis + 1) % 3] - bounds[0, 0]) / dx[0]).astype(int)
    v_idx = ((y[i, (axis + 2) % 3] - bounds[1, 0]) / dx[1]).astype(int)
    front = maps.front_depth[u_idx, v_idx]
    back = maps.back_depth[u_idx, v_idx]
    np.testing.assert_allclose(hit.depth[i], np.minimum(front - w, w - back), atol=1e-15)
    np.testing.assert_array_equal(hit.front[i], front - w <= w - back)
    assert (hit.depth[i] > 0).all()
    np.testing.assert_array_equal(hit.normal[i][hit.front[i]],
                                  maps.front_normal[u_idx, v_idx][hit.front[i]])
    np.testing.assert_array_equal(hit.velocity[i][~hit.front[i]],
                                  maps.back_velocity[u_idx, v_idx][~hit.front[i]])


def test_lookup_thickness_and_outside_map(sphere_mesh):
    vertices, tri, velocities, _ = sphere_mesh
    bounds = sphere_bounds(2)
    maps = render_maps(vertices, tri, velocities, bounds, (50, 50))
    uc, vc = maps.pixel_centres()
    i, j = 25, 24
    front = maps.front_depth[i, j]
    thickness = 0.004
    above = np.array([[uc[i], vc[j], front + 0.5 * thickness],
                      [uc[i], vc[j], front + 1.5 * thickness]])
    assert not lookup(maps, above).inside.any()
    hit = lookup(maps, above, thickness=thickness)
    np.testing.assert_array_equal(hit.inside, [True, False])
    assert hit.depth[0] == pytest.approx(0.5 * thickness) and hit.front[0]
    np.testing.assert_array_equal(hit.normal[0], maps.front_normal[i, j])
    np.testing.assert_array_equal(hit.velocity[0], maps.front_velocity[i, j])
    outside = np.array([[bounds[0, 1] + 0.01, CENTER[1], CENTER[2]],
                        [bounds[0, 0] - 1e-9, CENTER[1], CENTER[2]],
                        [CENTER[0], bounds[1, 1], CENTER[2]]])
    assert not lookup(maps, outside, thickness=1.0).inside.any()


def test_torso_front_view_smoke():
    """The shipped torso rendered along y (front/back of the body) at the
    0.5 cm map error of Vassilev et al. 2001."""
    v, tri = read_mesh(str(ROOT / "configs" / "meshes" / "torso.obj"))
    bounds = [[-0.05, 0.75], [-0.25, 0.25]]       # axis 1: (u, v) = (z, x)
    res = resolution_for_error(bounds, 0.005)
    assert res == (160, 100)
    maps = render_maps(v, tri, None, bounds, res, axis=1)
    hit = lookup(maps, np.array([[0.0, 0.0, 0.3], [0.0, 0.2, 0.3], [0.0, 0.0, 0.72],
                                 [0.0, 0.09, 0.3]]))
    np.testing.assert_array_equal(hit.inside, [True, False, False, True])
    assert hit.front[3] and hit.normal[3, 1] > 0.9


# ---------------------------------------------------------------- Eq. 14

def test_eq14_error_and_map_size():
    # Vassilev et al. 2001's numbers: 160-180 cm tall, 0.5 cm error -> 320-360 pixels
    np.testing.assert_allclose(xy_error_bound([[0, 1.7], [0, 1.7]], (340, 340)), [0.005, 0.005])
    assert resolution_for_error([[0, 1.6], [0, 1.8]], 0.005) == (320, 360)
    assert resolution_for_error([[0, 1.0], [0, 0.3]], 0.3) == (4, 1)
    with pytest.raises(ValueError):
        xy_error_bound([[1, 0], [0, 1]], (10, 10))


# ---------------------------------------------------------------- Eq. 15, 16

def frame(n=5, seed=12):
    rng = np.random.default_rng(seed)
    normal = rng.normal(size=(n, 3))
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    tangent = np.cross(normal, rng.normal(size=(n, 3)))
    tangent /= np.linalg.norm(tangent, axis=1)[:, None]
    return normal, tangent, rng.normal(size=(n, 3))


def test_eq15_pure_normal_approach_stops():
    n, _, v_body = frame()
    v = v_body - 2.0 * n
    res = velocity_response(v, n, v_body, friction=0.7, reflection=0.0)
    np.testing.assert_allclose(res, v_body, atol=1e-15)
    bounce = velocity_response(v, n, v_body, friction=0.7, reflection=0.5)
    np.testing.assert_allclose(np.einsum("ij,ij->i", bounce - v_body, n), 1.0, atol=1e-14)


def test_eq15_tangential_friction_and_body_velocity():
    n, t, v_body = frame()
    v = v_body + 3.0 * t - 1.0 * n
    c_fric = np.array([0.0, 0.25, 0.5, 1.0, 0.4])
    res = velocity_response(v, n, v_body, friction=c_fric, reflection=0.2)
    expected = v_body + c_fric[:, None] * 3.0 * t + 0.2 * n
    np.testing.assert_allclose(res, expected, atol=1e-14)
    # C_fric = 1, C_refl = 1: the relative velocity's normal part is mirrored
    mirror = velocity_response(v, n, v_body, 1.0, 1.0)
    np.testing.assert_allclose(mirror, v_body + 3.0 * t + n, atol=1e-14)


def test_far_away_vertex_is_clipped(sphere_mesh):
    """A triangle reaching far outside the map is clipped to it (pixel index
    ranges are clamped before the float -> int conversion)."""
    vertices, tri, _, _ = sphere_mesh
    base = render_maps(vertices, tri, None, sphere_bounds(2), (12, 12))
    v2 = np.vstack([vertices, [[1e30, 1e30, -1e30]]])
    t2 = np.vstack([tri, [[0, 1, vertices.shape[0]]]])
    maps = render_maps(v2, t2, None, sphere_bounds(2), (12, 12))
    assert (maps.covered >= base.covered).all()
    np.testing.assert_array_equal(maps.front_depth[base.covered], base.front_depth[base.covered])
