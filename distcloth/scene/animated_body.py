"""The collider of a scene's ``colliders:`` entry with ``animation:``: its
mesh rigged and driven by the motion capture file (docs/bodies.md)."""
from __future__ import annotations

import os

from ..body.animated import AnimatedBody
from ..body.bvh import read_bvh
from ..body.clip import Timeline
from ..body.regions import reachable_bones, region_triangles, submesh
from ..body.retarget import MappingError
from ..collision.colliders import (MeshFrameError, RigidMotion, SkinnedMeshCollider,
                                   collider_file_error, placement_map, read_mesh_frames)
from ..config.schema import ConfigError


# the last rigged body of this process: a garment scene builds its body twice (for the
# sewing and for the run), and rigging it (skeleton, bone heat, limb clearances) takes
# seconds; an AnimatedBody holds nothing a simulation changes but its pose caches
_RIGGED: dict = {}


def _mtime(path) -> int:
    try:
        return os.stat(path).st_mtime_ns
    except OSError:
        return -1


def load_animated_collider(spec, key: str, motion: RigidMotion | None = None) -> SkinnedMeshCollider:
    """``key``: the entry's key path (colliders.N), for the one-line errors of
    a motion file that does not read or a clip range it does not have."""
    anim = spec.animation
    if len(spec.files) != 1:
        raise ConfigError(f"{key}.file", list(spec.files), "one mesh file with animation "
                          "(the body is skinned, not a frame sequence)")
    try:
        clip = read_bvh(anim.motion, scale=anim.units)
    except (OSError, ValueError) as exc:
        raise ConfigError(f"{key}.animation.motion", anim.motion,
                          f"a readable BVH file ({exc})") from None
    try:
        timeline = Timeline(settle=anim.settle, blend_in=anim.blend_in, blend_out=anim.blend_out,
                            speed=anim.speed, start=anim.clip_start, end=anim.clip_end,
                            ease_in=anim.ease_in)
        timeline.total(clip.duration)
    except ValueError as exc:
        raise ConfigError(f"{key}.animation", f"clip {clip.duration:.4g} s",
                          f"a clip range and easing the clip has ({exc})") from None
    try:
        (vertices, triangles), = read_mesh_frames(spec.files)
    except MeshFrameError as exc:
        raise collider_file_error(spec, key, exc) from None
    key_rig = (anim, spec.files[0], _mtime(spec.files[0]), _mtime(anim.motion))
    try:
        body = _RIGGED.get(key_rig)
        if body is None:
            body = AnimatedBody(vertices, triangles, clip, timeline, method=anim.skinning,
                                root_motion=anim.root_motion, mapping=dict(anim.joints),
                                arm_clearance=anim.arm_clearance,
                                leg_clearance=anim.leg_clearance)
            _RIGGED.clear()
            _RIGGED[key_rig] = body
    except MappingError as exc:     # a body joint the capture has no joint for
        raise ConfigError(f"{key}.animation.joints", dict(anim.joints),
                          f"capture joints of {anim.motion} ({exc})") from None
    except ValueError as exc:       # a mesh the rig cannot be fitted to
        raise ConfigError(f"{key}.file", spec.files[0], f"a body mesh that can be rigged ({exc})") from None
    A, b = placement_map(spec, body.rest)
    return SkinnedMeshCollider(body, A, b, motion, spec.friction, spec.thickness)


def reachable_part(collider: SkinnedMeshCollider, garment_points, reach: float):
    """The part of a skinned body collider a garment starting at
    ``garment_points`` can reach (body/regions.py), as a collider of its own
    with ``cut_of_closed`` set (its distances stay signed: the cut is where
    parts out of reach join, away from the garment), and a one-line summary."""
    body = collider.body
    x0 = collider.vertices(0.0)
    bones = reachable_bones(x0, body.idx, body.w, garment_points, reach)
    keep = region_triangles(body.triangles, body.idx, body.w, bones)
    ids, tri = submesh(body.triangles, keep)
    part = SkinnedMeshCollider(body.part(ids, tri), collider.A, collider.b, collider.motion,
                               collider.friction, collider.thickness)
    part.cut_of_closed = True
    names = ", ".join(body.skeleton.names[b] for b in bones)
    summary = (f"{int(keep.sum())} of {keep.size} triangles, {ids.size} of "
               f"{body.rest.shape[0]} vertices within reach {reach:g} m: {names}")
    return part, summary
