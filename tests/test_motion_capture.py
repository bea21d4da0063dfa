"""Motion capture input: the BVH reader and its forward kinematics, clip
sampling and blending, and retargeting to the body's skeleton.

Tolerances: quantities computed exactly up to rounding (a few matrix
products of numbers of order 1, quaternion round trips) are compared to
1e-12, a thousand times the rounding of the ~10 operations involved;
lengths preserved by orthogonal rotations over a 17-joint chain to 1e-9 m
(rounding is ~1e-15 m, 1e-9 leaves room for the 317-frame products);
measurements of the captured walk (heights, strides) to the spread a
human walk has, stated where used.
"""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from distcloth.body.bvh import CMU_SCALE, bvh_global, parse_bvh, read_bvh, rest_positions
from distcloth.body.clip import (Timeline, remove_root_motion,
                                 sample, smoothstep, trim)
from distcloth.body.retarget import (BodyMotion, LIMB_JOINTS, facing_rotation, make_retargeting,
                                     resolve_mapping, retarget_pose, skinning_transforms)
from distcloth.body.skeleton import JOINT_NAMES, skeleton_from_positions
from distcloth.rotations import matrix_from_quat, quat_from_matrix

CMU_FILE = Path("/work/shared/data/mocap/cmu_07_01_walk.bvh")


def rx(deg):
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def ry(deg):
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def rz(deg):
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def small_bvh(root_channels="Zrotation Xrotation Yrotation", joint_channels="Xrotation Yrotation Zrotation",
              frames=("0 0 0 0 0 0 0 0 0", "1 2 3 90 90 0 0 90 0"), frame_line=None):
    """A root (positions then the given rotation order), one joint, one End Site;
    written with tabs, CRLF and a brace on the keyword's line to exercise the tokenizer."""
    text = ("HIERARCHY\r\n"
            "ROOT root\r\n{\r\n"
            "\tOFFSET 0 0 0\r\n"
            f"\tCHANNELS 6 Xposition Yposition Zposition {root_channels}\r\n"
            "\tJOINT arm {\r\n"
            "\t\tOFFSET 1 0 0\r\n"
            f"\t\tCHANNELS 3 {joint_channels}\r\n"
            "\t\tEnd Site\r\n\t\t{\r\n\t\t\tOFFSET 2 0 0\r\n\t\t}\r\n"
            "\t}\r\n}\r\n"
            "MOTION\r\n"
            f"Frames: {len(frames)}\r\n"
            f"{frame_line or 'Frame Time: 0.1'}\r\n" + "".join(f + "\r\n" for f in frames))
    return text


def standin_skeleton():
    """Plausible rest joints of a 1.72 m A-pose body (y up, faces +z, left +x)."""
    c = np.sqrt(0.5)
    pos = {"pelvis": (0, .95, 0), "spine": (0, 1.05, 0), "chest": (0, 1.25, 0), "neck": (0, 1.45, 0),
           "head": (0, 1.55, 0)}
    for side, x in (("l", 1.0), ("r", -1.0)):
        shoulder = np.array([x * .18, 1.42, 0.0])
        elbow = shoulder + .28 * np.array([x * c, -c, 0.0])      # 45° down and out
        pos[f"{side}_shoulder"], pos[f"{side}_elbow"] = shoulder, elbow
        pos[f"{side}_wrist"] = elbow + .25 * np.array([x * c, -c, 0.0])
        pos[f"{side}_hip"], pos[f"{side}_knee"], pos[f"{side}_ankle"] = \
            (x * .09, .92, 0), (x * .10, .5, .01), (x * .10, .08, -.01)
    return skeleton_from_positions(np.array([pos[n] for n in JOINT_NAMES], dtype=float))


@pytest.fixture(scope="module")
def cmu():
    if not CMU_FILE.exists():
        pytest.skip(f"{CMU_FILE} is not on this machine")
    return read_bvh(CMU_FILE, scale=CMU_SCALE)


@pytest.fixture(scope="module")
def skeleton():
    return standin_skeleton()


# --- reader and forward kinematics --------------------------------------------------------

