"""Colliders as triangle surfaces, for pictures and the result file.

``collider_surface(collider, t, extent)`` gives the world-space vertices and
triangles of a collider at time t: spheres and capsules as latitude-longitude
meshes of a few hundred triangles, boxes as 12 triangles, planes as a square
covering ``extent`` (the region the cloth occupies), mesh colliders as their
own mesh; the rigid motion (and a mesh's frames) at t applied.  Triangles are
outward oriented (a plane's quad faces along its normal) and the same for
every t, so a moving body is one triangle list and a vertex array per frame.
Pure numpy, no MPI: every rank can compute the same surfaces.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .colliders import AnalyticCollider, Box, Capsule, MeshCollider, Plane, RigidMotion, Sphere

if TYPE_CHECKING:     # only for annotations: the contact model pulls in the parallel layer
    from .contact import Collider

__all__ = ["ColliderSurface", "collider_surface", "collider_surfaces", "cloth_extent",
           "surface_shape", "moves"]

LATITUDE_BANDS = 12      # rings from pole to pole of a sphere or capsule (even: an equator)
LONGITUDE_SEGMENTS = 24  # 12 x 24: 528 triangles per sphere, enough to look round

# the 12 outward triangles of a box whose corner i sits at (bit 2, bit 1, bit 0)
# of i along (x, y, z): 0 -> low, 1 -> high
_BOX_CORNERS = np.array([[(i >> 2) & 1, (i >> 1) & 1, i & 1] for i in range(8)], dtype=np.float64)
_BOX_TRIANGLES = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                           [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]],
                          dtype=np.int64)


@functools.cache
def _rounded(length: float) -> tuple[np.ndarray, np.ndarray]:
    """A unit-radius sphere along z whose two hemispheres are pulled apart by
    ``length`` (a capsule; 0: a sphere): vertices (n, 3) and outward triangles."""
    half = LATITUDE_BANDS // 2
    theta = np.pi * np.arange(1, LATITUDE_BANDS) / LATITUDE_BANDS      # interior rings
    if length > 0.0:
        # the equator twice, once per hemisphere: the band between is the cylinder
        theta = np.concatenate([theta[:half], theta[half - 1:]])
    shift = np.where(np.arange(theta.size) < half, 0.5 * length, -0.5 * length)
    phi = 2.0 * np.pi * np.arange(LONGITUDE_SEGMENTS) / LONGITUDE_SEGMENTS
    rings = np.stack([np.sin(theta)[:, None] * np.cos(phi)[None],
                      np.sin(theta)[:, None] * np.sin(phi)[None],
                      np.broadcast_to((np.cos(theta) + shift)[:, None], (theta.size, phi.size))],
                     axis=-1).reshape(-1, 3)
    top, bottom = [0.0, 0.0, 1.0 + 0.5 * length], [0.0, 0.0, -1.0 - 0.5 * length]
    vertices = np.vstack([top, rings, bottom])
    m, s = LONGITUDE_SEGMENTS, np.arange(LONGITUDE_SEGMENTS)
    nxt = (s + 1) % m

    def ring(j, k):
        """Index of vertex k of ring j (after the top pole)."""
        return 1 + j * m + k

    last, south = theta.size - 1, vertices.shape[0] - 1
    caps = [np.stack([np.zeros(m, np.int64), ring(0, s), ring(0, nxt)], axis=1),
            np.stack([np.full(m, south), ring(last, nxt), ring(last, s)], axis=1)]
    j = np.repeat(np.arange(last), m)
    k, kn = np.tile(s, last), np.tile(nxt, last)
    bands = [np.stack([ring(j, k), ring(j + 1, k), ring(j + 1, kn)], axis=1),
             np.stack([ring(j, k), ring(j + 1, kn), ring(j, kn)], axis=1)]
    triangles = np.concatenate(caps + bands).astype(np.int64)
    for shared in (vertices, triangles):     # cached: callers must copy, not modify
        shared.setflags(write=False)
    return vertices, triangles


def _axis_frame(axis: np.ndarray) -> np.ndarray:
    """A rotation taking +z to the unit vector ``axis`` (columns: x', y', axis)."""
    helper = np.eye(3)[int(np.argmin(np.abs(axis)))]
    x = np.cross(helper, axis)
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(axis, x), axis], axis=1)


def _shape_surface(shape, extent_body: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Body-frame surface of an analytic shape."""
    if isinstance(shape, Sphere):
        unit, tri = _rounded(0.0)
        return shape.center + shape.radius * unit, tri
    if isinstance(shape, Capsule):
        axis = shape.b - shape.a
        length = float(np.linalg.norm(axis))
        if length == 0.0:
            unit, tri = _rounded(0.0)
            return shape.a + shape.radius * unit, tri
        # the unit capsule's hemispheres sit length / radius apart before scaling
        unit, tri = _rounded(length / shape.radius)
        frame = _axis_frame(axis / length)
        return 0.5 * (shape.a + shape.b) + shape.radius * unit @ frame.T, tri
    if isinstance(shape, Box):
        corners = shape.center + shape.half_extents * (2.0 * _BOX_CORNERS - 1.0)
        return corners, _BOX_TRIANGLES.copy()
    if isinstance(shape, Plane):
        lo, hi = extent_body
        half = max(0.5 * float(np.max(hi - lo)), 1e-3)
        return shape.quad(0.5 * (lo + hi), half)
    raise TypeError(f"no surface for a {type(shape).__name__}")


