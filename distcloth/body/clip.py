"""Operations on a motion clip, pure functions: trimming, root motion,
sampling at arbitrary times, and the timeline that blends a body from its
rest pose into a clip and out of it.

Rotations interpolate as unit quaternions (slerp, the shorter way round);
translations linearly.  Times before the clip's first frame or after its
last clamp to them.

Where blending happens.  The rest pose a body settles in before it walks is
its own (an A-pose for distcloth's bodies), not the capture's (a T-pose for
the CMU clips).  After retargeting (``distcloth.body.retarget``) that pose is
every bone rotation the identity with the pelvis at its rest position, so the
blend is done there: each bone's rotation slerps from the identity to the
clip's and the pelvis moves linearly, then the body's forward kinematics
places the joints.  Blending the BVH's local rotations instead would need the
local rotations that put the capture's skeleton in the body's rest pose,
which are defined only for the joints the retargeting maps (the capture's
clavicles, extra spine and neck joints, fingers have no counterpart) and
would again have to go through the same retargeting to become the body's
identity; blending after retargeting makes "at rest" exact (identity
transforms, zero translations) by construction.  ``Timeline`` gives the blend
weight and the clip time for every scene time; ``blend_from_identity`` blends
rotations; the retargeting module puts them together (``BodyMotion``).
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..rotations import matrix_from_quat, quat_from_matrix
from .bvh import BvhClip

ROOT_MOTIONS = ("keep", "remove")      # a clip's travel: kept, or walked in place


# --- quaternions (w, x, y, z), unit, acting on column vectors ---------------------------

def slerp(q0: np.ndarray, q1: np.ndarray, w) -> np.ndarray:
    """Spherical interpolation of unit quaternions (..., 4) by weights w (broadcast
    against the leading axes), the shorter way round; normalised lerp where the
    two are within 1e-6 rad (where slerp and lerp agree to 1e-13)."""
    q0 = np.asarray(q0, dtype=np.float64)
    q1 = np.asarray(q1, dtype=np.float64)
    w = np.asarray(w, dtype=np.float64)[..., None]
    dot = np.sum(q0 * q1, axis=-1, keepdims=True)
    q1 = np.where(dot < 0.0, -q1, q1)
    dot = np.clip(np.abs(dot), 0.0, 1.0)
    theta = np.arccos(dot)
    sin_theta = np.sin(theta)
    small = sin_theta < 1e-6
    safe = np.where(small, 1.0, sin_theta)
    a = np.where(small, 1.0 - w, np.sin((1.0 - w) * theta) / safe)
    b = np.where(small, w, np.sin(w * theta) / safe)
    q = a * q0 + b * q1
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def slerp_matrices(r0: np.ndarray, r1: np.ndarray, w) -> np.ndarray:
    """Rotations (..., 3, 3) a fraction w of the way from r0 to r1 (exactly r0
    where w == 0 and r1 where w == 1)."""
    w = np.asarray(w, dtype=np.float64)
    out = matrix_from_quat(slerp(quat_from_matrix(r0), quat_from_matrix(r1), w))
    out = np.where((w == 0.0)[..., None, None], r0, out)
    return np.where((w == 1.0)[..., None, None], r1, out)


def blend_from_identity(rot: np.ndarray, w) -> np.ndarray:
    """Rotations (..., 3, 3) a fraction w of the way from the identity to ``rot``."""
    return slerp_matrices(np.broadcast_to(np.eye(3), np.shape(rot)), rot, w)


def smoothstep(s) -> np.ndarray:
    """3s² − 2s³ on [0, 1], clamped outside: 0 → 1 with zero slope at both ends (C1)."""
    s = np.clip(np.asarray(s, dtype=np.float64), 0.0, 1.0)
    return s * s * (3.0 - 2.0 * s)


def _smoothstep_integral(s) -> np.ndarray:
    """∫₀ˢ smoothstep = s³ − s⁴/2 on [0, 1] (1/2 at s = 1)."""
    s = np.clip(np.asarray(s, dtype=np.float64), 0.0, 1.0)
    return s ** 3 - 0.5 * s ** 4


# --- clip operations ---------------------------------------------------------------------

def trim(clip: BvhClip, first: int = 0, last: int | None = None) -> BvhClip:
    """The frames first..last-1 (Python slice rules).  In cmu_07_01_walk.bvh frame 0
    is a reference pose, not part of the walk: ``trim(clip, 1)`` drops it (or
    start a ``Timeline`` one frame in)."""
    sel = slice(first, last)
    if clip.rotations[sel].shape[0] == 0:
        raise ValueError(f"trim({first}, {last}) leaves no frame of {clip.n_frames}")
    return replace(clip, rotations=clip.rotations[sel].copy(), translations=clip.translations[sel].copy())


def remove_root_motion(clip: BvhClip) -> BvhClip:
    """Walk in place: every root's horizontal position (x, z of the BVH's y-up frame)
    is held at its first frame's; its height and all rotations are kept."""
    tr = clip.translations.copy()
    roots = np.flatnonzero(clip.parents < 0)
    tr[:, roots[:, None], [0, 2]] = tr[:1, roots[:, None], [0, 2]]
    return replace(clip, translations=tr)


