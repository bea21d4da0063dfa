"""A body mesh driven by motion capture: rigged once, skinned at any time.

``AnimatedBody`` fits the skeleton to the mesh (skeleton_fit.py), computes
bone-heat weights (skinning_weights.py), retargets the clip to the skeleton
(retarget.py) and answers "where is every vertex at t, how fast is it
moving": the skinned positions (skinning.py) and their central differences
over ``VELOCITY_DT``, so contact and friction see the moving skin.  Poses
are cached per time: a step queries the same t several times.
"""
from __future__ import annotations

import copy

import numpy as np

from .arm_clearance import solve as arm_clearance_solve
from .bvh import BvhClip
from .clip import Timeline
from .leg_clearance import solve as leg_clearance_solve
from .regions import dominant_bone
from .retarget import LIMB_JOINTS, BodyMotion
from .skeleton_fit import fit_skeleton
from .skinning import skin
from .skinning_weights import skinning_weights

# half the interval of the central difference for skin velocities: well under
# a capture frame (8.3 ms at 120 Hz), so a velocity is that of the frame's
# interpolation, yet far above round-off of metre-sized positions
VELOCITY_DT = 1.0e-4


class AnimatedBody:
    """Rest vertices (V, 3) and triangles of a body in its file's frame (y up,
    metres), the clip on a ``Timeline``, a skinning method ("dqs" or "lbs").

    ``mapping``: body joint -> capture joint names replacing the CMU ones
    (retarget.py).  ``aligned``: the joints whose rest bone is aligned to the capture's
    (retarget.py); the limbs by default, so the body's torso keeps its own
    posture instead of taking the capture skeleton's spine curve.  ``arm_clearance``
    (m): turn each arm out, where the capture brings it closer, until its
    upper arm is this far from the chest (arm_clearance.py); None: as captured.
    ``leg_clearance`` (m): turn both legs apart about the hips, where the
    capture brings the lower legs closer, until they are this far apart
    (leg_clearance.py); None: as captured."""

    def __init__(self, vertices, triangles, clip: BvhClip, timeline: Timeline, method: str = "dqs",
                 root_motion: str = "keep", aligned=LIMB_JOINTS, mapping=None,
                 arm_clearance: float | None = None, leg_clearance: float | None = None):
        self.rest = np.ascontiguousarray(vertices, dtype=np.float64)
        self.triangles = np.asarray(triangles, dtype=np.int64)
        self.method = method
        self.skeleton = fit_skeleton(self.rest, self.triangles)
        self.idx, self.w = skinning_weights(self.rest, self.triangles, self.skeleton)
        self.motion = BodyMotion(clip, self.skeleton, timeline, root_motion, mapping=mapping,
                                 aligned=aligned)
        self.end_time = float(self.motion.end_time)
        if arm_clearance is not None:
            arm_clearance_solve(self.skeleton, self.rest, self.triangles,
                                dominant_bone(self.idx, self.w), self._skin_some,
                                lambda times: self.motion.pose(times)[1:], self._use_spread,
                                self.end_time, float(arm_clearance))
        if leg_clearance is not None:
            leg_clearance_solve(self.skeleton, self.triangles, dominant_bone(self.idx, self.w),
                                self._skin_some, lambda times: self.motion.pose(times)[1:],
                                self._use_leg_spread, self.end_time, float(leg_clearance))
        self.clear_cache()

    def _use_spread(self, spread) -> None:
        self.motion.spread = spread

    def _use_leg_spread(self, spread) -> None:
        self.motion.leg_spread = spread

    def _skin_some(self, times, ids) -> np.ndarray:
        """(F, k, 3) rest vertices ``ids`` skinned at ``times``."""
        R, t = self.motion.transforms(np.asarray(times, dtype=np.float64))
        return skin(self.method, self.rest[ids], self.idx[ids], self.w[ids], R, t)

    def part(self, ids, triangles) -> "AnimatedBody":
        """The same rig and motion on the vertices ``ids`` only, with
        ``triangles`` indexing them (regions.py): only they are skinned."""
        part = copy.copy(self)
        part.rest, part.idx, part.w = self.rest[ids], self.idx[ids], self.w[ids]
        part.triangles = np.asarray(triangles, dtype=np.int64)
        part.clear_cache()
        return part

    def clear_cache(self) -> None:
        """Forget the cached poses (a part has its own vertices)."""
        self._positions, self._velocities = {}, {}

    def positions_at(self, times) -> np.ndarray:
        """Skinned vertices (F, V, 3) at scene times (F,)."""
        R, t = self.motion.transforms(np.atleast_1d(np.asarray(times, dtype=np.float64)))
        out = np.empty((R.shape[0],) + self.rest.shape)
        # the rest pose exactly where the body holds it (skinning's round-off
        # would make a resting body "move" by 1e-17 m), and not skinned at all
        still = (R == np.eye(3)).all(axis=(1, 2, 3)) & (np.abs(t) < 1e-12).all(axis=(1, 2))
        out[still] = self.rest
        if not still.all():
            out[~still] = skin(self.method, self.rest, self.idx, self.w, R[~still], t[~still])
        return out

    def _cached(self, cache: dict, t: float, compute) -> np.ndarray:
        value = cache.get(t)
        if value is None:
            if len(cache) > 8:          # a step asks for two or three times
                cache.clear()
            value = cache[t] = compute(t)
        return value

    def positions(self, t: float) -> np.ndarray:
        return self._cached(self._positions, float(t), lambda s: self.positions_at([s])[0])

    def velocities(self, t: float) -> np.ndarray:
        """Skin velocities (V, 3) at t: central differences (zero where the
        body holds a pose)."""
        def central(s):
            a, b = self.positions_at([s - VELOCITY_DT, s + VELOCITY_DT])
            return (b - a) / (2.0 * VELOCITY_DT)
        return self._cached(self._velocities, float(t), central)
