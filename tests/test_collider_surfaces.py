"""Colliders as triangle surfaces for the result file and the previews
(distcloth/collision/surfaces.py): closed, outward, on the shape, moved with
the body, and the plane's square where the cloth is."""
from __future__ import annotations

import numpy as np
import pytest

from distcloth.collision.colliders import (AnalyticCollider, Box, Capsule, MeshCollider, Plane,
                                           RigidMotion, Sphere)
from distcloth.collision.contact import Collider
from distcloth.collision.surfaces import (cloth_extent, collider_surface, collider_surfaces,
                                          moves, surface_shape)

EXTENT = np.array([[-1.0, -2.0, 0.5], [1.0, 2.0, 0.5]])


def as_collider(body, name="body"):
    kind = "mesh" if isinstance(body, MeshCollider) else "analytic"
    return Collider(name=name, kind=kind, query=None, friction=0.0, thickness=0.0, law="",
                    body=body)


def analytic(shape, motion=None):
    return as_collider(AnalyticCollider(shape, motion))


def closed_and_outward(x, tri):
    """(each edge shared by exactly two triangles in opposite directions, volume)."""
    edges = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    keys = edges[:, 0] * x.shape[0] + edges[:, 1]
    closed = (np.unique(keys).size == keys.size
              and np.isin(edges[:, 1] * x.shape[0] + edges[:, 0], keys).all())
    a, b, c = (x[tri[:, i]] for i in range(3))
    return closed, np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0


@pytest.mark.parametrize("shape, volume", [
    (Sphere((0.1, 0.2, 0.3), 0.25), 4 / 3 * np.pi * 0.25 ** 3),
    (Capsule((0, 0, 0), (0.3, 0.4, 0.0), 0.1), np.pi * 0.01 * 0.5 + 4 / 3 * np.pi * 0.001),
    (Capsule((0, 0, 1), (0, 0, 1), 0.1), 4 / 3 * np.pi * 0.001),
    (Box((1, 2, 3), (0.5, 0.2, 0.1)), 0.08),
], ids=["sphere", "capsule", "point_capsule", "box"])
def test_shapes_are_closed_outward_and_on_the_surface(shape, volume):
    x, tri = collider_surface(analytic(shape), 0.0, EXTENT)
    assert x.dtype == np.float64 and tri.dtype == np.int64 and tri.shape[1] == 3
    assert tri.shape[0] <= 600                        # a few hundred triangles at most
    phi, _ = shape.signed_distance(x)
    assert np.abs(phi).max() < 1e-12                  # vertices on the shape
    closed, v = closed_and_outward(x, tri)
    assert closed and 0.95 * volume < v <= volume * (1 + 1e-12)   # inscribed, outward


def test_plane_is_a_square_under_the_cloth_facing_along_the_normal():
    plane = Plane((0.0, 0.0, 2.0), 0.2)               # z = 0.1
    x, tri = collider_surface(analytic(plane), 0.0, EXTENT)
    assert x.shape == (4, 3) and tri.shape == (2, 3)
    np.testing.assert_allclose(x[:, 2], 0.1, atol=1e-15)
    np.testing.assert_allclose(x.mean(axis=0), [0.0, 0.0, 0.1], atol=1e-15)
    np.testing.assert_allclose(np.ptp(x[:, :2], axis=0), [4.0, 4.0], atol=1e-12)   # largest side
    n = np.cross(x[tri[:, 1]] - x[tri[:, 0]], x[tri[:, 2]] - x[tri[:, 0]])
    assert (n[:, 2] > 0).all()


def test_motion_moves_the_surface_and_says_it_moves():
    motion = RigidMotion([0.0, 1.0], [[0, 0, 0], [1.0, 0, 0]], [[0, 0, 0], [0, 0, np.pi / 2]])
    box = Box((0.5, 0.0, 0.0), (0.5, 0.1, 0.2))
    moving = analytic(box, motion)
    rest, tri = collider_surface(analytic(box), 0.0, EXTENT)
    x, tri_t = collider_surface(moving, 0.5, EXTENT)
    np.testing.assert_array_equal(tri, tri_t)         # the same triangles at every t
    np.testing.assert_allclose(x, motion.to_world(rest, 0.5), atol=1e-15)
    assert moves(moving) and not moves(analytic(box))
    assert not moves(analytic(box, RigidMotion([0.0], [[1.0, 0, 0]])))   # one key: a fixed pose
    # a moving plane's square stays under the cloth
    floor = analytic(Plane((0, 0, 1), 0.0), RigidMotion([0.0, 1.0], [[0, 0, 0], [5.0, 0, 0.5]]))
    x, _ = collider_surface(floor, 1.0, EXTENT)
    np.testing.assert_allclose(x.mean(axis=0), [0.0, 0.0, 0.5], atol=1e-12)


def test_meshes_are_their_own_surface():
    v = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    tri = np.array([[0, 1, 2]])
    static = as_collider(MeshCollider.static(v, tri))
    seq = as_collider(MeshCollider.sequence([v, v + 1.0], tri, [0.0, 1.0]))
    x, t = collider_surface(seq, 0.5, EXTENT)
    np.testing.assert_allclose(x, v + 0.5)
    np.testing.assert_array_equal(t, tri)
    assert moves(seq) and not moves(static)
    assert [surface_shape(c) for c in (static, analytic(Sphere()), analytic(Plane()))] == \
        ["mesh", "sphere", "plane"]


def test_the_writers_surfaces():
    rest = np.array([[0.0, 0.0, 1.0], [1.0, 2.0, 1.0]])
    np.testing.assert_allclose(cloth_extent(rest), [[-0.5, -1.0, 1.0], [1.5, 3.0, 1.0]])
    motion = RigidMotion([0.0, 1.0], [[0, 0, 0], [0, 1.0, 0]])
    ball = analytic(Sphere((0, 0, 0), 0.2), motion)
    (surface,) = collider_surfaces([ball], rest)
    assert (surface.name, surface.shape, surface.moving) == ("body", "sphere", True)
    np.testing.assert_array_equal(surface.vertices(0.3),
                                  collider_surface(ball, 0.3, cloth_extent(rest))[0])
