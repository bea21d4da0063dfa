"""Collider geometry queried at a time t: rigid keyframe motion, analytic
shapes, static and deforming triangle meshes.

Conventions: SI units (m, s, m/s), z up, right-handed.  A body point with
body coordinates x sits at the world position y = R(t) x + p(t); p(t) is the
reference point (the body origin).  Signed distances are negative inside,
normals are the outward unit normals of the closest surface point.  Arrays in,
arrays out; no MPI.

The cloth–body contact models that use this geometry (collision/contact.py)
are the image-space maps of Vassilev et al. 2001 §4–5 (depth, normal and
*velocity* of the body, so the body's surface velocity enters the response,
Eq. 15) and BVH proximity with Bridson-style contact and friction (EG07
tutorial, Part 1 §2.3; Bridson et al. 2002); both need the collider's
surface velocity, which is why every collider here answers "where is the
surface and how fast is it moving" at any t.

``friction`` on a collider is the Coulomb coefficient μ ≥ 0; ``thickness`` is
the contact offset in metres: a point is in contact when phi < thickness.
"""
from __future__ import annotations

import os
from typing import Sequence

import numpy as np

from ..config.schema import ConfigError
from ..rotations import matrix_from_quat, quat_mul, rotation_matrix
from ..scene.meshio import read_mesh
from ..scene.placement import Y_UP_TO_Z_UP, place_frames

__all__ = [
    "RigidMotion", "Plane", "Sphere", "Capsule", "Box", "AnalyticCollider",
    "MeshCollider", "SkinnedMeshCollider", "load_mesh_collider", "rotvec_to_matrix",
]


# ---------------------------------------------------------------- rotations

def _quat_from_rotvec(rv: np.ndarray) -> np.ndarray:
    """Unit quaternions (w, x, y, z) of rotation vectors (..., 3)."""
    rv = np.asarray(rv, dtype=np.float64)
    angle = np.linalg.norm(rv, axis=-1, keepdims=True)
    half = 0.5 * angle
    # sin(half)/angle -> 1/2 as angle -> 0 (Taylor) so tiny angles stay exact
    small = angle < 1e-8
    scale = np.where(small, 0.5 - angle ** 2 / 48.0, np.sin(half) / np.where(small, 1.0, angle))
    return np.concatenate([np.cos(half), scale * rv], axis=-1)


def _quat_log(q: np.ndarray) -> np.ndarray:
    """Rotation vector (angle <= pi) of a unit quaternion: the shortest arc
    (q and -q are the same rotation)."""
    q = np.where(q[..., :1] < 0.0, -q, q)
    s = np.linalg.norm(q[..., 1:], axis=-1, keepdims=True)
    angle = 2.0 * np.arctan2(s, q[..., :1])
    factor = np.where(s < 1e-12, 2.0, angle / np.where(s < 1e-12, 1.0, s))
    return factor * q[..., 1:]


def rotvec_to_matrix(rv) -> np.ndarray:
    """3x3 rotation of a rotation vector (axis * angle, radians)."""
    return matrix_from_quat(_quat_from_rotvec(np.asarray(rv, dtype=np.float64).reshape(3)))


def _check_times(times: np.ndarray, what: str) -> None:
    if times.ndim != 1 or not np.isfinite(times).all():
        raise ValueError(f"{what}: times must be a finite 1-d array")
    if times.shape[0] > 1 and (np.diff(times) <= 0).any():
        raise ValueError(f"{what}: times must be strictly increasing")


def _locate(times: np.ndarray, t: float) -> tuple[int, float, bool]:
    """Key interval of t: (i, s in [0, 1), moving).  Before the first key and
    from the last key on the state is held (i = 0 or k-1, s = 0, not moving);
    intervals are closed on the left, so at an interior key the velocity is
    that of the interval starting there."""
    k = times.shape[0]
    if k < 2 or t < times[0]:
        return 0, 0.0, False
    if t >= times[-1]:
        return k - 1, 0.0, False
    i = int(np.searchsorted(times, t, side="right")) - 1
    return i, float((t - times[i]) / (times[i + 1] - times[i])), True


# ---------------------------------------------------------------- rigid motion