def with_root_motion(clip: BvhClip, root_motion: str) -> BvhClip:
    if root_motion == "keep":
        return clip
    if root_motion == "remove":
        return remove_root_motion(clip)
    raise ValueError(f"root_motion must be one of {ROOT_MOTIONS}, got {root_motion!r}")


def sample(clip: BvhClip, times, speed: float = 1.0, root_motion: str = "keep") -> BvhClip:
    """The clip at times ``times`` (seconds, 1-D) of a playback at ``speed``: clip time
    ``speed * t`` from the first frame, clamped to [0, duration].  Local rotations
    slerp between the two nearest frames, translations interpolate linearly; a time
    within 1e-9 frames of a frame gives that frame exactly.  Returns a clip with one
    frame per time (``frame_time`` the spacing of evenly spaced times, else NaN)."""
    if not (np.isfinite(speed) and speed > 0):
        raise ValueError(f"speed must be positive, got {speed!r}")
    clip = with_root_motion(clip, root_motion)
    times = np.atleast_1d(np.asarray(times, dtype=np.float64))
    if times.ndim != 1:
        raise ValueError(f"times must be 1-D, got shape {times.shape}")
    n = clip.n_frames
    if n > 1 and not (np.isfinite(clip.frame_time) and clip.frame_time > 0):
        raise ValueError(f"cannot sample a clip of unevenly spaced frames (frame_time {clip.frame_time})")
    if n == 1:
        f = np.zeros_like(times)
    else:
        f = np.clip(times * speed / clip.frame_time, 0.0, n - 1)
        near = np.round(f)
        f = np.where(np.abs(f - near) < 1e-9, near, f)
    i0 = np.minimum(np.floor(f).astype(np.int64), max(n - 2, 0))
    i1 = np.minimum(i0 + 1, n - 1)
    w = f - i0
    rot = slerp_matrices(clip.rotations[i0], clip.rotations[i1], w[:, None])
    tr = clip.translations[i0] + w[:, None, None] * (clip.translations[i1] - clip.translations[i0])
    tr = np.where((w == 0.0)[:, None, None], clip.translations[i0], tr)
    if len(times) > 1:
        steps = np.diff(times) * speed
        spacing = float(steps[0]) if np.allclose(steps, steps[0], rtol=1e-9, atol=0.0) else float("nan")
    else:
        spacing = clip.frame_time
    return replace(clip, rotations=rot, translations=tr, frame_time=spacing)