def test_small_file_forward_kinematics_by_hand():
    clip = parse_bvh(small_bvh())
    assert clip.names == ("root", "arm", "arm_end")
    assert list(clip.parents) == [-1, 0, 1]
    assert list(clip.end_site) == [False, False, True]
    assert clip.channels[0] == ("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation")
    assert list(clip.channel_start) == [0, 6, 9]
    assert clip.n_frames == 2 and clip.frame_time == 0.1
    rot, pos = bvh_global(clip)
    # frame 0 is the rest pose: joints at their offsets
    np.testing.assert_allclose(pos[0], [[0, 0, 0], [1, 0, 0], [3, 0, 0]], atol=1e-12)
    # frame 1: root at (1,2,3) turned by Rz(90) Rx(90), which takes x->y, y->z, z->x;
    # the arm's offset (1,0,0) -> (0,1,0), so the arm is at (1,3,3); the arm's own
    # Ry(90) takes the End Site's (2,0,0) to (0,0,-2), the root's turn that to (-2,0,0)
    root_rot = np.array([[0, 0, 1], [1, 0, 0], [0, 1, 0]])
    np.testing.assert_allclose(rot[1, 0], root_rot, atol=1e-12)
    np.testing.assert_allclose(pos[1], [[1, 2, 3], [1, 3, 3], [-1, 3, 3]], atol=1e-12)
    np.testing.assert_allclose(rest_positions(clip), pos[0], atol=0)
    # selecting frames gives the same numbers
    rot1, pos1 = bvh_global(clip, [1])
    np.testing.assert_array_equal(pos1[0], pos[1])


def test_scale_applies_to_offsets_and_positions():
    clip = parse_bvh(small_bvh(), scale=0.5)
    _, pos = bvh_global(clip)
    np.testing.assert_allclose(pos[1], 0.5 * np.array([[1, 2, 3], [1, 3, 3], [-1, 3, 3]]), atol=1e-12)
    assert clip.scale == 0.5


def test_channel_order_matters():
    angles = {"X": 40.0, "Y": 50.0, "Z": 30.0}
    results = {}
    for order in ("ZXY", "XYZ", "YZX"):
        channels = " ".join(f"{a}rotation" for a in order)
        values = " ".join(str(angles[a]) for a in order)
        clip = parse_bvh(small_bvh(root_channels=channels, frames=(f"0 0 0 {values} 0 0 0",)))
        results[order] = clip.rotations[0, 0]
    m = {"X": rx(40.0), "Y": ry(50.0), "Z": rz(30.0)}
    for order, rot in results.items():
        np.testing.assert_allclose(rot, m[order[0]] @ m[order[1]] @ m[order[2]], atol=1e-12)
    assert np.abs(results["ZXY"] - results["XYZ"]).max() > 0.1
    assert np.abs(results["ZXY"] - results["YZX"]).max() > 0.1


def test_position_channels_on_a_joint_add_to_its_offset():
    text = small_bvh(frames=("0 0 0 0 0 0 0 0 0",)).replace(
        "CHANNELS 3 Xrotation", "CHANNELS 4 Zposition Xrotation").replace(
        "0 0 0 0 0 0 0 0 0", "0 0 0 0 0 0 0.5 0 0 0")
    clip = parse_bvh(text)
    np.testing.assert_allclose(clip.translations[0, 1], [1, 0, 0.5], atol=0)