class RigidMotion:
    """Keyframed rigid motion y = R(t) x + p(t).

    Translation is piecewise linear between keys; rotation is slerp between
    consecutive key rotations along the shortest arc (angle <= pi; to spin
    further, add keys).  Outside the key range the pose is held and the
    velocity is zero.  Within a key interval both the linear velocity v_p of
    the reference point and the angular velocity ω are *constant* (exactly:
    slerp turns at a constant rate about a fixed world axis); they jump at
    keys, where the interval starting at the key applies.  A world point y of
    the body moves with v = v_p + ω × (y − p).  No keys: identity motion.
    """

    def __init__(self, times=(), translations=None, rotations=None):
        self.times = np.asarray(times, dtype=np.float64).reshape(-1)
        k = self.times.shape[0]
        _check_times(self.times, "RigidMotion")
        self.translations = (np.zeros((k, 3)) if translations is None
                             else np.asarray(translations, dtype=np.float64).reshape(k, 3))
        rotvecs = (np.zeros((k, 3)) if rotations is None
                   else np.asarray(rotations, dtype=np.float64).reshape(k, 3))
        self._quats = _quat_from_rotvec(rotvecs)
        self._matrices = np.array([matrix_from_quat(q) for q in self._quats]).reshape(k, 3, 3)
        if k >= 2:
            h = np.diff(self.times)[:, None]
            conj = self._quats[:-1] * np.array([1.0, -1.0, -1.0, -1.0])
            # body-frame relative rotation of each interval, R_{i+1} = R_i exp(Δ_i)
            self._deltas = _quat_log(quat_mul(conj, self._quats[1:]))
            self._linear = np.diff(self.translations, axis=0) / h
            # dR/dt = R_i exp(sΔ) [Δ]x / h  =>  ω_world = R_i Δ / h (constant in the interval)
            self._angular = np.einsum("kij,kj->ki", self._matrices[:-1], self._deltas) / h
        if not (np.isfinite(self.translations).all() and np.isfinite(rotvecs).all()):
            raise ValueError("RigidMotion: translations and rotations must be finite")

    @classmethod
    def identity(cls) -> "RigidMotion":
        return cls()

    @property
    def is_identity(self) -> bool:
        return self.times.shape[0] == 0

    def transform(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """(R 3x3, p 3) at time t."""
        if self.is_identity:
            return np.eye(3), np.zeros(3)
        i, s, moving = _locate(self.times, t)
        if not moving:
            return self._matrices[i].copy(), self.translations[i].copy()
        R = self._matrices[i] @ rotvec_to_matrix(s * self._deltas[i])
        p = (1.0 - s) * self.translations[i] + s * self.translations[i + 1]
        return R, p

    def moving(self, t: float) -> bool:
        """Whether the body moves at t (inside a key interval)."""
        return not self.is_identity and _locate(self.times, t)[2]

    def velocity(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """(v_p, ω): velocity of the reference point and world angular velocity."""
        if self.is_identity:
            return np.zeros(3), np.zeros(3)
        i, _, moving = _locate(self.times, t)
        if not moving:
            return np.zeros(3), np.zeros(3)
        return self._linear[i].copy(), self._angular[i].copy()

    def to_world(self, points_body, t: float) -> np.ndarray:
        R, p = self.transform(t)
        return np.asarray(points_body, dtype=np.float64) @ R.T + p

    def to_body(self, points_world, t: float) -> np.ndarray:
        R, p = self.transform(t)
        return (np.asarray(points_world, dtype=np.float64) - p) @ R

    def point_velocity(self, points_world, t: float) -> np.ndarray:
        """Velocity v_p + ω × (y − p) of the body points at world positions y."""
        y = np.asarray(points_world, dtype=np.float64).reshape(-1, 3)
        _, p = self.transform(t)
        v_p, omega = self.velocity(t)
        return v_p + np.cross(omega, y - p)


# ---------------------------------------------------------------- analytic shapes
# Each shape works in body coordinates: signed_distance(points (n, 3)) ->
# (phi (n,), outward unit normal (n, 3)).  Where the closest point is not
# unique (centre of a sphere, axis of a capsule, medial planes of a box) a
# fixed valid choice is returned.

def _unit(v: np.ndarray, fallback: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit vectors and norms; zero vectors get ``fallback`` (unit, (3,) or (n, 3))."""
    norm = np.sqrt(np.einsum("ni,ni->n", v, v))
    zero = norm < 1e-300
    if not zero.any():
        return v / norm[:, None], norm
    out = v / np.where(zero, 1.0, norm)[:, None]
    out[zero] = np.broadcast_to(fallback, v.shape)[zero]
    return out, norm


def _points(points) -> np.ndarray:
    return np.asarray(points, dtype=np.float64).reshape(-1, 3)


class Plane:
    """Half-space normal·y < offset is inside; normal·y = offset is the plane.
    The normal is normalised on construction (offset scaled with it)."""

    def __init__(self, normal=(0.0, 0.0, 1.0), offset: float = 0.0):
        n = np.asarray(normal, dtype=np.float64).reshape(3)
        length = np.linalg.norm(n)
        if not length > 0:
            raise ValueError("Plane: normal must be non-zero")
        self.normal, self.offset = n / length, float(offset) / length

    def signed_distance(self, points):
        y = _points(points)
        return y @ self.normal - self.offset, np.broadcast_to(self.normal, y.shape).copy()

    def quad(self, near, half: float) -> tuple[np.ndarray, np.ndarray]:
        """A square of the plane centred at the projection of ``near``, of
        half-width ``half``: corners (4, 3) and two triangles (2, 3), facing
        along the normal (a plane as a mesh for the triangle pipeline)."""
        n = self.normal
        near = np.asarray(near, dtype=np.float64).reshape(3)
        c = near - (near @ n - self.offset) * n
        a = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
        a /= np.linalg.norm(a)
        b = np.cross(n, a)
        corners = c + half * np.array([-a - b, a - b, a + b, -a + b])
        return corners, np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int64)


class Sphere:
    def __init__(self, center=(0.0, 0.0, 0.0), radius: float = 1.0):
        self.center = np.asarray(center, dtype=np.float64).reshape(3)
        self.radius = float(radius)
        if not self.radius > 0:
            raise ValueError("Sphere: radius must be positive")

    def signed_distance(self, points):
        normal, dist = _unit(_points(points) - self.center, np.array([0.0, 0.0, 1.0]))
        return dist - self.radius, normal


class Capsule:
    """Points within ``radius`` of the segment a–b."""

    def __init__(self, a, b, radius: float):
        self.a = np.asarray(a, dtype=np.float64).reshape(3)
        self.b = np.asarray(b, dtype=np.float64).reshape(3)
        self.radius = float(radius)
        if not self.radius > 0:
            raise ValueError("Capsule: radius must be positive")
        axis = self.b - self.a
        self._len2 = float(axis @ axis)
        # a unit vector perpendicular to the axis: the normal on the axis itself
        helper = np.eye(3)[int(np.argmin(np.abs(axis)))] if self._len2 > 0 else np.array([1.0, 0, 0])
        perp = np.cross(axis, helper) if self._len2 > 0 else np.array([0.0, 0.0, 1.0])
        self._perp = perp / np.linalg.norm(perp)

    def signed_distance(self, points):
        y = _points(points)
        if self._len2 > 0:
            s = np.clip((y - self.a) @ (self.b - self.a) / self._len2, 0.0, 1.0)
        else:
            s = np.zeros(y.shape[0])
        closest = self.a + s[:, None] * (self.b - self.a)
        normal, dist = _unit(y - closest, self._perp)
        return dist - self.radius, normal


class Box:
    """Axis-aligned box (in the body frame) with the given centre and half extents.
    Exact signed distance inside and outside."""

    def __init__(self, center=(0.0, 0.0, 0.0), half_extents=(0.5, 0.5, 0.5)):
        self.center = np.asarray(center, dtype=np.float64).reshape(3)
        self.half_extents = np.asarray(half_extents, dtype=np.float64).reshape(3)
        if not (self.half_extents > 0).all():
            raise ValueError("Box: half extents must be positive")

    def signed_distance(self, points):
        d = _points(points) - self.center
        sign = np.where(d < 0.0, -1.0, 1.0)
        q = np.abs(d) - self.half_extents          # per-axis distance beyond the faces
        outside = np.maximum(q, 0.0)
        out_dist = np.linalg.norm(outside, axis=1)
        face = np.argmax(q, axis=1)                # nearest face from inside
        inside_dist = q[np.arange(q.shape[0]), face]
        is_out = out_dist > 0.0
        phi = np.where(is_out, out_dist, inside_dist)
        normal = np.zeros_like(d)
        normal[np.arange(d.shape[0]), face] = sign[np.arange(d.shape[0]), face]
        normal[is_out] = sign[is_out] * outside[is_out] / out_dist[is_out, None]
        return phi, normal


class AnalyticCollider:
    """An analytic shape moved by a rigid motion.

    ``query(points, t)`` gives, in world coordinates, phi, the outward normal
    and the velocity of the body's surface point closest to each query point
    (y − phi n, moved by v_p + ω × (· − p)).  Contact when phi < thickness.
    """

    def __init__(self, shape, motion: RigidMotion | None = None,
                 friction: float = 0.0, thickness: float = 0.0):
        self.shape = shape
        self.motion = motion if motion is not None else RigidMotion()
        self.friction, self.thickness = float(friction), float(thickness)
        if self.friction < 0 or self.thickness < 0:
            raise ValueError("AnalyticCollider: friction and thickness must be >= 0")

    def signed_distance(self, points, t: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        y = _points(points)
        if self.motion.is_identity:
            # body and world frames agree: no transform (a static body is
            # queried dozens of times a step by the barrier's Newton)
            return self.shape.signed_distance(y)
        R, p = self.motion.transform(t)
        phi, normal_body = self.shape.signed_distance((y - p) @ R)
        return phi, normal_body @ R.T

    def query(self, points, t: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        y = _points(points)
        phi, normal = self.signed_distance(y, t)
        if not self.motion.moving(t):
            return phi, normal, np.zeros_like(y)
        velocity = self.motion.point_velocity(y - phi[:, None] * normal, t)
        return phi, normal, velocity


# ---------------------------------------------------------------- meshes

class MeshCollider:
    """A triangle mesh, static, rigidly moved, or deforming (one vertex array
    per frame time, same triangles).

    Between frames vertex positions are linearly interpolated, so a vertex's
    velocity is the finite difference of the two frames, constant inside the
    interval; before the first and from the last frame the mesh is held
    (velocity zero).  An optional rigid ``motion`` is applied on top:
    y = R(t) x(t) + p(t), v = R ẋ + v_p + ω × (y − p).
    Only geometry and velocities; contacts are found by the BVH code.
    """
    cut_of_closed = False       # a part of a closed mesh (body/regions.py): distances stay signed

    def __init__(self, frames, triangles, frame_times=(0.0,), motion: RigidMotion | None = None,
                 friction: float = 0.0, thickness: float = 0.0):
        self.frames = np.asarray(frames, dtype=np.float64)
        if self.frames.ndim != 3 or self.frames.shape[2] != 3 or self.frames.shape[0] < 1:
            raise ValueError("MeshCollider: frames must have shape (k, n, 3)")
        self.frame_times = np.asarray(frame_times, dtype=np.float64).reshape(-1)
        _check_times(self.frame_times, "MeshCollider")
        if self.frame_times.shape[0] != self.frames.shape[0]:
            raise ValueError(f"MeshCollider: {self.frames.shape[0]} frames but "
                             f"{self.frame_times.shape[0]} frame times")
        tri = np.asarray(triangles, dtype=np.int64)
        if tri.ndim != 2 or tri.shape[1] != 3 or tri.shape[0] == 0:
            raise ValueError("MeshCollider: triangles must have shape (m, 3), m > 0")
        if tri.min() < 0 or tri.max() >= self.frames.shape[1]:
            raise ValueError("MeshCollider: a triangle refers to a vertex that does not exist")
        if not np.isfinite(self.frames).all():
            raise ValueError("MeshCollider: vertex positions must be finite")
        self._triangles = tri
        self._triangles.setflags(write=False)
        self.motion = motion if motion is not None else RigidMotion()
        self.friction, self.thickness = float(friction), float(thickness)

    @classmethod
    def static(cls, vertices, triangles, motion: RigidMotion | None = None,
               friction: float = 0.0, thickness: float = 0.0) -> "MeshCollider":
        return cls(np.asarray(vertices, dtype=np.float64)[None], triangles, (0.0,),
                   motion, friction, thickness)

    @classmethod
    def sequence(cls, frames: Sequence, triangles, frame_times, motion: RigidMotion | None = None,
                 friction: float = 0.0, thickness: float = 0.0) -> "MeshCollider":
        shapes = {np.shape(f) for f in frames}
        if len(shapes) != 1:
            raise ValueError(f"MeshCollider.sequence: frames differ in shape {sorted(shapes)}")
        return cls(np.stack([np.asarray(f, dtype=np.float64) for f in frames]), triangles,
                   frame_times, motion, friction, thickness)

    @property
    def triangles(self) -> np.ndarray:
        return self._triangles

    @property
    def n_vertices(self) -> int:
        return self.frames.shape[1]

    @property
    def is_deforming(self) -> bool:
        return self.frames.shape[0] > 1

    def _local(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Body-frame positions and velocities of the frame sequence at t."""
        i, s, moving = _locate(self.frame_times, t)
        if not moving:
            return self.frames[i].copy(), np.zeros_like(self.frames[i])
        a, b = self.frames[i], self.frames[i + 1]
        h = self.frame_times[i + 1] - self.frame_times[i]
        return (1.0 - s) * a + s * b, (b - a) / h

    def vertices(self, t: float = 0.0) -> np.ndarray:
        x, _ = self._local(t)
        return x if self.motion.is_identity else self.motion.to_world(x, t)

    def velocities(self, t: float = 0.0) -> np.ndarray:
        x, xdot = self._local(t)
        if self.motion.is_identity:
            return xdot
        R, _ = self.motion.transform(t)
        return xdot @ R.T + self.motion.point_velocity(self.motion.to_world(x, t), t)


class SkinnedMeshCollider(MeshCollider):
    """A body mesh skinned by motion capture (body/animated.py): its vertices
    at t are the skinned rest mesh placed in the scene by one affine map
    x -> A x + b (the collider's up axis, scale, rotation and move, fixed by
    the rest mesh), its velocities the skin's; the rigid ``motion`` goes on
    top as for any mesh.  Same triangles at every t, so the BVH is refit."""

    def __init__(self, body, A, b, motion: RigidMotion | None = None, friction: float = 0.0,
                 thickness: float = 0.0):
        self.body = body
        self.A = np.asarray(A, dtype=np.float64)
        self.b = np.asarray(b, dtype=np.float64)
        placed = body.rest @ self.A.T + self.b
        super().__init__(placed[None], body.triangles, (0.0,), motion, friction, thickness)
        self.drive_end = float(body.end_time)

    @property
    def is_deforming(self) -> bool:
        return True

    @property
    def arm_spread_degrees(self):
        """(left, right) largest extra abduction of the arms (body/arm_clearance.py),
        or None when the arms move as captured."""
        spread = self.body.motion.spread
        return None if spread is None else tuple(float(a) for a in np.degrees(spread.largest))

    @property
    def leg_spread_degrees(self):
        """Largest turn of each leg apart about its hip (body/leg_clearance.py),
        or None when the legs move as captured."""
        spread = self.body.motion.leg_spread
        return None if spread is None else float(np.degrees(spread.largest.max()))

    def _local(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        return self.body.positions(t) @ self.A.T + self.b, self.body.velocities(t) @ self.A.T

    # positions and velocities apart: most queries want only the positions
    def vertices(self, t: float = 0.0) -> np.ndarray:
        x = self.body.positions(t) @ self.A.T + self.b
        return x if self.motion.is_identity else self.motion.to_world(x, t)

    def velocities(self, t: float = 0.0) -> np.ndarray:
        xdot = self.body.velocities(t) @ self.A.T
        if self.motion.is_identity:
            return xdot
        R, _ = self.motion.transform(t)
        return xdot @ R.T + self.motion.point_velocity(self.vertices(t), t)


class MeshFrameError(ValueError):
    """A frame of a collider mesh (sequence) that cannot be used: ``frame``
    is its index in the list of files."""

    def __init__(self, frame: int, message: str):
        self.frame = frame
        super().__init__(message)


def read_mesh_frames(paths: Sequence[str]) -> list[tuple[np.ndarray, np.ndarray]]:
    """Every file of a collider mesh (sequence) read and checked against frame 0:
    same vertex count, same triangles; raises MeshFrameError naming the frame."""
    meshes = []
    for k, path in enumerate(paths):
        try:
            meshes.append(read_mesh(path))
        except OSError as exc:
            raise MeshFrameError(k, f"cannot read it: {exc.strerror or exc}") from None
        except ValueError as exc:       # MeshFormatError
            raise MeshFrameError(k, str(exc)) from None
    v0, tri0 = meshes[0]
    for k, (v, tri) in enumerate(meshes[1:], start=1):
        if v.shape[0] != v0.shape[0]:
            raise MeshFrameError(k, f"mesh sequence: frame {k} ({paths[k]}) has {v.shape[0]} "
                                 f"vertices but frame 0 ({paths[0]}) has {v0.shape[0]}; every "
                                 f"frame must have the same vertices")
        if tri.shape != tri0.shape or not np.array_equal(tri, tri0):
            raise MeshFrameError(k, f"mesh sequence: frame {k} ({paths[k]}) has different "
                                 f"triangles from frame 0 ({paths[0]}); every frame must have "
                                 f"the same triangles in the same order")
    return meshes


def load_mesh_collider(paths, frame_times=None, frame_rate: float | None = None,
                       motion: RigidMotion | None = None, friction: float = 0.0,
                       thickness: float = 0.0) -> MeshCollider:
    """Read a collider mesh (OBJ or PLY, via :mod:`distcloth.scene.meshio`).

    One path: a static mesh (rigidly moved by ``motion`` if given).  Several
    paths: a deforming sequence, one file per frame, at ``frame_times`` (s)
    or, if those are not given, at k / ``frame_rate`` (frames per second).
    Every frame must have the same vertex count and the same triangles.
    """
    if isinstance(paths, (str, os.PathLike)):
        paths = [paths]
    paths = [os.fspath(p) for p in paths]
    if not paths:
        raise ValueError("load_mesh_collider: no mesh file given")
    meshes = read_mesh_frames(paths)
    v0, tri0 = meshes[0]
    if len(paths) == 1:
        return MeshCollider.static(v0, tri0, motion, friction, thickness)
    if frame_times is None:
        if frame_rate is None or not frame_rate > 0:
            raise ValueError("mesh sequence: give frame_times or a positive frame_rate")
        frame_times = np.arange(len(paths)) / float(frame_rate)
    frame_times = np.asarray(frame_times, dtype=np.float64).reshape(-1)
    if frame_times.shape[0] != len(paths):
        raise ValueError(f"mesh sequence: {len(paths)} files but {frame_times.shape[0]} frame times")
    return MeshCollider.sequence([v for v, _ in meshes], tri0, frame_times, motion,
                                 friction, thickness)


def collider_file_error(spec, key: str, exc: MeshFrameError) -> ConfigError:
    """The one-line error of a collider entry (at ``key``) whose mesh file is unusable."""
    files = list(spec.files)
    where = f"{key}.file" if len(files) == 1 else f"{key}.file.{exc.frame}"
    return ConfigError(where, files[exc.frame], f"an OBJ or PLY triangle mesh a collider can "
                       f"use: {exc}")


def load_collider_mesh(spec, motion: RigidMotion | None = None,
                       key: str = "colliders") -> MeshCollider:
    """The mesh collider a scene's ``colliders:`` entry describes (``shape: mesh``):
    its file or frame sequence, placed, with the entry's rigid ``motion`` on top.

    The placement is one transform for every frame, in this order: a y-up file
    (``up_axis: y``) is turned so its +y becomes +z, then scaled, rotated about
    frame 0's bounding-box centre, and moved so that centre lands on ``center``
    or by ``translation`` (scene/placement.py, as for cloth pieces).  The
    motion's body coordinates are these placed coordinates.  A file that
    cannot be used is a ConfigError naming ``key`` (the entry's key path)."""
    try:
        mesh = load_mesh_collider(list(spec.files), frame_rate=spec.frame_rate, motion=motion,
                                  friction=spec.friction, thickness=spec.thickness)
    except MeshFrameError as exc:
        raise collider_file_error(spec, key, exc) from None
    frames = mesh.frames
    if spec.up_axis == "y":
        frames = frames @ Y_UP_TO_Z_UP.T
    if spec.scale != 1.0:
        frames = frames * spec.scale
    mesh.frames = place_frames(frames, spec.rotation, center=dict(spec.geometry).get("center"),
                               translation=spec.translation)
    return mesh


def placement_map(spec, rest: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The collider placement (load_collider_mesh) of a mesh whose file
    positions are ``rest`` as one affine map x -> A x + b."""
    A = np.eye(3)
    if spec.up_axis == "y":
        A = Y_UP_TO_Z_UP @ A
    A = spec.scale * A
    A = rotation_matrix(spec.rotation) @ A
    placed = place_frames((rest @ (spec.scale * (Y_UP_TO_Z_UP if spec.up_axis == "y"
                                                 else np.eye(3))).T)[None], spec.rotation,
                          center=dict(spec.geometry).get("center"), translation=spec.translation)[0]
    return A, np.mean(placed - rest @ A.T, axis=0)
