"""Limbs kept clear of the body (distcloth.body.arm_clearance,
distcloth.body.leg_clearance): the turn of a whole arm about its shoulder
and of a whole leg about its hip, and on the bundled body walking the CMU
walk, the gaps ``arm_clearance`` (upper arm to chest) and ``leg_clearance``
(lower leg to lower leg) ask for, checked against densely sampled skin
(independent of the closest-point search the solver uses) at times off the
solvers' grids, with the rest of the body as captured.

Every rank builds the same bodies (no MPI in this file).
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from conftest import ROOT
from distcloth.body.animated import AnimatedBody
from distcloth.body.arm_clearance import JUNCTION, abduct, arm_chain, axis_rotations
from distcloth.body.bvh import read_bvh
from distcloth.body.clip import Timeline
from distcloth.body.leg_clearance import lower_leg_bones, spread_legs
from distcloth.body.limb_clearance import limb_chain
from distcloth.body.regions import dominant_bone
from distcloth.body.retarget import body_fk
from distcloth.config.schema import CMU_UNIT
from distcloth.scene.meshio import read_mesh

BODY = ROOT / "configs" / "meshes" / "mean_all.obj"
WALK = ROOT / "configs" / "motion" / "cmu_07_01_walk.bvh"
# the clip's first 1.6 s hold one pass of the swinging foot by the standing ankle
TIMELINE = Timeline(settle=0.2, blend_in=0.3, ease_in=0.2, start=1 / 120, end=1.6)
CLEARANCE = 0.015


@pytest.fixture(scope="module")
def bodies():
    x, tri = read_mesh(str(BODY))
    clip = read_bvh(str(WALK), scale=CMU_UNIT)
    return (AnimatedBody(x, tri, clip, TIMELINE, "dqs", "remove"),
            AnimatedBody(x, tri, clip, TIMELINE, "dqs", "remove", arm_clearance=CLEARANCE,
                         leg_clearance=CLEARANCE))


@pytest.mark.parametrize("turn, first, frame, below", [
    (abduct, "shoulder", "chest", ("elbow", "wrist")),
    (spread_legs, "hip", "pelvis", ("knee", "ankle")),
])
def test_turn_moves_each_whole_limb_about_its_first_joint(bodies, turn, first, frame, below):
    captured, _ = bodies
    sk = captured.skeleton
    times = np.array([0.7, 1.1, 1.4])
    _, rot, joints = captured.motion.pose(times)
    angles = np.radians([[5.0, 0.0], [12.0, 7.0], [0.0, 20.0]])
    moved = body_fk(sk, turn(sk, rot, angles), joints[:, sk.index("pelvis")])
    forward = rot[:, sk.index(frame)] @ np.array([0.0, 0.0, 1.0])
    limbs = set()
    for k, (side, sign) in enumerate((("l", 1.0), ("r", -1.0))):
        chain = limb_chain(sk, f"{side}_{first}")
        limbs.update(chain)
        assert [sk.names[j] for j in chain] == [f"{side}_{j}" for j in (first,) + below]
        Q = axis_rotations(forward, sign * angles[:, k])
        pivot = joints[:, chain[0]]
        for j in chain:
            expect = np.einsum("fab,fb->fa", Q, joints[:, j] - pivot) + pivot
            assert np.abs(moved[:, j] - expect).max() < 1e-12
        # away from the body: the limb's end moves out to its own side
        lateral = sign * (moved[:, chain[2], 0] - joints[:, chain[2], 0])
        assert np.all(lateral[angles[:, k] > 0] > 0)
    rest = [j for j in range(len(sk.names)) if j not in limbs]
    assert np.abs(moved[:, rest] - joints[:, rest]).max() < 1e-12
    if first == "shoulder":
        assert limb_chain(sk, f"l_{first}") == arm_chain(sk, "l")


def _skin_samples(x, tri, n=8):
    """Points on every triangle on a barycentric grid of n subdivisions: no
    point of a triangle is farther than its longest edge / n from them."""
    i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
    keep = i + j <= n
    a, b = i[keep] / n, j[keep] / n
    w = np.stack([1.0 - a - b, a, b], axis=1)
    return np.einsum("kc,tcd->tkd", w, x[tri]).reshape(-1, 3)


def _gap_to_skin(points, x, tri, n, within):
    """The smallest distance from ``points`` to the skin of triangles ``tri``
    (positions ``x``) sampled as ``_skin_samples``, or inf where it is
    ``within`` or more.  Only triangles with a corner within ``within`` + their
    longest edge of a point can hold a sample closer than ``within``: the rest
    are not sampled."""
    corners = x[tri]
    edge = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2).max()
    near = np.isfinite(cKDTree(points).query(corners.reshape(-1, 3),
                                             distance_upper_bound=within + edge)[0])
    near = near.reshape(-1, 3).any(axis=1)
    if not near.any():
        return np.inf
    return cKDTree(_skin_samples(x, tri[near], n)).query(
        points, distance_upper_bound=within)[0].min()


def test_walking_arms_keep_the_clearance(bodies):
    captured, spread = bodies
    sk = spread.skeleton
    dom = dominant_bone(spread.idx, spread.w)
    on_chest = np.isin(dom, [sk.index("chest"), sk.index("spine")])
    chest_tri = spread.triangles[on_chest[spread.triangles].all(axis=1)]
    upper = {}
    for side in "lr":
        sh, el = sk.index(f"{side}_shoulder"), sk.index(f"{side}_elbow")
        bone = sk.rest[el] - sk.rest[sh]
        along = (spread.rest - sk.rest[sh]) @ (bone / np.linalg.norm(bone))
        upper[side] = np.flatnonzero((dom == sh) & (along > JUNCTION))
    arm_ids = np.concatenate(list(upper.values()))
    not_limb = ~np.isin(dom, _limb_bones(sk))
    # off the 1/60 s grid the angles are interpolated: sample between grid times
    times = np.arange(0.0, spread.end_time, 0.0237)
    x_spread, x_captured = spread.positions_at(times), captured.positions_at(times)
    closest_captured, closest = np.inf, np.inf
    edge = np.linalg.norm(np.diff(spread.rest[chest_tri], axis=1, append=spread.rest[chest_tri][:, :1]),
                          axis=2).max()
    for f in range(len(times)):
        for x, name in ((x_captured[f], "captured"), (x_spread[f], "spread")):
            # gaps of twice the clearance or more are reported as inf: both
            # assertions below are about gaps under that
            gap = _gap_to_skin(x[arm_ids], x, chest_tri, 8, 2 * CLEARANCE)
            if name == "captured":
                closest_captured = min(closest_captured, gap)
            else:
                closest = min(closest, gap)
        # what the limbs do not move stays as captured (the chest's skin near the
        # shoulder takes a little of the arm's bone weights)
        assert np.abs(x_spread[f][not_limb] - x_captured[f][not_limb]).max() < 0.02
    # the capture brings the arms within a few millimetres of the chest
    assert closest_captured < 0.5 * CLEARANCE
    # sampled skin overestimates the distance by at most edge/8 (~1.5 mm on this
    # body), and between grid times the interpolated angle lags a swinging arm:
    # 10 % of the clearance covers both
    assert closest > 0.9 * CLEARANCE - edge / 8
    # the turn is the least that gives the gap, smoothed: a few degrees to tens
    largest = np.degrees(spread.motion.spread.largest)
    assert np.all(largest > 1.0) and np.all(largest < 30.0)
    # nothing moves while the body holds its rest pose (until the blend's window)
    still = times < TIMELINE.settle - 0.15
    assert np.array_equal(x_spread[still], x_captured[still])


def test_walking_lower_legs_keep_the_clearance(bodies):
    captured, spread = bodies
    sk = spread.skeleton
    dom = dominant_bone(spread.idx, spread.w)
    left = np.flatnonzero(np.isin(dom, lower_leg_bones(sk, "l")))
    on_right = np.isin(dom, lower_leg_bones(sk, "r"))
    right_ids, right_tri = np.unique(spread.triangles[on_right[spread.triangles].all(axis=1)],
                                     return_inverse=True)
    right_tri = right_tri.reshape(-1, 3)
    ids = np.concatenate([left, right_ids])
    # off the 1/240 s grid, where the angles are interpolated; the foot passes
    # the ankle in about 10 ms, so sample every 2.1 ms (the lower legs only)
    times = np.arange(0.0, spread.end_time, 0.0021)
    x_rest = spread.rest[right_ids]
    edge = np.linalg.norm(np.diff(x_rest[right_tri], axis=1, append=x_rest[right_tri][:, :1]),
                          axis=2).max()
    gaps = {}
    for name, body in (("captured", captured), ("spread", spread)):
        xs = body.part(ids, np.empty((0, 3), np.int64)).positions_at(times)
        # to the right leg's vertices first: the skin is at most an edge
        # closer, so only frames within that of the clearance need the samples
        gap = np.array([cKDTree(x[len(left):]).query(
            x[:len(left)], distance_upper_bound=CLEARANCE + edge)[0].min() for x in xs])
        for f in np.flatnonzero(gap < CLEARANCE + edge):
            gap[f] = _gap_to_skin(xs[f, :len(left)], xs[f, len(left):], right_tri, 6,
                                  2 * CLEARANCE)
        gaps[name] = gap
    # the capture brings the ankles within a few millimetres of each other
    assert gaps["captured"].min() < 0.25 * CLEARANCE
    # sampled skin overestimates the distance by at most edge/6, and between
    # grid times the interpolated angle lags the swinging foot: 10 % of the
    # clearance covers both
    assert gaps["spread"].min() > 0.9 * CLEARANCE - edge / 6
    # the least turn that gives the gap: about a degree per leg
    largest = np.degrees(spread.motion.leg_spread.largest)
    assert largest[0] == largest[1] and 0.1 < largest[0] < 5.0


def test_walking_legs_spread_moves_only_the_legs(bodies):
    captured, spread = bodies
    sk = spread.skeleton
    dom = dominant_bone(spread.idx, spread.w)
    legs = np.isin(dom, [sk.index(f"{s}_{j}") for s in "lr" for j in ("hip", "knee", "ankle")])
    not_limb = ~np.isin(dom, _limb_bones(sk))
    times = np.arange(0.0, spread.end_time, 0.0237)
    x_spread, x_captured = spread.positions_at(times), captured.positions_at(times)
    # the torso stays as captured (the pelvis's skin near the hips takes a
    # little of the legs' bone weights, the chest's of the arms')
    assert np.abs(x_spread[:, not_limb] - x_captured[:, not_limb]).max() < 0.02
    # a degree at the hip: under 2 cm at the toes
    assert np.abs(x_spread[:, legs] - x_captured[:, legs]).max() < 0.02
    # nothing moves while the body holds its rest pose (until the blend's window)
    still = times < TIMELINE.settle - 0.15
    assert np.array_equal(x_spread[still], x_captured[still])


def _limb_bones(sk):
    return [sk.index(f"{s}_{j}") for s in "lr"
            for j in ("shoulder", "elbow", "wrist", "hip", "knee", "ankle")]
