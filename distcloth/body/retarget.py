"""Retargeting a motion capture clip to the body's skeleton.

Method (direction matching with a rest alignment):

1. Mapping.  Every body joint names one capture joint (``CMU_MAPPING`` for
   the CMU conversions; a caller's entries override it).  A body joint owns
   the bone to its first child; the capture joint's global rotation drives it.
2. Frame.  The capture's rest pose is turned about its up axis (y) so that it
   faces +z like the body: facing = left × up, with left = left hip − right
   hip at rest ("auto"; the CMU files already face +z with their left at +x,
   so the turn is the identity there).
3. Rest alignment.  For a body joint j with a child c, ``A_j`` is the minimal
   rotation taking the body's rest bone direction (rest_c − rest_j) to the
   capture's rest bone direction (from j's capture joint to c's, going on
   down the capture's first children while the two coincide, as Hips and
   LowerBack do in the CMU skeleton).  A leaf (head, wrists, ankles) takes its
   parent's alignment, ``A_leaf = A_parent``: the body's skeleton does not say
   where a hand, foot or head points, so the leaf keeps the angle to its
   parent bone it has at rest, as it has it in the capture's rest pose.
4. Animation.  ``R_j(t) = G_j(t) A_j`` with ``G_j`` the global rotation of
   j's capture joint (relative to the capture's rest, turned into the body's
   frame), so the body bone points exactly where the capture bone points.
   Joint positions follow by forward kinematics down the body skeleton with
   the body's own bone lengths, ``J_c = J_p + R_p (rest_c − rest_p)``; the
   pelvis is at ``scale * root(t) + offset`` with ``scale`` the body's hip
   height over the capture's (root to hip height plus thigh and shin
   lengths), the offset putting the pelvis at its rest position horizontally
   at the first played clip time and the lowest ankle of the body over the
   played frames (a planted foot) at the mean rest height of its ankles.
5. Skinning.  A rest point x on bone j moves to ``R_j x + t_j`` with
   ``t_j = J_j − R_j rest_j``.

What the rest poses give.  Identity transforms (every ``R_j = I``, pelvis at
rest) are exactly the body's rest pose, so a body settling before a walk is
"identity" and blending toward a clip is done on these bone rotations (see
``distcloth.body.clip``).  The capture at its own rest pose (every channel
zero) gives ``R_j = A_j``: the body with its bones along the capture's rest
bones, a T-pose with the capture's leg spread, not the body's A-pose.

Velocities are not returned: ``BodyMotion.transforms`` is a function of time,
so a caller finite-differences positions at t ± dt.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Collection, Mapping

import numpy as np

from .arm_clearance import abduct
from .bvh import BvhClip, bvh_global, rest_positions
from .clip import Timeline, blend_from_identity, sample, with_root_motion
from .leg_clearance import spread_legs
from .skeleton import Skeleton

# body joint -> capture joint (alternatives in order of preference) for the CMU
# database's BVH conversion with 31 joints and a Hips root (names checked
# against cmu_07_01_walk.bvh)
CMU_MAPPING: dict[str, tuple[str, ...]] = {
    "pelvis": ("Hips",), "spine": ("LowerBack",), "chest": ("Spine1",),
    "neck": ("Neck1", "Neck"), "head": ("Head",),
    "l_shoulder": ("LeftArm",), "l_elbow": ("LeftForeArm",), "l_wrist": ("LeftHand",),
    "r_shoulder": ("RightArm",), "r_elbow": ("RightForeArm",), "r_wrist": ("RightHand",),
    "l_hip": ("LeftUpLeg",), "l_knee": ("LeftLeg",), "l_ankle": ("LeftFoot",),
    "r_hip": ("RightUpLeg",), "r_knee": ("RightLeg",), "r_ankle": ("RightFoot",),
}

# the joints whose rest bones differ by pose, not by anatomy, between a T-pose
# capture and an A-pose body (``make_retargeting(aligned=LIMB_JOINTS)``)
LIMB_JOINTS = ("l_shoulder", "l_elbow", "r_shoulder", "r_elbow", "l_hip", "l_knee", "r_hip", "r_knee")

UP = np.array([0.0, 1.0, 0.0])


class MappingError(ValueError):
    """A body joint the capture has no (suitable) joint for."""


def resolve_mapping(clip: BvhClip, skeleton: Skeleton,
                    mapping: Mapping[str, str | tuple[str, ...]] | None = None) -> np.ndarray:
    """(J_body,) capture joint index of every body joint.  ``mapping`` entries
    (body joint -> capture joint name, or a tuple of alternatives) override
    ``CMU_MAPPING``.  A body joint's capture joint must descend from its
    parent's."""
    merged = {k: v for k, v in CMU_MAPPING.items()}
    for key, value in (mapping or {}).items():
        if key not in skeleton.names:
            raise MappingError(f"retarget mapping: {key!r} is not a body joint (joints: {', '.join(skeleton.names)})")
        merged[key] = (value,) if isinstance(value, str) else tuple(value)
    index = np.empty(len(skeleton.names), dtype=np.int64)
    for j, name in enumerate(skeleton.names):
        found = [c for c in merged.get(name, ()) if c in clip.names]
        if not found:
            raise MappingError(f"retarget mapping: body joint {name!r} -> {' or '.join(merged.get(name, ('?',)))}, "
                             f"not a joint of the capture (joints: {', '.join(clip.names)})")
        index[j] = clip.index(found[0])
    for j, p in enumerate(skeleton.parents):
        if p >= 0 and not _descends(clip, index[j], index[p]):
            raise MappingError(f"retarget mapping: {clip.names[index[j]]!r} (body {skeleton.names[j]}) does not "
                             f"descend from {clip.names[index[p]]!r} (body {skeleton.names[p]})")
    return index


