"""Image-space body collider (Vassilev et al. 2001 §4): the depth, normal and velocity
maps of :mod:`.imagespace` behind the ``query(points, t)`` interface of
:class:`.colliders.AnalyticCollider` and :class:`.mesh_query.MeshProximity`.

Maps.  The :class:`.colliders.MeshCollider` is rendered orthographically
along ``axis`` (front = largest, back = smallest depth w = y[axis] over each
pixel) onto its bounding box at t in the two image axes (u, v) =
(y[(axis+1)%3], y[(axis+2)%3]), padded by ``margin``.  A static collider
(no frames sequence, identity motion) is rendered once; a moving or
deforming one is re-rendered when t changes (the maps of the last t are
kept).  Pick the axis so that every line along it crosses the body in one
interval (only the outermost front and back layers are stored): for the
shipped torso (z up) that is its front/back axis y (axis=1) or x, as in
Vassilev et al. 2001, not z (a vertical line crosses hips and shoulders separately).

Signed distance.  At the point's pixel (nearest pixel centre, Eq. 11) with
front depth F and back depth B, the signed *axial* gap is
s = max(w - F, B - w): > 0 above the front or below the back, < 0 between
them (Vassilev et al. 2001's inside test, Eq. 12), and the nearer layer (front if
w >= (F + B)/2) gives the surface sample c = (pixel centre, F or B), its
interpolated outward normal n and velocity.  s is a distance along the axis,
not to the surface; the returned estimate is the distance to the tangent
plane of the sampled surface point,

    phi = (y - c) . n = s |n . a| + delta . n_t

(n . a > 0 on the front layer, < 0 on the back one), i.e. the axial gap
times |n . axis| plus the sub-pixel lateral offset delta (point minus pixel
centre, |delta| <= half the pixel diagonal) times the in-plane part of n.
It is exact for a locally planar surface (y - phi n, c and the surface
between them on one plane, and n that plane's normal: flat shading, or a
region where the vertex normals agree), whatever the slope and wherever the
point sits in its pixel.  ``subpixel=False`` drops the delta term
(phi = s |n . a|, its sign exactly Vassilev et al.'s test; error up to
|delta| |n_t| <= half the pixel diagonal on a plane).  On a curved surface of
curvature kappa the tangent plane departs from the surface by about
kappa L^2 / 2 over the distance L between c and the true closest point;
L ~ (|delta| + |phi| |n_t|) / |n . a| grows without bound where the surface
turns parallel to the axis (silhouettes), which a depth map cannot resolve:
trust the estimate where |n . a| is not small (tests/test_image_collider.py
checks a bound of this form against exact distances).  On a convex body the
tangent plane lies outside the body, so outside points get phi <= the true
distance (contact over- rather than under-reported), up to the deviation of
the Gouraud normal from the facet's.  The velocity is the body's at c, not at
the closest point (the same for a translation).  Points whose pixel is off the
map or not covered by the body (laterally beyond the silhouette) have no
surface to compare with and get phi = +inf, like points with
phi > max_distance.  Unlike ``MeshProximity`` (which cuts |phi|), deep
points inside the body keep their negative phi: max_distance only hides
points that are far *outside*.
"""
from __future__ import annotations

import numpy as np

from .colliders import MeshCollider
from .imagespace import ImageMaps, pixel_index, render_maps, xy_error_bound

__all__ = ["ImageSpaceCollider"]


