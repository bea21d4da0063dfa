"""Keeping the lower legs clear of each other: the smallest turn of both
legs out about the hips, frame by frame, that leaves a gap two trouser legs
fit in.

Why.  In a captured walk the swinging foot passes the standing ankle
closely: in the CMU walk 07_01 the skinned ankles come within 1 mm of each
other.  Trouser legs there are pinched between two moving surfaces closer
than their contact distances add up to (body, cloth, cloth, body): no
position satisfies every contact, and the contact handling stretches the
hems between the feet (a straight-leg trousers' walk stopped with a hem
triangle past 100 % strain as the ankles passed).  Real legs are held
apart by the cloth itself.

What.  For each time of a grid, the smallest angle δ ≥ 0 by which both
whole legs (thigh, shin, foot) turn about their hip joints, each away from
the other by δ about the pelvis's forward axis, such that every skin point
of the left lower leg (the skin the knee and ankle bones dominate: shin and
foot) is at least ``clearance`` from the right lower leg's skin.  Lower
legs only: the thighs meet at the crotch in the rest pose already, where
the skin is one surface.  Both legs turn rigidly below the knee, so the
search turns the skinned points (a bisection; the distance grows with δ).
The angles are then made smooth in time as the arms' are
(limb_clearance.py), on a finer grid.  Where the captured legs are clear
already, δ = 0.

Kernels only: arrays in, arrays out.
"""
from __future__ import annotations

import numpy as np

from ..collision.mesh_query import MeshProximity
from .limb_clearance import (FORWARD, LimbSpread, axis_rotations, least_angle, posed_mesh,
                             solve_grid, solve_passes, turn_out)
from .skeleton import Skeleton

MAX_ANGLE = np.radians(10.0)   # per leg; 0.8 m below the hip: 14 cm at the ankle
PASSES = 2                     # searches from the spread pose (solve)
# a swinging foot passes the standing ankle in about 10 ms: half the
# capture's frame time (120 Hz), not the arms' 1/60 s, or the closest
# moment falls between grid times
GRID = 1.0 / 240.0


def lower_leg_bones(skeleton: Skeleton, side: str) -> list[int]:
    """The bones whose skin is the lower leg of ``side``: shin and foot."""
    return [skeleton.index(f"{side}_knee"), skeleton.index(f"{side}_ankle")]


def spread_legs(skeleton: Skeleton, rot: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """Bone rotations (F, J, 3, 3) with each whole leg turned about its hip
    by ``angles`` (F, 2: left, right; radians, away from the other leg)
    about the pelvis's forward axis."""
    return turn_out(skeleton, rot, angles, "hip", "pelvis")


def _clear_angle(left, hips, forward, right: MeshProximity, clearance: float) -> float:
    """Smallest δ with the ``left`` points, the left leg turned by δ about
    its hip and the right one by -δ about its own (``hips`` (2, 3)), at
    least ``clearance`` from the right lower leg's skin.  The right leg's
    turn is applied to the points inversely, so its mesh stays put."""
    hl, hr = hips

    def gap(delta):
        Ql, Qr = axis_rotations(np.stack([forward, forward]), np.array([delta, -delta]))
        turned = (left - hl) @ Ql.T + hl
        return right.closest((turned - hr) @ Qr + hr, max_distance=clearance)[2].min()
    return least_angle(gap, clearance, MAX_ANGLE)


def solve(skeleton: Skeleton, triangles: np.ndarray, dominant: np.ndarray, skin_at, pose_at,
          use, end_time: float, clearance: float) -> LimbSpread:
    """The angles (both columns equal) on a grid over [0, end_time].

    ``dominant`` (V,): each rest vertex's dominant bone; ``pose_at(times)``
    -> (rot (F, J, 3, 3), joints (F, J, 3)) and ``skin_at(times, vertices)``
    -> (F, k, 3) the skinned positions of ``vertices`` (rest indices), both
    with the spread last given to ``use(spread)``."""
    left = np.flatnonzero(np.isin(dominant, lower_leg_bones(skeleton, "l")))
    on_right = np.isin(dominant, lower_leg_bones(skeleton, "r"))
    right_ids, right_tri = np.unique(triangles[on_right[triangles].all(axis=1)],
                                     return_inverse=True)
    right_tri = right_tri.reshape(-1, 3)
    ids = np.concatenate([left, right_ids])
    hips = [skeleton.index("l_hip"), skeleton.index("r_hip")]
    pelvis = skeleton.index("pelvis")

    right_at = posed_mesh(right_tri)

    def frame_angles(rot, joints, skinned):
        right = right_at(skinned[len(left):])
        delta = _clear_angle(skinned[:len(left)], joints[hips], rot[pelvis] @ FORWARD, right,
                             clearance)
        return [delta, delta]
    return solve_passes(solve_grid(end_time, GRID), PASSES, MAX_ANGLE, ids, skin_at, pose_at,
                        use, frame_angles)