def _descends(clip: BvhClip, j: int, ancestor: int) -> bool:
    j = clip.parents[j]
    while j >= 0:
        if j == ancestor:
            return True
        j = clip.parents[j]
    return False


def minimal_rotation(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The rotation by the smallest angle taking direction a to direction b (3, 3)."""
    a = np.asarray(a, dtype=np.float64) / np.linalg.norm(a)
    b = np.asarray(b, dtype=np.float64) / np.linalg.norm(b)
    v = np.cross(a, b)
    c = float(a @ b)
    if c < -1.0 + 1e-12:
        # opposite: half a turn about any axis perpendicular to a
        axis = np.cross(a, np.eye(3)[np.argmin(np.abs(a))])
        axis /= np.linalg.norm(axis)
        return 2.0 * np.outer(axis, axis) - np.eye(3)
    k = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    return np.eye(3) + k + k @ k / (1.0 + c)


def facing_rotation(clip: BvhClip, bvh_joints: np.ndarray, skeleton: Skeleton) -> np.ndarray:
    """Rotation about y (3, 3) turning the capture's rest facing (left hip − right
    hip, crossed with up) to +z, the body's facing."""
    rest = rest_positions(clip)
    left = rest[bvh_joints[skeleton.index("l_hip")]] - rest[bvh_joints[skeleton.index("r_hip")]]
    forward = np.cross(left, UP)
    if np.hypot(forward[0], forward[2]) < 1e-12 * max(np.linalg.norm(left), 1e-300):
        raise ValueError("retarget: the capture's hips are not side by side at rest, cannot tell its facing")
    angle = -np.arctan2(forward[0], forward[2])
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _hip_height(pos: np.ndarray, idx: dict[str, int]) -> float:
    """Root height above the hips plus the mean thigh + shin length: the root's
    height standing with straight vertical legs."""
    legs = [np.linalg.norm(pos[idx[f"{s}_knee"]] - pos[idx[f"{s}_hip"]])
            + np.linalg.norm(pos[idx[f"{s}_ankle"]] - pos[idx[f"{s}_knee"]]) for s in ("l", "r")]
    hips = 0.5 * (pos[idx["l_hip"]] + pos[idx["r_hip"]])
    return float((pos[idx["pelvis"]] - hips) @ UP + np.mean(legs))


@dataclass(frozen=True)
class Retargeting:
    """Everything that ties a capture to a body skeleton (``make_retargeting``).

    ``bvh_joints`` (J,) capture joint of each body joint; ``align`` (J, 3, 3)
    the rest alignments A_j; ``frame`` (3, 3) turns capture coordinates into
    the body's; the pelvis is at ``scale * frame @ root(t) + offset``."""
    skeleton: Skeleton
    bvh_joints: np.ndarray
    align: np.ndarray
    frame: np.ndarray
    scale: float
    offset: np.ndarray