@pytest.mark.parametrize("text, line, what", [
    (small_bvh().replace("Frames: 2\r\n", ""), 16, "Frames"),
    (small_bvh().replace("1 2 3 90 90 0 0 90 0", "1 2 3 90 90 0 0 90"), 19, "9 values"),
    (small_bvh().replace("Xrotation Yrotation Zrotation", "Xrotation Yrotation Wrotation"), 8, "channel name"),
    (small_bvh(frame_line="Frame Time: -1"), 17, "positive frame time"),
    (small_bvh().replace("\t\t\tOFFSET 2 0 0", "\t\t\tOFFSET 2 0"), 12, "number"),
    (small_bvh().replace("MOTION\r\n", ""), 15, "MOTION"),
    (small_bvh().replace("JOINT arm {", "JOINT arm"), 7, "'{'"),
    (small_bvh(frames=("0 0 0 0 0 0 0 0 0", "0 0 0 0 0 x 0 0 0")), 19, "numbers"),
    (small_bvh(frames=("0 0 0 0 0 0 0 0 0", "0 0 0 0 0 0 0 0 0", "0 0 0 0 0 0 0 0 0")).replace(
        "Frames: 3", "Frames: 2"), 20, "end of file"),
])
def test_malformed_files_name_the_line(text, line, what):
    with pytest.raises(ValueError, match=rf"line {line}: expected .*{what}") as err:
        parse_bvh(text, source="bad.bvh")
    assert "\n" not in str(err.value) and str(err.value).startswith("bad.bvh")


def test_cmu_file(cmu):
    assert int(np.sum(~cmu.end_site)) == 31
    assert cmu.n_joints == 31 + 7                 # 5 chain tips, 2 thumbs
    assert cmu.n_frames == 317
    assert abs(cmu.frame_time - 1 / 120) < 1e-6
    rot, pos = bvh_global(cmu)
    # the hips start 15.75 units up: 0.889 m at the CMU unit of 1/0.45 inch
    assert abs(pos[0, cmu.index("Hips"), 1] - 0.889) < 0.005
    # FK correctness: every bone keeps its rest length in every frame
    child = np.flatnonzero(cmu.parents >= 0)
    length = np.linalg.norm(pos[:, child] - pos[:, cmu.parents[child]], axis=-1)
    np.testing.assert_allclose(length, np.broadcast_to(np.linalg.norm(cmu.offsets[child], axis=-1), length.shape),
                               atol=1e-9)
    # global rotations stay orthonormal
    np.testing.assert_allclose(rot @ np.swapaxes(rot, -1, -2), np.broadcast_to(np.eye(3), rot.shape), atol=1e-12)
    # it walks along +z, its left side at +x: the left foot's x is larger in every frame
    left, right = pos[:, cmu.index("LeftFoot")], pos[:, cmu.index("RightFoot")]
    assert np.all(left[:, 0] > right[:, 0])
    # the feet alternate: their forward coordinates cross at least twice
    assert np.count_nonzero(np.diff(np.sign(left[:, 2] - right[:, 2]))) >= 2
    hips = pos[:, cmu.index("Hips")]
    assert hips[-1, 2] - hips[0, 2] > 3.0      # 3.58 m in 2.63 s
    # the conversion's frame 0 is a reference pose, not part of the walk: the
    # change to frame 1 (largest rotation-matrix entry change, mean over joints:
    # 0.22) is over five times any later frame-to-frame change (at most 0.025)
    steps = np.abs(np.diff(cmu.rotations, axis=0)).max(axis=(2, 3)).mean(axis=1)
    assert steps[0] > 5 * steps[1:].max()


def test_cmu_root_motion_removed(cmu):
    _, pos = bvh_global(remove_root_motion(cmu))
    hips = pos[:, cmu.index("Hips")]
    # walk in place: the hips stay within a few cm of their start horizontally
    # (exactly at it: the root's horizontal position is held) and keep their height
    assert np.abs(hips[:, [0, 2]] - hips[0, [0, 2]]).max() < 0.03
    np.testing.assert_array_equal(hips[:, 1], bvh_global(cmu)[1][:, cmu.index("Hips"), 1])


# --- sampling -----------------------------------------------------------------------------

def test_quaternion_round_trip():
    rng = np.random.default_rng(3)
    q = rng.normal(size=(200, 4))
    rot = matrix_from_quat(q)
    np.testing.assert_allclose(matrix_from_quat(quat_from_matrix(rot)), rot, atol=1e-12)


