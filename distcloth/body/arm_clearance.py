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
interpolated linearly between grid times (limb_clearance.py).
Where the captured arm is clear already, δ = 0 and the pose is the capture's.

Kernels only: arrays in, arrays out.
"""
from __future__ import annotations

import numpy as np

from ..collision.mesh_query import MeshProximity
from .limb_clearance import (FORWARD, SIDES, LimbSpread, axis_rotations, least_angle,
                             limb_chain, posed_mesh, solve_grid, solve_passes, turn_out)
from .skeleton import Skeleton

JUNCTION = 0.08          # m down the upper arm from the shoulder joint: below the armpit
MAX_ANGLE = np.radians(35.0)
PASSES = 3               # searches from the spread pose (solve)

__all__ = ["JUNCTION", "abduct", "arm_chain", "axis_rotations", "solve"]


def arm_chain(skeleton: Skeleton, side: str) -> list[int]:
    """The shoulder joint of ``side`` and every joint below it."""
    return limb_chain(skeleton, f"{side}_shoulder")


def abduct(skeleton: Skeleton, rot: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """Bone rotations (F, J, 3, 3) with each whole arm turned about its
    shoulder by ``angles`` (F, 2: left, right; radians, away from the body)
    about the chest's forward axis."""
    return turn_out(skeleton, rot, angles, "shoulder", "chest")


def _clear_angle(points, pivot, axis, chest: MeshProximity, clearance: float) -> float:
    """Smallest δ in [0, MAX_ANGLE] with every point, turned by δ about
    ``axis`` through ``pivot``, at least ``clearance`` from the chest's skin."""
    def gap(delta):
        Q = axis_rotations(axis[None], np.array([delta]))[0]
        return chest.closest((points - pivot) @ Q.T + pivot, max_distance=clearance)[2].min()
    return least_angle(gap, clearance, MAX_ANGLE)


def solve(skeleton: Skeleton, rest_vertices: np.ndarray, triangles: np.ndarray,
          dominant: np.ndarray, skin_at, pose_at, use, end_time: float,
          clearance: float) -> LimbSpread:
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
    shoulders = [skeleton.index(f"{side}_shoulder") for side, _ in SIDES]

    chest_at = posed_mesh(chest_tri)

    def frame_angles(rot, joints, skinned):
        chest = chest_at(skinned[:n_chest])
        forward = rot[skeleton.index("chest")] @ FORWARD
        arm_points = np.split(skinned[n_chest:], [len(arms[0])])
        return [_clear_angle(pts, joints[j], sign * forward, chest, clearance)
                for pts, j, (_, sign) in zip(arm_points, shoulders, SIDES)]
    return solve_passes(solve_grid(end_time), PASSES, MAX_ANGLE, ids, skin_at, pose_at, use,
                        frame_angles)
