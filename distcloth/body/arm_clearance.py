"""Keeping the upper arms clear of the chest: the smallest extra abduction of
each arm, frame by frame, that leaves a gap a garment fits in.

Why.  A captured walk lets the arms hang close to the sides; on a skinned
body the upper arm then comes within a few millimetres of the chest, or
into it (the skin does not collide with itself).  Cloth there (a sleeve, a
bodice's armhole) is pinched between two moving surfaces closer than its
contact distances add up to: no position satisfies both contacts, and the
contact handling holds the cloth in rigid impact zones whose kinematic
vertices move apart, stretching it (docs/bodies.md, "Where the body meets
itself").  Real arms are held off the chest by the cloth itself.

What.  For each arm and each time of a grid, the smallest angle δ ≥ 0 by
which the whole arm (upper arm, forearm, hand) turns about the shoulder
joint, about the chest's forward axis and away from the body, such that
every skin point of the upper arm more than ``JUNCTION`` down the bone from
the shoulder (away from the armpit, where arm and chest skin are one
surface) is at least ``clearance`` from the chest's skin.  The chest skin
moves with δ only through its small arm weights, so the search turns the
upper arm's skinned points rigidly about the shoulder (a bisection; the
distance grows with δ), and again from the turned pose (``PASSES``).  The
angles are then made smooth in time: a running maximum over ±2 ``WINDOW``
and a running mean over ±``WINDOW`` (never below the angles found),
interpolated linearly between grid times.
Where the captured arm is clear already, δ = 0 and the pose is the capture's.

Kernels only: arrays in, arrays out.
"""
from __future__ import annotations

import numpy as np

from ..collision.colliders import MeshCollider
from ..collision.mesh_query import MeshProximity
from .skeleton import Skeleton

JUNCTION = 0.08          # m down the upper arm from the shoulder joint: below the armpit
GRID = 1.0 / 60.0        # s between the times the angle is solved at
WINDOW = 0.05            # s: the smoothing's half width
MAX_ANGLE = np.radians(35.0)
BISECTIONS = 14          # 35° / 2^14: 0.002°, 0.01 mm at the elbow
PASSES = 3               # searches from the spread pose (solve)
FORWARD = np.array([0.0, 0.0, 1.0])   # the body's front at rest (mesh frame: y up, front +z)
SIDES = (("l", 1.0), ("r", -1.0))     # the left arm is at +x: turning it about +z by +δ lifts it