def test_slerp_sampling():
    axis = np.array([1.0, 2.0, 2.0]) / 3.0
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])

    def about_axis(deg):
        a = np.radians(deg)
        return np.eye(3) + np.sin(a) * k + (1 - np.cos(a)) * k @ k

    clip = parse_bvh(small_bvh(frames=("0 0 0 0 0 0 0 0 0", "1 2 3 90 90 0 0 90 0", "0 0 0 10 20 30 0 0 0")))
    clip = replace(clip, rotations=clip.rotations.copy())
    clip.rotations[0, 1] = np.eye(3)
    clip.rotations[1, 1] = about_axis(100.0)
    dt = clip.frame_time
    at_frames = sample(clip, np.arange(3) * dt)
    np.testing.assert_array_equal(at_frames.rotations, clip.rotations)
    np.testing.assert_array_equal(at_frames.translations, clip.translations)
    half = sample(clip, [0.5 * dt])
    np.testing.assert_allclose(half.rotations[0, 1], about_axis(50.0), atol=1e-12)   # the half angle
    np.testing.assert_allclose(half.translations[0, 0], [0.5, 1.0, 1.5], atol=1e-12)  # linear
    quarter = sample(clip, [1.25 * dt])
    r0, r1 = clip.rotations[1, 0], clip.rotations[2, 0]
    rel = r0.T @ r1                                    # a quarter of the relative turn
    angle = np.arccos((np.trace(rel) - 1) / 2)
    got = r0.T @ quarter.rotations[0, 0]
    assert abs(np.arccos(np.clip((np.trace(got) - 1) / 2, -1, 1)) - angle / 4) < 1e-12
    # playback speed and clamping at the ends
    np.testing.assert_array_equal(sample(clip, [0.5 * dt], speed=2.0).rotations[0], clip.rotations[1])
    np.testing.assert_array_equal(sample(clip, [-1.0, 10.0]).rotations, clip.rotations[[0, 2]])
    assert sample(clip, [0.0, 0.05, 0.1]).frame_time == pytest.approx(0.05)


# --- timeline and blending ----------------------------------------------------------------

def test_timeline_weight_is_c1():
    tl = Timeline(settle=0.4, blend_in=0.5, blend_out=0.3, start=0.0)
    duration = 2.0
    h = 1e-5
    for edge in (0.4, 0.9, 0.9 + 2.0, 0.9 + 2.0 + 0.3):
        left = (tl.weight(edge, duration) - tl.weight(edge - h, duration)) / h
        right = (tl.weight(edge + h, duration) - tl.weight(edge, duration)) / h
        # smoothstep's slope at its ends is O(h / T²) ~ 1e-4 one step away; a linear
        # ramp would jump by 1/T >= 2 there
        assert abs(left - right) < 1e-3
    assert tl.weight(0.2, duration) == 0.0 and tl.weight(1.5, duration) == 1.0
    assert tl.weight(0.65, duration) == pytest.approx(smoothstep(0.5))
    assert tl.weight(10.0, duration) == 0.0
    assert tl.clip_time(0.9, duration) == 0.0 and tl.clip_time(1.4, duration) == pytest.approx(0.5)


def test_timeline_ease_makes_clip_time_c1():
    tl = Timeline(settle=0.1, blend_in=0.2, ease_in=0.4, ease_out=0.3, speed=1.5, start=0.2, end=1.7)
    duration = 2.0
    h = 1e-5
    t_play, total = 0.3, tl.total(duration)
    for edge in (t_play, t_play + 0.4, total - 0.3, total):
        left = (tl.clip_time(edge, duration) - tl.clip_time(edge - h, duration)) / h
        right = (tl.clip_time(edge + h, duration) - tl.clip_time(edge, duration)) / h
        assert abs(left - right) < 1e-3
    assert tl.clip_time(total, duration) == pytest.approx(1.7)
    assert tl.clip_time(t_play + 0.4 + 0.1, duration) - tl.clip_time(t_play + 0.4, duration) == pytest.approx(0.15)