def collider_surface(collider: Collider, t: float, extent) -> tuple[np.ndarray, np.ndarray]:
    """World vertices (n, 3) float64 and triangles (m, 3) int64 of ``collider`` at
    time ``t``; ``extent`` ([low corner, high corner], m) is the region a plane's
    square covers: its centre is projected on the plane and its largest side is
    the square's side."""
    body = collider.body
    if isinstance(body, MeshCollider):
        return (np.asarray(body.vertices(t), dtype=np.float64),
                np.asarray(body.triangles, dtype=np.int64))
    if not isinstance(body, AnalyticCollider):
        raise TypeError(f"collider {collider.name}: no surface for a {type(body).__name__}")
    extent = np.asarray(extent, dtype=np.float64).reshape(2, 3)
    # the plane's square is centred under the region wherever the body has moved
    centre_body = body.motion.to_body(0.5 * (extent[0] + extent[1]), t).reshape(3)
    half = 0.5 * (extent[1] - extent[0])
    vertices, triangles = _shape_surface(body.shape, np.stack([centre_body - half,
                                                               centre_body + half]))
    return body.motion.to_world(vertices, t), triangles


def surface_shape(collider: Collider) -> str:
    """plane, sphere, capsule, box or mesh."""
    body = collider.body
    return "mesh" if isinstance(body, MeshCollider) else type(body.shape).__name__.lower()


def _keyed(motion: RigidMotion) -> bool:
    """A motion with two keys or more changes the pose (one key is a fixed pose)."""
    return motion.times.shape[0] > 1


def moves(collider: Collider) -> bool:
    """Whether the collider's surface changes with t: keyframed motion, or a
    mesh sequence of several frames."""
    body = collider.body
    if isinstance(body, MeshCollider) and body.is_deforming:
        return True
    return _keyed(body.motion)


def cloth_extent(rest_positions, factor: float = 2.0) -> np.ndarray:
    """[low, high] of the cloth's rest bounding box grown ``factor`` times about its centre."""
    rest = np.asarray(rest_positions, dtype=np.float64).reshape(-1, 3)
    lo, hi = rest.min(axis=0), rest.max(axis=0)
    centre, half = 0.5 * (lo + hi), 0.5 * factor * (hi - lo)
    return np.stack([centre - half, centre + half])


@dataclass(frozen=True, eq=False)
class ColliderSurface:
    """One collider as the result file stores it (the writer's collider
    interface, io/h5writer.py): name, shape, triangles, whether it moves, and
    its vertices at any t."""
    name: str
    shape: str
    triangles: np.ndarray
    moving: bool
    collider: Collider
    extent: np.ndarray

    def vertices(self, t: float) -> np.ndarray:
        return collider_surface(self.collider, t, self.extent)[0]


def collider_surfaces(colliders, rest_positions) -> list[ColliderSurface]:
    """The surfaces of a scene's colliders, planes sized to twice the cloth's
    rest bounding box."""
    extent = cloth_extent(rest_positions)
    out = []
    for c in colliders:
        _, triangles = collider_surface(c, 0.0, extent)
        out.append(ColliderSurface(c.name, surface_shape(c), triangles, moves(c), c, extent))
    return out