def make_retargeting(clip: BvhClip, skeleton: Skeleton, mapping=None, frame="auto",
                     scale: float | None = None, start: float = 0.0, end: float | None = None,
                     aligned: Collection[str] | None = None) -> Retargeting:
    """Build the retargeting of ``clip`` to ``skeleton`` (method in the module doc).

    ``frame``: "auto" (turn the capture to face +z), or a (3, 3) rotation from
    capture to body coordinates.  ``scale``: body length per capture length
    (default: the ratio of hip heights).  ``start``/``end`` (clip seconds): the
    played part, whose first time puts the pelvis at its rest position
    horizontally and whose lowest ankle sets the height.  ``aligned``: the
    body joints (with children) that get the rest alignment A_j; the others
    get the identity (None: all, the method above; ``LIMB_JOINTS``: arms and
    legs only, so a torso upright at the capture's rest stays upright on the
    body even where the two spines bend differently).  Leaves always take
    their parent's."""
    bvh = resolve_mapping(clip, skeleton, mapping)
    turn = facing_rotation(clip, bvh, skeleton) if isinstance(frame, str) and frame == "auto" \
        else np.asarray(frame, dtype=np.float64)
    if turn.shape != (3, 3) or not np.allclose(turn @ turn.T, np.eye(3), atol=1e-9):
        raise ValueError(f"retarget frame must be 'auto' or a 3x3 rotation, got {frame!r}")
    cap_rest = rest_positions(clip) @ turn.T
    body_rest = skeleton.rest
    extent = max(np.ptp(cap_rest, axis=0).max(), 1e-300)
    align = np.empty((len(skeleton.names), 3, 3))
    for j in range(len(skeleton.names)):  # parents first: a leaf takes its parent's
        kids = skeleton.children(j)
        if len(kids) == 0:
            align[j] = align[skeleton.parents[j]] if skeleton.parents[j] >= 0 else np.eye(3)
            continue
        if aligned is not None and skeleton.names[j] not in aligned:
            align[j] = np.eye(3)
            continue
        c = kids[0]
        target = bvh[c]
        direction = cap_rest[target] - cap_rest[bvh[j]]
        while np.linalg.norm(direction) < 1e-9 * extent:
            below = clip.children(target)
            if len(below) == 0:
                raise ValueError(f"retarget: capture joints {clip.names[bvh[j]]!r} and {clip.names[bvh[c]]!r} "
                                 f"coincide at rest and nothing below gives the bone's direction")
            target = below[0]
            direction = cap_rest[target] - cap_rest[bvh[j]]
        bone = body_rest[c] - body_rest[j]
        if np.linalg.norm(bone) == 0.0:
            raise ValueError(f"retarget: body joints {skeleton.names[j]} and {skeleton.names[c]} coincide at rest")
        align[j] = minimal_rotation(bone, direction)
    idx = {n: i for i, n in enumerate(skeleton.names)}
    if scale is None:
        scale = _hip_height(body_rest, idx) / _hip_height(cap_rest[bvh], idx)
    if not (np.isfinite(scale) and scale > 0):
        raise ValueError(f"retarget scale must be positive, got {scale!r}")
    # the pelvis's capture joint at the first played time, and the played frames' ankles
    _, first = bvh_global(sample(clip, [start]))
    played = np.arange(clip.n_frames)
    if clip.n_frames > 1 and np.isfinite(clip.frame_time) and clip.frame_time > 0:
        t = played * clip.frame_time
        last = np.inf if end is None else end
        keep = (t >= start - 0.5 * clip.frame_time) & (t <= last + 0.5 * clip.frame_time)
        played = played[keep] if keep.any() else played[[min(int(round(start / clip.frame_time)), clip.n_frames - 1)]]
    root = turn @ first[0, bvh[idx["pelvis"]]]
    offset = body_rest[idx["pelvis"]] - scale * root
    offset[1] = 0.0
    rt = Retargeting(skeleton, bvh, align, turn, float(scale), offset)
    _, joints = retarget_pose(rt, clip, played)
    ankle_rest = 0.5 * (body_rest[idx["l_ankle"], 1] + body_rest[idx["r_ankle"], 1])
    offset[1] = ankle_rest - joints[:, [idx["l_ankle"], idx["r_ankle"]], 1].min()
    return replace(rt, offset=offset)