def test_blending_from_rest_into_the_clip(cmu, skeleton):
    tl = Timeline(settle=0.3, blend_in=0.5, start=1 / 120)
    motion = BodyMotion(cmu, skeleton, tl)
    # settle: the body's rest pose, identity transforms
    rot, trans = motion.transforms(np.linspace(0.0, 0.3, 7))
    np.testing.assert_allclose(rot, np.broadcast_to(np.eye(3), rot.shape), atol=1e-12)
    np.testing.assert_allclose(trans, 0.0, atol=1e-12)
    # end of blend_in: the clip's first played frame
    rot, trans = motion.transforms([0.8])
    rot_c, joints_c = retarget_pose(motion.retargeting, sample(motion.clip, [1 / 120]))
    rot_c, trans_c = skinning_transforms(skeleton, rot_c, joints_c)
    np.testing.assert_allclose(rot, rot_c, atol=1e-12)
    np.testing.assert_allclose(trans, trans_c, atol=1e-12)
    # joint velocities continuous where the blend starts (the weight's slope is 0 there)
    h = 1e-4
    _, _, joints = motion.pose([0.3 - h, 0.3, 0.3 + h])
    assert np.abs(joints[2] - joints[1]).max() / h < 1e-2


def test_ease_in_starts_the_walk_without_a_velocity_jump(cmu, skeleton):
    h = 1e-3
    edge = 0.8
    for ease, expect_jump in ((0.0, True), (0.4, False)):
        motion = BodyMotion(cmu, skeleton, Timeline(settle=0.3, blend_in=0.5, start=1 / 120, ease_in=ease))
        _, _, j = motion.pose([edge - h, edge, edge + h])
        jump = np.linalg.norm((j[2] - j[1]) / h - (j[1] - j[0]) / h, axis=-1).max()
        # the captured pelvis moves at 1.3 m/s: without easing the velocity jumps by that
        assert (jump > 1.0) if expect_jump else (jump < 0.05)


# --- retargeting --------------------------------------------------------------------------

def test_cmu_mapping_and_facing(cmu, skeleton):
    bvh = resolve_mapping(cmu, skeleton)
    assert [cmu.names[i] for i in bvh[:5]] == ["Hips", "LowerBack", "Spine1", "Neck1", "Head"]
    # the CMU skeleton already faces +z with its left at +x: no turn
    np.testing.assert_array_equal(facing_rotation(cmu, bvh, skeleton), np.eye(3))
    with pytest.raises(ValueError, match="not a joint of the capture"):
        resolve_mapping(cmu, skeleton, {"head": "Skull"})


def test_auto_frame_undoes_a_turned_capture(cmu, skeleton):
    """The same walk recorded facing -x (every offset, rotation and translation
    turned by -90° about y) retargets to the same body motion."""
    q = np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])    # +z -> -x
    clip = trim(cmu, 1, 40)
    turned = replace(clip, offsets=clip.offsets @ q.T, rotations=q @ clip.rotations @ q.T,
                     translations=clip.translations @ q.T)
    rt, rt_turned = make_retargeting(clip, skeleton), make_retargeting(turned, skeleton)
    np.testing.assert_allclose(rt_turned.frame, q.T, atol=1e-12)
    for a, b in zip(retarget_pose(rt, clip), retarget_pose(rt_turned, turned)):
        np.testing.assert_allclose(a, b, atol=1e-12)


def test_capture_rest_pose_gives_its_t_pose(cmu, skeleton):
    """At the capture's rest (all channels zero) every body bone with a child points
    along the capture's rest bone: R_j = A_j, the capture's T-pose, not the body's
    A-pose (which is the identity, see the settle test)."""
    rest = replace(cmu, rotations=np.broadcast_to(np.eye(3), (1,) + cmu.rotations.shape[1:]).copy(),
                   translations=cmu.offsets[None].copy())
    rt = make_retargeting(rest, skeleton)
    rot, joints = retarget_pose(rt, rest)
    np.testing.assert_allclose(rot[0], rt.align, atol=1e-12)
    cap = rest_positions(cmu)
    for body, a, b in (("l_shoulder", "LeftArm", "LeftForeArm"), ("l_elbow", "LeftForeArm", "LeftHand"),
                       ("r_elbow", "RightForeArm", "RightHand"), ("l_hip", "LeftUpLeg", "LeftLeg"),
                       ("spine", "LowerBack", "Spine1")):
        j = skeleton.index(body)
        c = skeleton.children(j)[0]
        got = joints[0, c] - joints[0, j]
        want = cap[cmu.index(b)] - cap[cmu.index(a)]
        np.testing.assert_allclose(got / np.linalg.norm(got), want / np.linalg.norm(want), atol=1e-12)
    # the arms are horizontal there (T-pose) while the body's rest arms hang at 45°
    arm = joints[0, skeleton.index("l_elbow")] - joints[0, skeleton.index("l_shoulder")]
    assert abs(arm[1]) < 0.01 * np.linalg.norm(arm)
    # aligning the limbs only leaves the torso as the capture's upright rest has it: identity
    rt_limbs = make_retargeting(rest, skeleton, aligned=LIMB_JOINTS)
    rot_l, _ = retarget_pose(rt_limbs, rest)
    for name in ("pelvis", "spine", "chest", "neck", "head"):
        np.testing.assert_allclose(rot_l[0, skeleton.index(name)], np.eye(3), atol=1e-12)