@dataclass(frozen=True)
class Timeline:
    """How scene time maps to a clip and to the blend weight of the clip's pose
    against the body's rest pose (weight 0: rest, 1: the clip).

    Scene time 0..settle: the body holds its rest pose.  Then for ``blend_in``
    seconds the weight rises by smoothstep from 0 to 1 while the pose held is
    the clip's first played frame (clip time ``start``).  Then the clip plays
    from ``start`` to ``end`` (seconds of clip time; None: its last frame) at
    ``speed``; with ``ease_in``/``ease_out`` > 0 the playback speed itself rises
    from 0 (falls to 0) by smoothstep over that many seconds, so the body's
    velocity is continuous where the clip starts and stops (without them it
    jumps from 0 to the clip's velocity there: the held pose is still, the clip
    is not).  After the clip the last played frame is held, or with
    ``blend_out`` > 0 the weight falls by smoothstep back to the rest pose.
    The weight is C1: smoothstep has zero slope at both ends.
    """
    settle: float = 0.0
    blend_in: float = 0.0
    blend_out: float = 0.0
    speed: float = 1.0
    start: float = 0.0
    end: float | None = None
    ease_in: float = 0.0
    ease_out: float = 0.0

    def __post_init__(self):
        for name in ("settle", "blend_in", "blend_out", "start", "ease_in", "ease_out"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"timeline {name} must be >= 0 seconds, got {value!r}")
        if not (np.isfinite(self.speed) and self.speed > 0):
            raise ValueError(f"timeline speed must be positive, got {self.speed!r}")
        if self.end is not None and not self.end > self.start:
            raise ValueError(f"timeline end ({self.end}) must come after start ({self.start})")

    def clip_end(self, clip_duration: float) -> float:
        """Clip time where playback stops."""
        end = clip_duration if self.end is None else min(self.end, clip_duration)
        if end < self.start:
            raise ValueError(f"timeline start {self.start} s is after the clip's end ({clip_duration} s)")
        return end

    def playback(self, clip_duration: float) -> float:
        """Scene seconds the clip plays (from the end of blend_in to the last frame)."""
        span = (self.clip_end(clip_duration) - self.start) / self.speed
        if span < 0.5 * (self.ease_in + self.ease_out) - 1e-12:
            raise ValueError(f"ease_in + ease_out ({self.ease_in + self.ease_out} s) need a clip of at "
                             f"least {0.5 * (self.ease_in + self.ease_out)} s at this speed, it plays {span} s")
        return span + 0.5 * (self.ease_in + self.ease_out)

    def total(self, clip_duration: float) -> float:
        """Scene time at which the timeline ends (rest reached again, or the last frame held)."""
        return self.settle + self.blend_in + self.playback(clip_duration) + self.blend_out

    def clip_time(self, t, clip_duration: float) -> np.ndarray:
        """Clip time (seconds) shown at scene times t."""
        t = np.asarray(t, dtype=np.float64)
        end = self.clip_end(clip_duration)
        T = self.playback(clip_duration)
        r1, r2 = self.ease_in, self.ease_out
        tau = np.clip(t - self.settle - self.blend_in, 0.0, T)
        # u(τ): playback progress in scene seconds at full speed; u' rises 0→1 over
        # ease_in, stays 1, falls 1→0 over the last ease_out seconds (smoothstep)
        u = tau - 0.5 * r1
        if r1 > 0:
            u = np.where(tau < r1, r1 * _smoothstep_integral(tau / r1), u)
        if r2 > 0:
            u = np.where(tau > T - r2, (T - 0.5 * (r1 + r2)) - r2 * _smoothstep_integral((T - tau) / r2), u)
        return np.minimum(self.start + self.speed * u, end)

    def weight(self, t, clip_duration: float) -> np.ndarray:
        """Blend weight of the clip against the rest pose at scene times t."""
        t = np.asarray(t, dtype=np.float64)
        t_in = t - self.settle
        w = (t_in >= 0).astype(np.float64) if self.blend_in == 0 else smoothstep(t_in / self.blend_in)
        if self.blend_out > 0:
            t_out = t - self.settle - self.blend_in - self.playback(clip_duration)
            w = w * (1.0 - smoothstep(t_out / self.blend_out))
        return w