def body_fk(skeleton: Skeleton, rot: np.ndarray, root: np.ndarray) -> np.ndarray:
    """Joint positions (F, J, 3) from bone rotations (F, J, 3, 3) and root positions
    (F, 3): ``J_c = J_p + R_p (rest_c − rest_p)``."""
    joints = np.empty(rot.shape[:2] + (3,))
    for j, p in enumerate(skeleton.parents):
        if p < 0:  # the pelvis, the skeleton's one root
            joints[:, j] = root
        else:
            joints[:, j] = joints[:, p] + rot[:, p] @ (skeleton.rest[j] - skeleton.rest[p])
    return joints


def skinning_transforms(skeleton: Skeleton, rot: np.ndarray, joints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-bone (R (F, J, 3, 3), t (F, J, 3)): a rest point x of bone j moves to
    ``R_j x + t_j``, so ``t_j = J_j − R_j rest_j``."""
    return rot, joints - np.einsum("fjab,jb->fja", rot, skeleton.rest)


def retarget_pose(rt: Retargeting, clip: BvhClip, frames=None) -> tuple[np.ndarray, np.ndarray]:
    """Body bone rotations (F, J, 3, 3) and joint positions (F, J, 3) for the
    clip's frames (all, or ``frames``)."""
    glob, pos = bvh_global(clip, frames)
    g = rt.frame @ glob[:, rt.bvh_joints] @ rt.frame.T
    rot = g @ rt.align
    root = rt.scale * pos[:, rt.bvh_joints[rt.skeleton.index("pelvis")]] @ rt.frame.T + rt.offset
    return rot, body_fk(rt.skeleton, rot, root)


class BodyMotion:
    """A clip retargeted to a body and placed on a timeline (``clip.Timeline``):
    rest pose, blend in, play, hold or blend out.  The rest pose blended into
    is the body's rest (identity transforms); the one blended out to is the
    rest pose standing where the clip ended (the pelvis keeps its last
    horizontal position, takes its rest height).

    ``transforms(times)`` gives the skinning transforms at scene times (seconds);
    vertex velocities are finite differences of skinned positions at t ± dt
    (no analytic velocities)."""

    def __init__(self, clip: BvhClip, skeleton: Skeleton, timeline: Timeline = Timeline(),
                 root_motion: str = "keep", mapping=None, frame="auto", scale: float | None = None,
                 aligned: Collection[str] | None = None):
        self.clip = with_root_motion(clip, root_motion)
        self.skeleton = skeleton
        self.timeline = timeline
        self.end_time = timeline.total(clip.duration)  # also checks the timeline against the clip
        self.retargeting = make_retargeting(self.clip, skeleton, mapping, frame, scale,
                                            timeline.start, timeline.clip_end(clip.duration), aligned)
        # (times) -> (F, 2) arms' extra abduction (arm_clearance.py); None: as captured
        self.spread = None
        # (times) -> (F, 2) legs' turn apart about the hips (leg_clearance.py); None: as captured
        self.leg_spread = None

    def pose(self, times) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Blend weights (F,), bone rotations (F, J, 3, 3) and joint positions (F, J, 3)."""
        times = np.atleast_1d(np.asarray(times, dtype=np.float64))
        w = self.timeline.weight(times, self.clip.duration)
        u = self.timeline.clip_time(times, self.clip.duration)
        rot, joints = retarget_pose(self.retargeting, sample(self.clip, u))
        rot = blend_from_identity(rot, w[:, None])
        if self.spread is not None:
            rot = abduct(self.skeleton, rot, self.spread(times))
        if self.leg_spread is not None:
            rot = spread_legs(self.skeleton, rot, self.leg_spread(times))
        pelvis = self.skeleton.index("pelvis")
        rest_root = np.broadcast_to(self.skeleton.rest[pelvis], (len(times), 3)).copy()
        # blending out after the clip: rest pose where the walk ended (horizontally)
        out = times > self.timeline.settle + self.timeline.blend_in
        rest_root[out, 0] = joints[out, pelvis, 0]
        rest_root[out, 2] = joints[out, pelvis, 2]
        root = rest_root + w[:, None] * (joints[:, pelvis] - rest_root)
        return w, rot, body_fk(self.skeleton, rot, root)

    def transforms(self, times) -> tuple[np.ndarray, np.ndarray]:
        """Skinning transforms (R (F, J, 3, 3), t (F, J, 3)) at scene times (1-D)."""
        _, rot, joints = self.pose(times)
        return skinning_transforms(self.skeleton, rot, joints)