def test_retargeted_walk(cmu, skeleton):
    clip = trim(cmu, 1)                               # drop the reference frame
    walk = BodyMotion(clip, skeleton, Timeline())
    t = np.arange(clip.n_frames) * clip.frame_time
    _, rot, joints = walk.pose(t)
    # the body's bone lengths in every frame
    child = np.flatnonzero(skeleton.parents >= 0)
    length = np.linalg.norm(joints[:, child] - joints[:, skeleton.parents[child]], axis=-1)
    rest_length = np.linalg.norm(skeleton.rest[child] - skeleton.rest[skeleton.parents[child]], axis=-1)
    np.testing.assert_allclose(length, np.broadcast_to(rest_length, length.shape), atol=1e-9)
    # skinning transforms carry each child joint with its parent bone
    r, tr = walk.transforms(t)
    p = skeleton.parents[child]
    carried = np.einsum("fjab,jb->fja", r[:, p], skeleton.rest[child]) + tr[:, p]
    np.testing.assert_allclose(carried, joints[:, child], atol=1e-12)
    pelvis = joints[:, skeleton.index("pelvis")]
    np.testing.assert_allclose(pelvis[0, [0, 2]], skeleton.rest[0, [0, 2]], atol=1e-12)
    # a walking speed: 1.31 m/s measured (human walks: 1.0-1.7 m/s)
    speed = (pelvis[-1, 2] - pelvis[0, 2]) / (t[-1] - t[0])
    assert 1.0 < speed < 1.7
    # strides: a foot is planted where its ankle moves slower than 0.3 m/s; the
    # planted positions fall in clusters along z (a gap > 0.3 m between clusters);
    # consecutive plants of one foot are a stride apart: 1.41-1.44 m measured
    # (1.2-1.7 m for a walk at that speed)
    strides = []
    for name in ("l_ankle", "r_ankle"):
        ankle = joints[:, skeleton.index(name)]
        slow = np.linalg.norm(np.diff(ankle, axis=0), axis=1) / clip.frame_time < 0.3
        z = np.sort(ankle[1:][slow, 2])
        plants = [c.mean() for c in np.split(z, np.flatnonzero(np.diff(z) > 0.3) + 1) if len(c) >= 5]
        strides += list(np.diff(plants))
    assert len(strides) >= 2
    assert all(1.2 < s < 1.7 for s in strides)
    # walking in place: the ankles swing fore and aft of the pelvis by about a step
    # (0.84 m peak to peak measured; 0.5-1.2 m for a step of 0.7 m)
    in_place = BodyMotion(clip, skeleton, Timeline(), root_motion="remove")
    _, _, j2 = in_place.pose(t)
    assert np.abs(j2[:, 0, [0, 2]] - skeleton.rest[0, [0, 2]]).max() < 1e-12
    swing = j2[:, skeleton.index("l_ankle"), 2] - j2[:, 0, 2]
    assert 0.5 < np.ptp(swing) < 1.2
    # the planted foot is at the body's ankle height (the walk's lowest ankle)
    ankles_y = joints[:, [skeleton.index("l_ankle"), skeleton.index("r_ankle")], 1]
    assert ankles_y.min() == pytest.approx(0.08, abs=1e-12)
