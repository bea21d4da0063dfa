"""Image-space cloth–body collision (Vassilev et al. 2001 §4–5), rasterised in software.

Vassilev et al. 2001 §4 renders the body twice with orthographic cameras, from the front
and from the back of its bounding box, and reads back the z-buffer (depth
map), the Gouraud-interpolated vertex normals (normal map, §4.2) and the
Gouraud-interpolated vertex velocities (velocity map, §4.3).  A cloth point
collides when it lies behind the front depth or in front of the back depth
of its pixel (§4.4, Eq. 12); the maps at that pixel give the normal and
velocity for the response of §5 (Eq. 15, 16).  Here the same maps come from
a numba scan-converter instead of OpenGL, in float64 (so the z error of
Eq. 13 is round-off), with depths in world units rather than [0, 1].

Projection: view axis ``a`` (0, 1 or 2); the image plane coordinates are
(u, v) = (y[(a+1)%3], y[(a+2)%3]) (cyclic, so u × v = +a) and the depth is
w = y[a].  The FRONT map holds the largest w of the body surface over each
pixel (what a viewer at +∞ on the axis sees), the BACK map the smallest.
Pixel (i, j) covers [u0 + i du, u0 + (i+1) du) × [v0 + j dv, v0 + (j+1) dv);
the body is sampled at pixel centres.  Only the outermost front and back
layers are stored: a body part hidden behind another along the axis (an arm
in front of the torso) is not represented, as in the paper.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numba import njit

__all__ = [
    "ImageMaps", "MapContact", "render_maps", "lookup", "pixel_index", "xy_error_bound",
    "resolution_for_error", "velocity_response", "vertex_normals",
]


@dataclass(frozen=True)
class ImageMaps:
    """Front and back depth / normal / velocity maps of one view (Vassilev et al. 2001 §4.1–4.3).

    Arrays are indexed [i, j] by pixel (u index, v index).  Uncovered pixels:
    front_depth = -inf, back_depth = +inf, normals and velocities zero."""
    axis: int
    bounds: np.ndarray            # ((u_min, u_max), (v_min, v_max)), metres
    resolution: tuple[int, int]   # (nu, nv) pixels
    front_depth: np.ndarray       # (nu, nv)
    back_depth: np.ndarray        # (nu, nv)
    front_normal: np.ndarray      # (nu, nv, 3) world, outward unit
    back_normal: np.ndarray
    front_velocity: np.ndarray    # (nu, nv, 3) world, m/s
    back_velocity: np.ndarray

    @property
    def covered(self) -> np.ndarray:
        return np.isfinite(self.front_depth)

    @property
    def pixel_size(self) -> np.ndarray:
        return xy_error_bound(self.bounds, self.resolution)

    def pixel_centres(self) -> tuple[np.ndarray, np.ndarray]:
        """u (nu,) and v (nv,) coordinates of the pixel centres."""
        du, dv = self.pixel_size
        (u0, _), (v0, _) = self.bounds
        nu, nv = self.resolution
        return u0 + (np.arange(nu) + 0.5) * du, v0 + (np.arange(nv) + 0.5) * dv


class MapContact(NamedTuple):
    """Per query point.  ``inside``: between back − thickness and front +
    thickness of its pixel.  ``depth``: distance along the view axis to the
    nearer of the two offset surfaces (> 0 inside, 0 elsewhere).  ``front``:
    the nearer surface is the front one.  ``normal``/``velocity``: the map
    values of that surface at that pixel (zero where not inside)."""
    inside: np.ndarray
    depth: np.ndarray
    normal: np.ndarray
    velocity: np.ndarray
    front: np.ndarray


def _plane_axes(axis: int) -> tuple[int, int]:
    if axis not in (0, 1, 2):
        raise ValueError(f"view axis must be 0, 1 or 2, not {axis!r}")
    return (axis + 1) % 3, (axis + 2) % 3


def _bounds_resolution(bounds, resolution) -> tuple[np.ndarray, tuple[int, int]]:
    b = np.asarray(bounds, dtype=np.float64).reshape(2, 2)
    if not (np.isfinite(b).all() and (b[:, 1] > b[:, 0]).all()):
        raise ValueError(f"map bounds must be ((u_min, u_max), (v_min, v_max)) with min < max, "
                         f"got {b.tolist()}")
    nu, nv = (int(n) for n in np.broadcast_to(np.asarray(resolution), (2,)))
    if nu < 1 or nv < 1:
        raise ValueError(f"map resolution must be positive, got {(nu, nv)}")
    return b, (nu, nv)


# ---------------------------------------------------------------- error bound (§4.5)

def xy_error_bound(bounds, resolution) -> np.ndarray:
    """Vassilev et al. 2001 §4.5 Eq. 14: "Δx = Δy = bboxheight / mapsize ≈ (160 to 180) /
    mapsize cm" — the x–y discretisation error of the maps is the pixel pitch,
    the extent of the map divided by its number of pixels (the paper's map is
    square and spans the body's height).  Returned per image axis:
    (Δu, Δv) = (extent_u / nu, extent_v / nv).

    With the nearest-pixel lookup used here a query point is compared with
    the body sampled at most (Δu/2, Δv/2) away laterally, so the pitch is a
    conservative bound (the paper quotes the pitch itself).  The depth error of
    Eq. 13 is float64 round-off here."""
    b, (nu, nv) = _bounds_resolution(bounds, resolution)
    return (b[:, 1] - b[:, 0]) / np.array([nu, nv], dtype=np.float64)


def resolution_for_error(bounds, max_error: float) -> tuple[int, int]:
    """Smallest map size (nu, nv) whose Eq. 14 error (pixel pitch) is at most
    ``max_error`` on both axes: mapsize = ceil(extent / Δ).  The paper's
    example: Δ = 0.5 cm over a 160–180 cm body gives 320–360 pixels."""
    if not max_error > 0:
        raise ValueError("max_error must be positive")
    b, _ = _bounds_resolution(bounds, (1, 1))
    n = np.ceil((b[:, 1] - b[:, 0]) / float(max_error) * (1.0 - 1e-12))
    return int(max(n[0], 1)), int(max(n[1], 1))


# ---------------------------------------------------------------- rendering (§4.1–4.3)

def vertex_normals(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Area-weighted unit vertex normals (the per-vertex colours of §4.2)."""
    v = np.asarray(vertices, dtype=np.float64)
    tri = np.asarray(triangles, dtype=np.int64)
    face = np.cross(v[tri[:, 1]] - v[tri[:, 0]], v[tri[:, 2]] - v[tri[:, 0]])
    normals = np.zeros_like(v)
    for corner in range(3):
        np.add.at(normals, tri[:, corner], face)
    length = np.linalg.norm(normals, axis=1)
    return normals / np.where(length > 0, length, 1.0)[:, None]


@njit(cache=True)
def _clamp(x, n):
    """x limited to [-1, n + 1] before floor/ceil turn it into an integer
    (numba's float -> int64 of a far-away vertex would overflow)."""
    return min(max(x, -1.0), n + 1.0)


@njit(cache=True)
def _rasterise(u, v, w, tri, attr_n, attr_v, smooth, face_n, u0, v0, du, dv,
               front_d, back_d, front_n, back_n, front_v, back_v):
    """Scan-convert every triangle: pixels whose centre lies in the projected
    triangle (inclusive edge test, so shared edges leave no cracks) get the
    barycentric depth; z-buffer max for the front map, min for the back map.
    Normals (smooth: interpolated vertex normals, renormalised; else the face
    normal) and velocities are interpolated with the same weights (§4.2–4.3)."""
    nu, nv = front_d.shape
    for t in range(tri.shape[0]):
        a, b, c = tri[t, 0], tri[t, 1], tri[t, 2]
        ua, va, ub, vb, uc, vc = u[a], v[a], u[b], v[b], u[c], v[c]
        area2 = (ub - ua) * (vc - va) - (uc - ua) * (vb - va)
        if abs(area2) <= 1e-300:
            continue  # edge-on: its neighbours cover the silhouette
        # pixel index range whose centres u0 + (i + 1/2) du fall in the bbox
        i0 = max(0, math.ceil(_clamp((min(ua, ub, uc) - u0) / du - 0.5, nu)))
        i1 = min(nu - 1, math.floor(_clamp((max(ua, ub, uc) - u0) / du - 0.5, nu)))
        j0 = max(0, math.ceil(_clamp((min(va, vb, vc) - v0) / dv - 0.5, nv)))
        j1 = min(nv - 1, math.floor(_clamp((max(va, vb, vc) - v0) / dv - 0.5, nv)))
        tol = -1e-12 * abs(area2)
        for i in range(i0, i1 + 1):
            pu = u0 + (i + 0.5) * du
            for j in range(j0, j1 + 1):
                pv = v0 + (j + 0.5) * dv
                ea = (ub - pu) * (vc - pv) - (uc - pu) * (vb - pv)
                eb = (uc - pu) * (va - pv) - (ua - pu) * (vc - pv)
                ec = (ua - pu) * (vb - pv) - (ub - pu) * (va - pv)
                if area2 < 0:
                    ea, eb, ec = -ea, -eb, -ec
                if ea < tol or eb < tol or ec < tol:
                    continue
                s = ea + eb + ec
                la, lb, lc = ea / s, eb / s, ec / s
                depth = la * w[a] + lb * w[b] + lc * w[c]
                is_front = depth > front_d[i, j]
                is_back = depth < back_d[i, j]
                if not (is_front or is_back):
                    continue
                n0 = face_n[t, 0]
                n1 = face_n[t, 1]
                n2 = face_n[t, 2]
                if smooth:
                    n0 = la * attr_n[a, 0] + lb * attr_n[b, 0] + lc * attr_n[c, 0]
                    n1 = la * attr_n[a, 1] + lb * attr_n[b, 1] + lc * attr_n[c, 1]
                    n2 = la * attr_n[a, 2] + lb * attr_n[b, 2] + lc * attr_n[c, 2]
                    length = math.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
                    if length > 0.0:
                        n0 /= length
                        n1 /= length
                        n2 /= length
                if is_front:
                    front_d[i, j] = depth
                    front_n[i, j, 0] = n0
                    front_n[i, j, 1] = n1
                    front_n[i, j, 2] = n2
                    for k in range(3):
                        front_v[i, j, k] = la * attr_v[a, k] + lb * attr_v[b, k] + lc * attr_v[c, k]
                if is_back:
                    back_d[i, j] = depth
                    back_n[i, j, 0] = n0
                    back_n[i, j, 1] = n1
                    back_n[i, j, 2] = n2
                    for k in range(3):
                        back_v[i, j, k] = la * attr_v[a, k] + lb * attr_v[b, k] + lc * attr_v[c, k]


def render_maps(vertices, triangles, velocities, bounds, resolution, axis: int = 2,
                smooth_normals: bool = True) -> ImageMaps:
    """Front and back depth, normal and velocity maps of a triangle mesh
    (Vassilev et al. 2001 §4.1–4.3) by orthographic projection along ``axis`` onto the
    (u, v) rectangle ``bounds`` = ((u_min, u_max), (v_min, v_max)) with
    ``resolution`` = (nu, nv) pixels.  ``velocities``: per-vertex body
    velocities (n, 3) or None (zero).  Normals are outward for a consistently
    outward-oriented mesh; ``smooth_normals`` interpolates area-weighted
    vertex normals as the paper's Gouraud shading does, otherwise face normals."""
    a_u, a_v = _plane_axes(axis)
    b, (nu, nv) = _bounds_resolution(bounds, resolution)
    x = np.ascontiguousarray(vertices, dtype=np.float64).reshape(-1, 3)
    tri = np.ascontiguousarray(triangles, dtype=np.int64).reshape(-1, 3)
    if tri.size and (tri.min() < 0 or tri.max() >= x.shape[0]):
        raise ValueError("a triangle refers to a vertex that does not exist")
    vel = (np.zeros_like(x) if velocities is None
           else np.ascontiguousarray(velocities, dtype=np.float64).reshape(x.shape))
    face = np.cross(x[tri[:, 1]] - x[tri[:, 0]], x[tri[:, 2]] - x[tri[:, 0]])
    face_len = np.linalg.norm(face, axis=1)
    face_n = np.ascontiguousarray(face / np.where(face_len > 0, face_len, 1.0)[:, None])
    vn = vertex_normals(x, tri) if smooth_normals else np.zeros_like(x)
    du, dv = (b[:, 1] - b[:, 0]) / np.array([nu, nv])
    front_d = np.full((nu, nv), -np.inf)
    back_d = np.full((nu, nv), np.inf)
    maps = [np.zeros((nu, nv, 3)) for _ in range(4)]
    _rasterise(np.ascontiguousarray(x[:, a_u]), np.ascontiguousarray(x[:, a_v]),
               np.ascontiguousarray(x[:, axis]), tri, vn, vel, smooth_normals, face_n,
               b[0, 0], b[1, 0], du, dv, front_d, back_d, *maps)
    return ImageMaps(axis, b, (nu, nv), front_d, back_d, maps[0], maps[1], maps[2], maps[3])


# ---------------------------------------------------------------- collision test (§4.4)

def pixel_index(maps: ImageMaps, points) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Nearest pixel (the one whose cell contains the projected point, i.e.
    the nearest pixel centre — no bilinear filtering, like reading the map at
    the integer map coordinates of Eq. 11): (i, j, in_map)."""
    y = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    a_u, a_v = _plane_axes(maps.axis)
    du, dv = maps.pixel_size
    fu = (y[:, a_u] - maps.bounds[0, 0]) / du
    fv = (y[:, a_v] - maps.bounds[1, 0]) / dv
    nu, nv = maps.resolution
    in_map = (fu >= 0) & (fu < nu) & (fv >= 0) & (fv < nv)
    i = np.clip(np.floor(np.where(in_map, fu, 0.0)), 0, nu - 1).astype(np.int64)
    j = np.clip(np.floor(np.where(in_map, fv, 0.0)), 0, nv - 1).astype(np.int64)
    return i, j, in_map


def lookup(maps: ImageMaps, points, thickness: float = 0.0) -> MapContact:
    """Collision test of Vassilev et al. 2001 §4.4 for many points.

    A point is inside when back − thickness < w < front + thickness at its
    pixel (Eq. 12 tests front and back separately, picking the map by the
    sign of z about the box centre; testing against both depths of the pixel
    is the same test for points in the body's slab and needs no centre).  The
    response uses the nearer offset surface.  Points outside the map or over
    uncovered pixels are "no contact"."""
    y = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    i, j, in_map = pixel_index(maps, y)
    w = y[:, maps.axis]
    front = maps.front_depth[i, j]
    back = maps.back_depth[i, j]
    d_front = front + thickness - w          # > 0: below the front surface
    d_back = w - (back - thickness)          # > 0: above the back surface
    inside = in_map & np.isfinite(front) & (d_front > 0) & (d_back > 0)
    use_front = d_front <= d_back
    depth = np.where(inside, np.minimum(d_front, d_back), 0.0)
    normal = np.where(use_front[:, None], maps.front_normal[i, j], maps.back_normal[i, j])
    velocity = np.where(use_front[:, None], maps.front_velocity[i, j], maps.back_velocity[i, j])
    normal[~inside] = 0.0
    velocity[~inside] = 0.0
    return MapContact(inside, depth, normal, velocity, use_front & inside)


# ---------------------------------------------------------------- response (§5)

def _split(vectors, normal) -> tuple[np.ndarray, np.ndarray]:
    """Normal and tangential parts of vectors (n, 3) w.r.t. unit normals (n, 3)."""
    vn = np.sum(vectors * normal, axis=-1, keepdims=True) * normal
    return vn, vectors - vn


def velocity_response(v_cloth, normal, v_body, friction, reflection) -> np.ndarray:
    """Vassilev et al. 2001 §5 Eq. 15, for colliding points (vectorised; coefficients
    scalars or per point):

        v_rel = v − v_object,   v_rel = v_n + v_t (normal, tangential parts)
        v_res = C_fric v_t − C_refl v_n + v_object                  (15)

    ``friction`` is C_fric and ``reflection`` C_refl.  Note C_fric multiplies
    the kept tangential velocity: C_fric = 1 is frictionless sliding, 0 makes
    the point stick to the body; C_refl = 0 leaves zero relative normal
    velocity, 1 is an elastic bounce.  As in the paper the rule is applied to
    every colliding point; with C_refl > 0 the caller should apply it only to
    approaching points (v_rel · n < 0), otherwise a separating point is sent
    back into the body."""
    v = np.asarray(v_cloth, dtype=np.float64)
    vo = np.asarray(v_body, dtype=np.float64)
    n = np.asarray(normal, dtype=np.float64)
    c_fric = np.asarray(friction, dtype=np.float64)
    c_refl = np.asarray(reflection, dtype=np.float64)
    if c_fric.ndim:
        c_fric = c_fric[..., None]
    if c_refl.ndim:
        c_refl = c_refl[..., None]
    v_n, v_t = _split(v - vo, n)
    return c_fric * v_t - c_refl * v_n + vo