def axis_rotations(axes: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """(F, 3, 3) rotations by ``angles`` (F,) about the unit ``axes`` (F, 3) (Rodrigues)."""
    k = axes / np.linalg.norm(axes, axis=1)[:, None]
    K = np.zeros((len(k), 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -k[:, 2], k[:, 1], -k[:, 0]
    K -= np.transpose(K, (0, 2, 1))
    s, c = np.sin(angles)[:, None, None], np.cos(angles)[:, None, None]
    return np.eye(3) + s * K + (1.0 - c) * (K @ K)


def arm_chain(skeleton: Skeleton, side: str) -> list[int]:
    """The shoulder joint of ``side`` and every joint below it."""
    chain, todo = [], [skeleton.index(f"{side}_shoulder")]
    while todo:
        j = todo.pop()
        chain.append(j)
        todo.extend(int(c) for c in skeleton.children(j))
    return chain


def abduct(skeleton: Skeleton, rot: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """Bone rotations (F, J, 3, 3) with each whole arm turned about its
    shoulder by ``angles`` (F, 2: left, right; radians, away from the body)
    about the chest's forward axis.  Joint positions follow by forward
    kinematics (retarget.body_fk): a rotation of every bone of the chain is
    a rotation of the chain about its first joint."""
    out = rot.copy()
    forward = rot[:, skeleton.index("chest")] @ FORWARD
    for k, (side, sign) in enumerate(SIDES):
        a = angles[:, k]
        if not np.any(a):
            continue
        Q = axis_rotations(forward, sign * a)
        for j in arm_chain(skeleton, side):
            out[:, j] = Q @ rot[:, j]
    return out


def _clear_angle(points, pivot, axis, chest: MeshProximity, clearance: float) -> float:
    """Smallest δ in [0, MAX_ANGLE] with every point, turned by δ about
    ``axis`` through ``pivot``, at least ``clearance`` from the chest's skin."""
    def gap(delta):
        Q = axis_rotations(axis[None], np.array([delta]))[0]
        return chest.closest((points - pivot) @ Q.T + pivot, max_distance=clearance)[2].min()
    if gap(0.0) >= clearance:
        return 0.0
    if gap(MAX_ANGLE) < clearance:
        return MAX_ANGLE
    lo, hi = 0.0, MAX_ANGLE
    for _ in range(BISECTIONS):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if gap(mid) >= clearance else (mid, hi)
    return hi


def smooth_max(times: np.ndarray, values: np.ndarray, window: float) -> np.ndarray:
    """Running maximum over ±2 window, then running mean over ±window (per
    column): every mean is over maxima whose windows all hold t, so the
    result is nowhere below ``values``."""
    def running(vals, half, reduce):
        out = np.empty_like(vals)
        for i, t in enumerate(times):
            out[i] = reduce(vals[np.abs(times - t) <= half + 1e-12], axis=0)
        return out
    return running(running(values, 2.0 * window, np.max), window, np.mean)


class ArmSpread:
    """Abduction angles (F, 2: left, right) at any scene time: solved on a
    grid once (``solve``), interpolated linearly, held after its last time
    (the body holds its last pose)."""

    def __init__(self, times: np.ndarray, angles: np.ndarray):
        self.times = np.asarray(times, dtype=np.float64)
        self.angles = np.asarray(angles, dtype=np.float64)

    def __call__(self, times) -> np.ndarray:
        t = np.atleast_1d(np.asarray(times, dtype=np.float64))
        return np.stack([np.interp(t, self.times, self.angles[:, k])
                         for k in range(2)], axis=1)

    @property
    def largest(self) -> np.ndarray:
        """(2,) the largest angle of each arm, radians."""
        return self.angles.max(axis=0) if len(self.angles) else np.zeros(2)


def solve(skeleton: Skeleton, rest_vertices: np.ndarray, triangles: np.ndarray,
          dominant: np.ndarray, skin_at, pose_at, use, end_time: float,
          clearance: float) -> ArmSpread:
    """The angles on a grid over [0, end_time].

    ``dominant`` (V,): each rest vertex's dominant bone (the chest's skin: the
    triangles whose corners are all the chest's or the spine's);
    ``pose_at(times)`` -> (rot (F, J, 3, 3), joints (F, J, 3)) and
    ``skin_at(times, vertices)`` -> (F, k, 3) the skinned positions of
    ``vertices`` (rest indices), both with the spread last given to
    ``use(spread)``.  The rigid turn of the search is not the skinning's (the
    upper arm's skin near the chest blends in the chest's bones), so the
    search runs again from the spread pose, ``PASSES`` times in all."""
    on_chest = np.isin(dominant, [skeleton.index("chest"), skeleton.index("spine")])
    chest_tri = triangles[on_chest[triangles].all(axis=1)]
    chest_ids, chest_tri = np.unique(chest_tri, return_inverse=True)
    chest_tri = chest_tri.reshape(-1, 3)
    arms = []
    for side, _ in SIDES:
        sh, el = skeleton.index(f"{side}_shoulder"), skeleton.index(f"{side}_elbow")
        bone = skeleton.rest[el] - skeleton.rest[sh]
        along = (rest_vertices - skeleton.rest[sh]) @ (bone / np.linalg.norm(bone))
        arms.append(np.flatnonzero((dominant == sh) & (along > JUNCTION)))
    ids = np.concatenate([chest_ids] + arms)
    n_chest = len(chest_ids)
    times = np.linspace(0.0, end_time, int(np.ceil(end_time / GRID)) + 1)
    spread = ArmSpread(times, np.zeros((len(times), 2)))
    needed = np.zeros((len(times), 2))      # the least angle found to give the gap
    for _ in range(PASSES):
        use(spread)
        rot, joints = pose_at(times)
        skinned = skin_at(times, ids)
        extra = np.zeros((len(times), 2))
        for f in range(len(times)):
            chest = MeshProximity(MeshCollider.static(skinned[f, :n_chest], chest_tri))
            forward = rot[f, skeleton.index("chest")] @ FORWARD
            start = n_chest
            for k, (side, sign) in enumerate(SIDES):
                pts = skinned[f, start:start + len(arms[k])]
                start += len(arms[k])
                pivot = joints[f, skeleton.index(f"{side}_shoulder")]
                extra[f, k] = _clear_angle(pts, pivot, sign * forward, chest, clearance)
        if not extra.any():
            break
        # where the smoothed angle is not enough, it needs this much more; elsewhere
        # keep what was needed (smoothing the smoothed angles again would widen
        # the turn by a window each pass)
        needed = np.where(extra > 0.0, np.maximum(needed, spread.angles + extra), needed)
        spread = ArmSpread(times, np.minimum(smooth_max(times, needed, WINDOW), MAX_ANGLE))
    use(spread)
    return spread