class ImageSpaceCollider:
    """Vassilev et al. 2001 §4 image-space collision against a :class:`MeshCollider`.

    ``resolution``: map size (nu, nv) in pixels (an int for square maps); a
    setting, changing it drops the cached maps.  ``axis``: projection axis
    (0, 1, 2).  ``margin`` (m): padding of the body's bounding box in the two
    image axes.  ``subpixel``: add the sub-pixel lateral term to phi (see the
    module docstring).  ``smooth_normals``: Gouraud-interpolated vertex
    normals as in Vassilev et al. 2001 (§4.2), else flat face normals.
    ``friction``/``thickness`` are the collider's (Coulomb μ and contact
    offset: contact when phi < thickness).  ``n_renders`` counts renderings.
    """

    def __init__(self, collider: MeshCollider, resolution=(256, 256), axis: int = 2,
                 margin: float = 0.01, subpixel: bool = True, smooth_normals: bool = True):
        if axis not in (0, 1, 2):
            raise ValueError(f"ImageSpaceCollider: axis must be 0, 1 or 2, not {axis!r}")
        if not margin >= 0:
            raise ValueError("ImageSpaceCollider: margin must be >= 0")
        self.collider = collider
        self.axis = int(axis)
        self.margin = float(margin)
        self.subpixel = bool(subpixel)
        self.smooth_normals = bool(smooth_normals)
        self._static = not collider.is_deforming and collider.motion.is_identity
        self._t0 = float(collider.frame_times[0])
        self._maps: ImageMaps | None = None
        self._t: float | None = None
        self.n_renders = 0
        self.resolution = resolution

    friction = property(lambda self: self.collider.friction)
    thickness = property(lambda self: self.collider.thickness)

    # -------------------------------------------------------------- settings
    @property
    def resolution(self) -> tuple[int, int]:
        return self._resolution

    @resolution.setter
    def resolution(self, value) -> None:
        nu, nv = (int(n) for n in np.broadcast_to(np.asarray(value), (2,)))
        if nu < 1 or nv < 1:
            raise ValueError(f"ImageSpaceCollider: resolution must be positive, got {(nu, nv)}")
        self._resolution = (nu, nv)
        self._maps = self._t = None

    # -------------------------------------------------------------- maps at t
    def bounds(self, t: float = 0.0) -> np.ndarray:
        """((u_min, u_max), (v_min, v_max)): bounding box of the body at t in
        the image axes, padded by ``margin``."""
        x = self.collider.vertices(t)
        uv = x[:, [(self.axis + 1) % 3, (self.axis + 2) % 3]]
        return np.stack([uv.min(axis=0) - self.margin, uv.max(axis=0) + self.margin], axis=1)

    def maps(self, t: float = 0.0) -> ImageMaps:
        """The maps at t: rendered once for a static collider, re-rendered
        when t changes for a moving or deforming one."""
        t = float(t)
        if self._maps is None or (not self._static and t != self._t):
            verts = self.collider.vertices(t)
            vel = None if self._static else self.collider.velocities(t)
            self._maps = render_maps(verts, self.collider.triangles, vel, self.bounds(t),
                                     self._resolution, axis=self.axis,
                                     smooth_normals=self.smooth_normals)
            self._t = t
            self.n_renders += 1
        return self._maps

    @property
    def error_bound(self) -> np.ndarray:
        """Vassilev et al. 2001 Eq. 14 x–y error (Δu, Δv) = extent / pixels of the current
        maps (those of the last queried t; of the first frame if none yet)."""
        maps = self._maps if self._maps is not None else self.maps(self._t0)
        return xy_error_bound(maps.bounds, maps.resolution)

    # -------------------------------------------------------------- queries
    def query(self, points, t: float = 0.0, max_distance: float = np.inf):
        """(phi (n,), normal (n, 3), velocity (n, 3)) as ``AnalyticCollider.query``:
        phi the estimated signed distance (< 0 inside), normal the outward
        unit normal and velocity the body surface velocity from the maps of
        the nearer layer at the point's pixel.  Uncovered points and points
        with phi > max_distance: phi = +inf, normal = velocity = 0."""
        if not max_distance >= 0.0:
            raise ValueError("ImageSpaceCollider: max_distance must be >= 0")
        y = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        maps = self.maps(t)
        a, a_u, a_v = self.axis, (self.axis + 1) % 3, (self.axis + 2) % 3
        n = y.shape[0]
        phi = np.full(n, np.inf)
        normal = np.zeros((n, 3))
        velocity = np.zeros((n, 3))
        i, j, in_map = pixel_index(maps, y)
        front, back = maps.front_depth[i, j], maps.back_depth[i, j]
        hit = np.flatnonzero(in_map & np.isfinite(front))
        if hit.size == 0:
            return phi, normal, velocity
        i, j, front, back, y = i[hit], j[hit], front[hit], back[hit], y[hit]
        w = y[:, a]
        use_front = 2.0 * w >= front + back
        nrm = np.where(use_front[:, None], maps.front_normal[i, j], maps.back_normal[i, j])
        vel = np.where(use_front[:, None], maps.front_velocity[i, j], maps.back_velocity[i, j])
        # signed axial gap (> 0 outside) times |n . axis|: the tangent-plane
        # distance at the pixel centre; the front normal points to +axis, the back one to -axis
        est = np.where(use_front, w - front, back - w) * np.abs(nrm[:, a])
        if self.subpixel:
            uc, vc = maps.pixel_centres()
            est += (y[:, a_u] - uc[i]) * nrm[:, a_u] + (y[:, a_v] - vc[j]) * nrm[:, a_v]
        keep = est <= max_distance
        idx = hit[keep]
        phi[idx] = est[keep]
        normal[idx] = nrm[keep]
        velocity[idx] = vel[keep]
        return phi, normal, velocity

    def signed_distance(self, points, t: float = 0.0, max_distance: float = np.inf):
        """(phi, normal) as ``AnalyticCollider.signed_distance``."""
        phi, normal, _ = self.query(points, t, max_distance)
        return phi, normal

