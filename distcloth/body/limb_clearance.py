"""What keeping a limb clear of the body needs, whichever limb: turning a
whole limb about its first joint, the least angle that opens a gap, and
angles made smooth in time (arm_clearance.py, leg_clearance.py).

Kernels only: arrays in, arrays out.
"""
from __future__ import annotations

import numpy as np

from ..collision.colliders import MeshCollider
from ..collision.mesh_query import MeshProximity
from .skeleton import Skeleton

FORWARD = np.array([0.0, 0.0, 1.0])   # the body's front at rest (mesh frame: y up, front +z)
SIDES = (("l", 1.0), ("r", -1.0))     # the left limbs are at +x: turning about +z by +δ lifts them
GRID = 1.0 / 60.0        # s between the times the angles are solved at
WINDOW = 0.05            # s: the smoothing's half width
BISECTIONS = 14          # 35° / 2^14: 0.002°, 0.01 mm at the elbow


def posed_mesh(triangles: np.ndarray):
    """``at(vertices)``: the closest-point queries of ``triangles`` at those
    vertices, one pose after another; the tree and the edge adjacency are
    built on the first call and refit on the later ones (a search visits
    hundreds of poses of the same skin)."""
    held: list[MeshProximity] = []

    def at(vertices) -> MeshProximity:
        if held:
            held[0].move_to(vertices)
        else:
            held.append(MeshProximity(MeshCollider.static(vertices, triangles)))
        return held[0]
    return at


def axis_rotations(axes: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """(F, 3, 3) rotations by ``angles`` (F,) about the unit ``axes`` (F, 3) (Rodrigues)."""
    k = axes / np.linalg.norm(axes, axis=1)[:, None]
    K = np.zeros((len(k), 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -k[:, 2], k[:, 1], -k[:, 0]
    K -= np.transpose(K, (0, 2, 1))
    s, c = np.sin(angles)[:, None, None], np.cos(angles)[:, None, None]
    return np.eye(3) + s * K + (1.0 - c) * (K @ K)


def limb_chain(skeleton: Skeleton, first: str) -> list[int]:
    """The joint ``first`` and every joint below it."""
    chain, todo = [], [skeleton.index(first)]
    while todo:
        j = todo.pop()
        chain.append(j)
        todo.extend(int(c) for c in skeleton.children(j))
    return chain


def turn_out(skeleton: Skeleton, rot: np.ndarray, angles: np.ndarray, first: str,
             frame: str) -> np.ndarray:
    """Bone rotations (F, J, 3, 3) with each whole limb (the chains from
    ``l_<first>`` and ``r_<first>``) turned about its first joint by
    ``angles`` (F, 2: left, right; radians, away from the body) about the
    forward axis of bone ``frame``.  Joint positions follow by forward
    kinematics (retarget.body_fk): a rotation of every bone of the chain is
    a rotation of the chain about its first joint."""
    out = rot.copy()
    forward = rot[:, skeleton.index(frame)] @ FORWARD
    for k, (side, sign) in enumerate(SIDES):
        a = angles[:, k]
        if not np.any(a):
            continue
        Q = axis_rotations(forward, sign * a)
        for j in limb_chain(skeleton, f"{side}_{first}"):
            out[:, j] = Q @ rot[:, j]
    return out


def least_angle(gap, clearance: float, max_angle: float) -> float:
    """Smallest δ in [0, max_angle] with ``gap(δ) >= clearance`` (``gap``
    growing with δ; a bisection), or ``max_angle`` if even that is short."""
    if gap(0.0) >= clearance:
        return 0.0
    if gap(max_angle) < clearance:
        return max_angle
    lo, hi = 0.0, max_angle
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


def solve_grid(end_time: float, step: float = GRID) -> np.ndarray:
    """The times the angles are solved at, over [0, end_time], ``step`` apart at most."""
    return np.linspace(0.0, end_time, int(np.ceil(end_time / step)) + 1)


def solve_passes(times, passes: int, max_angle: float, ids, skin_at, pose_at, use,
                 frame_angles) -> "LimbSpread":
    """The spread over ``times``: each pass poses the body with the spread so
    far (``use(spread)``, then ``pose_at(times)`` -> (rot (F, J, 3, 3),
    joints (F, J, 3)) and ``skin_at(times, ids)`` -> (F, k, 3)), asks
    ``frame_angles(rot[f], joints[f], skinned[f])`` -> (2,) for the extra
    angles each frame still needs, and where one is needed raises the
    angles found to the smoothed spread plus that; elsewhere what was
    needed stays (smoothing the smoothed angles again would widen the turn
    by a window each pass).  Stops early when no frame needs more."""
    spread = LimbSpread(times, np.zeros((len(times), 2)))
    needed = np.zeros((len(times), 2))      # the least angles found to give the gap
    for _ in range(passes):
        use(spread)
        rot, joints = pose_at(times)
        skinned = skin_at(times, ids)
        extra = np.array([frame_angles(rot[f], joints[f], skinned[f]) for f in range(len(times))])
        if not extra.any():
            break
        needed = np.where(extra > 0.0, np.maximum(needed, spread.angles + extra), needed)
        spread = LimbSpread(times, np.minimum(smooth_max(times, needed, WINDOW), max_angle))
    use(spread)
    return spread


class LimbSpread:
    """Turning angles (F, 2: left, right) at any scene time: solved on a
    grid once, interpolated linearly, held after its last time (the body
    holds its last pose)."""

    def __init__(self, times: np.ndarray, angles: np.ndarray):
        self.times = np.asarray(times, dtype=np.float64)
        self.angles = np.asarray(angles, dtype=np.float64)

    def __call__(self, times) -> np.ndarray:
        t = np.atleast_1d(np.asarray(times, dtype=np.float64))
        return np.stack([np.interp(t, self.times, self.angles[:, k])
                         for k in range(2)], axis=1)

    @property
    def largest(self) -> np.ndarray:
        """(2,) the largest angle of each side, radians."""
        return self.angles.max(axis=0) if len(self.angles) else np.zeros(2)
