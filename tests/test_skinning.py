"""Skeleton fitting, bone heat weights and LBS / DQS skinning
(distcloth.body.skeleton_fit, .skinning_weights, .skinning).

Analytic checks of the two skinning methods, bone heat on a synthetic bent
tube (fast, exact geometry), and one module-scoped fit of the real
GarmentCode mean body (skipped when the mesh is absent): joints inside and
symmetric, weights sane and not bleeding across the body, the candy
wrapper.  No MPI, nothing written.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from distcloth.body.skeleton import JOINT_NAMES
from distcloth.body.skeleton_fit import fit_skeleton, sections
from distcloth.body.skinning import (axis_angle_matrix, candy_wrapper, dual_quaternion,
                                     linear_blend, mesh_volume, skin)
from distcloth.body.skinning_weights import (MAX_INFLUENCES, bone_heat, bone_segments,
                                             dense_weights, skinning_weights, visible_bone)
from distcloth.garment.start_check import ClosedMesh
from distcloth.rotations import quat_from_matrix
from distcloth.scene.meshio import read_mesh
from meshes import icosphere

BODY = Path(__file__).resolve().parents[1] / "configs" / "meshes" / "mean_all.obj"


def matrix_of_quaternion(q):
    """Rotation matrices (n, 3, 3) of unit quaternions (n, 4) as (w, x, y, z)."""
    w, x, y, z = np.asarray(q).T
    rows = [[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]]
    return np.stack([np.stack(r, axis=-1) for r in rows], axis=1)


def random_rotations(rng, n):
    q = rng.normal(size=(n, 4))
    return matrix_of_quaternion(q / np.linalg.norm(q, axis=1, keepdims=True))


def random_skin(rng, n_vertices=200, n_bones=6, k=4):
    x = rng.uniform(-1.0, 1.0, size=(n_vertices, 3))
    idx = np.stack([rng.choice(n_bones, k, replace=False) for _ in range(n_vertices)])
    w = rng.uniform(0.0, 1.0, size=(n_vertices, k))
    w /= w.sum(axis=1, keepdims=True)
    return x, idx, w


# ------------------------------------------------------------------ skinning, analytic

def test_identity_and_one_rigid_transform_are_reproduced():
    rng = np.random.default_rng(0)
    x, idx, w = random_skin(rng)
    J = 6
    R = np.repeat(np.eye(3)[None], J, axis=0)
    t = np.zeros((J, 3))
    for method in ("lbs", "dqs"):
        # identity: DQS blends exact unit quaternions (exact), LBS sums
        # w_k x with weights summing to 1 within an ulp: 1e-12 is rounding
        np.testing.assert_allclose(skin(method, x, idx, w, R, t), x, rtol=0, atol=1e-12)
    Q = random_rotations(rng, 3)
    shift = rng.normal(size=(3, 3))
    Rf = np.repeat(Q[:, None], J, axis=1)                   # (F, J, 3, 3): 3 frames
    tf = np.repeat(shift[:, None], J, axis=1)
    expected = np.einsum("fij,vj->fvi", Q, x) + shift[:, None, :]
    for method in ("lbs", "dqs"):
        got = skin(method, x, idx, w, Rf, tf)
        assert got.shape == (3, x.shape[0], 3)
        np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12)
        np.testing.assert_allclose(skin(method, x, idx, w, Rf[1], tf[1]), expected[1],
                                   rtol=0, atol=1e-12)
    with pytest.raises(ValueError):
        skin("slerp", x, idx, w, R, t)


def test_quaternion_from_matrix_round_trip():
    rng = np.random.default_rng(1)
    R = np.concatenate([random_rotations(rng, 50),
                        [axis_angle_matrix([1, 0, 0], np.pi), axis_angle_matrix([0, 1, 1], np.pi),
                         np.eye(3)]])
    q = quat_from_matrix(R)
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, rtol=0, atol=1e-15)
    # rounding of products of O(1) entries: 1e-14 leaves a decade of margin
    np.testing.assert_allclose(matrix_of_quaternion(q), R, rtol=0, atol=1e-14)


@pytest.mark.parametrize("theta_deg, mid_deg", [(10.0, 0.0), (60.0, 0.0), (120.0, 180.0)])
def test_two_bones_half_half_about_one_axis(theta_deg, mid_deg):
    """A vertex blended 0.5/0.5 between bones turned +theta and -theta about
    one axis through its joint: DQS gives the mid rotation on the shorter
    arc between them (identity, or the half turn when 2 theta > 180: the
    antipodality fix), LBS the chord, the radial offset shrunk by
    cos(theta)."""
    theta = np.radians(theta_deg)
    c = np.array([0.3, -0.2, 0.5])                  # the joint
    a = np.array([1.0, 2.0, 2.0]) / 3.0             # the axis
    p = c + 0.4 * a + np.array([0.2, 0.1, -0.2])    # axial 0.4 + radial part
    R = np.stack([axis_angle_matrix(a, theta), axis_angle_matrix(a, -theta)])
    t = c - R @ c
    idx, w = np.array([[0, 1]]), np.array([[0.5, 0.5]])
    rel = p - c
    axial = (rel @ a) * a
    mid = axis_angle_matrix(a, np.radians(mid_deg)) @ rel + c
    np.testing.assert_allclose(dual_quaternion(p[None], idx, w, R, t)[0], mid, atol=1e-14)
    np.testing.assert_allclose(linear_blend(p[None], idx, w, R, t)[0],
                               c + axial + np.cos(theta) * (rel - axial), atol=1e-14)


def test_dqs_blends_two_rotations_to_their_mean_and_takes_the_short_way():
    c = np.array([0.0, 1.0, 0.0])
    a = np.array([0.0, 0.0, 1.0])
    p = np.array([[0.5, 1.0, 0.2]])
    idx, w = np.array([[0, 1]]), np.array([[0.5, 0.5]])
    for alpha, beta, mean in ((20.0, 80.0, 50.0), (170.0, -170.0, 180.0)):
        # 170 and -170 degrees: the quaternions are on opposite hemispheres;
        # the antipodality fix blends them through 180, not through 0
        R = np.stack([axis_angle_matrix(a, np.radians(alpha)),
                      axis_angle_matrix(a, np.radians(beta))])
        t = c - R @ c
        expected = axis_angle_matrix(a, np.radians(mean)) @ (p[0] - c) + c
        np.testing.assert_allclose(dual_quaternion(p, idx, w, R, t)[0], expected, atol=1e-14)


# ------------------------------------------------------------------ bone heat, synthetic

def bent_tube(length=0.3, radius=0.05, bend_deg=60.0, n_around=24, step=0.01):
    """Closed tube along (0,0,0) -> E = (0, length, 0) -> E + length d2, d2
    in the x-y plane at bend_deg from +y; rings perpendicular to each
    straight part, one mitred ring at the elbow, flat end caps.  Returns
    (vertices, triangles, ring id of every vertex (-1 for the cap centres),
    arc length of every ring, E, d2)."""
    b = np.radians(bend_deg)
    d1 = np.array([0.0, 1.0, 0.0])
    d2 = np.array([np.sin(b), np.cos(b), 0.0])
    E = length * d1
    phi = 2 * np.pi * np.arange(n_around) / n_around
    z = np.array([0.0, 0.0, 1.0])

    def ring(center, d, scale=1.0):
        e1 = np.array([d[1], -d[0], 0.0])
        return center + radius * (np.cos(phi)[:, None] * e1 * scale + np.sin(phi)[:, None] * z)

    clear = radius * np.tan(b / 2) + step
    s1 = np.arange(0.0, length - clear, step)
    s2 = np.arange(clear, length + 1e-9, step)[::-1][::-1]
    bis = (d1 + d2) / np.linalg.norm(d1 + d2)
    rings = [ring(s * d1, d1) for s in s1]
    rings.append(ring(E, bis, 1.0 / np.cos(b / 2)))
    rings += [ring(E + s * d2, d2) for s in s2]
    arc = np.concatenate([s1, [length], length + s2])
    nr = len(rings)
    x = np.concatenate(rings + [[np.zeros(3)], [E + length * d2]])
    i = np.arange(n_around)
    tris = []
    for r in range(nr - 1):
        a0, a1 = r * n_around + i, r * n_around + (i + 1) % n_around
        b0, b1 = a0 + n_around, a1 + n_around
        tris += [np.stack([a0, a1, b1], 1), np.stack([a0, b1, b0], 1)]
    c0, c1 = nr * n_around, nr * n_around + 1
    tris.append(np.stack([np.full(n_around, c0), (i + 1) % n_around, i], 1))
    last = (nr - 1) * n_around
    tris.append(np.stack([np.full(n_around, c1), last + i, last + (i + 1) % n_around], 1))
    tri = np.concatenate(tris)
    if mesh_volume(x, tri) < 0:
        tri = tri[:, ::-1]
    ring_id = np.concatenate([np.repeat(np.arange(nr), n_around), [-1, -1]])
    return x, np.ascontiguousarray(tri), ring_id, arc, E, d2


def test_bone_heat_on_a_bent_tube():
    length, radius = 0.3, 0.05
    x, tri, ring_id, arc, E, d2 = bent_tube(length, radius)
    assert ClosedMesh(x, tri).closed
    heads = np.array([[0.0, 0.02, 0.0], E])
    tails = np.array([E, E + (length - 0.02) * d2])
    idx, w = bone_heat(x, tri, heads, tails)
    assert idx.shape == w.shape == (x.shape[0], MAX_INFLUENCES)
    assert (w >= 0).all() and np.allclose(w.sum(axis=1), 1.0, atol=1e-12)
    assert (w[w > 0] >= 0.01).all()
    W = dense_weights(idx, w, 2)
    assert (W.argmax(axis=1) == 0).sum() > 100 and (W.argmax(axis=1) == 1).sum() > 100
    on_ring = ring_id >= 0
    ring_w = np.bincount(ring_id[on_ring], W[on_ring, 0]) / np.bincount(ring_id[on_ring])
    # the upper bone's ring mean falls monotonically along the tube (up to
    # solver rounding; the tube is symmetric about its bend) ...
    assert (np.diff(ring_w) <= 1e-9).all()
    # ... smoothly: on a tube bone heat blends like exp(-s / radius) on each
    # side of the joint, slope about 0.5 / radius = 10 per metre at the
    # joint; measured max 7.8 per metre (the tie at the joint goes to the
    # child, so the mitred ring has 0.37, not 0.5)
    slope = np.abs(np.diff(ring_w) / np.diff(arc))
    assert slope.max() < 12.0
    assert 0.25 < ring_w[np.argmin(np.abs(arc - length))] < 0.75
    # ~1 / ~0 farther than 4 radii from the joint (exp(-4) / 2 = 0.009;
    # measured: ring means >= 0.989 and <= 0.0, every vertex >= 0.988)
    far1 = arc < length - 4 * radius
    far2 = arc > length + 4 * radius
    assert ring_w[far1].min() > 0.98 and ring_w[far2].max() < 0.02
    v_arc = np.where(ring_id >= 0, arc[np.maximum(ring_id, 0)], np.nan)
    assert W[v_arc < length - 4 * radius, 0].min() > 0.97
    assert W[v_arc > length + 4 * radius, 1].min() > 0.97


def test_visibility_takes_the_nearest_bone_the_vertex_can_see():
    """Two spheres: a vertex of the small one nearer to the big one's bone
    (through the air gap) must take its own sphere's bone."""
    vs, ts = icosphere(3)
    xa, ta = vs * 1.0, ts
    xb, tb = vs * 3.0 + [4.5, 0.0, 0.0], ts + vs.shape[0]
    x, tri = np.concatenate([xa, xb]), np.concatenate([ta, tb])
    heads = np.array([[-0.5, 0.0, 0.0], [2.0, 0.0, 0.0]])
    tails = np.array([[-0.4, 0.0, 0.0], [7.0, 0.0, 0.0]])
    seg, dist = visible_bone(x, tri, heads, tails)
    on_a = np.arange(x.shape[0]) < xa.shape[0]
    d_other = np.linalg.norm(x[on_a] - [2.0, 0.0, 0.0], axis=1)
    d_own = np.linalg.norm(x[on_a] - [-0.45, 0.0, 0.0], axis=1)
    assert (d_other < d_own - 0.05).any()            # the test case exists
    np.testing.assert_array_equal(seg, np.where(on_a, 0, 1))


# ------------------------------------------------------------------ the real body

@pytest.fixture(scope="module")
def body():
    if not BODY.exists():
        pytest.skip(f"{BODY} is absent")
    v, t = read_mesh(str(BODY))
    sk = fit_skeleton(v, t)
    idx, w = skinning_weights(v, t, sk)
    return v, t, sk, idx, w


def test_body_joints_are_inside_and_plausible(body):
    v, t, sk, _, _ = body
    assert sk.names == JOINT_NAMES
    assert ClosedMesh(v, t).inside(sk.rest).all()
    P = dict(zip(sk.names, sk.rest))
    H = v[:, 1].max() - v[:, 1].min()
    y = {k: p[1] / H for k, p in P.items()}
    # left / right mirror images: the mesh itself is symmetric to ~1 cm
    # (mirrored vertices lie within 9.5 mm of a vertex for 99 %, the
    # fingertips differ by 7.7 mm); fitted pairs differ by at most 9 mm
    for name in sk.names:
        if name.startswith("l_"):
            mirror = P[name] * [-1.0, 1.0, 1.0]
            assert np.linalg.norm(mirror - P["r_" + name[2:]]) < 0.015, name
    for name in ("pelvis", "spine", "chest", "neck", "head"):
        assert abs(P[name][0]) < 0.01, name          # on the midline
        assert abs(P[name][2]) < 0.05, name          # not at the front or back skin
    # chain heights (fractions of H; Drillis & Contini: hip 0.53, knee 0.285,
    # ankle 0.039, shoulder 0.818 (acromion), elbow 0.63, wrist 0.485 with the
    # arms hanging; the A-pose raises elbows and wrists)
    for s in ("l_", "r_"):
        assert y[s + "ankle"] < 0.06 < 0.24 < y[s + "knee"] < 0.32 < 0.46 < y[s + "hip"] < 0.55
        assert y[s + "hip"] < y["pelvis"]
        knee_mid = 0.5 * (y[s + "hip"] + y[s + "ankle"])
        assert abs(y[s + "knee"] - knee_mid) < 0.02
        assert 0.74 < y[s + "shoulder"] < 0.82
        assert y[s + "wrist"] < y[s + "elbow"] < y[s + "shoulder"]
        side = 1.0 if s == "l_" else -1.0
        lat = [side * P[s + j][0] for j in ("shoulder", "elbow", "wrist")]
        assert 0.0 < lat[0] < lat[1] < lat[2]
        assert 0.06 < side * P[s + "hip"][0] < 0.12
    assert y["pelvis"] < y["spine"] < y["chest"] < y["neck"] < y["head"] < 0.92


def test_body_weights(body):
    v, t, sk, idx, w = body
    J = len(sk.names)
    assert idx.shape == w.shape == (v.shape[0], MAX_INFLUENCES)
    assert (w >= 0).all() and np.allclose(w.sum(axis=1), 1.0, atol=1e-12)
    W = dense_weights(idx, w, J)
    # every bone is the dominant bone somewhere (fewest: the neck's 368 and
    # the spine's 459, which share their short bones' flesh with the
    # neighbours)
    dominant = np.bincount(idx[:, 0], minlength=J)
    assert (dominant >= 100).all(), dict(zip(sk.names, dominant))
    right = [i for i, n in enumerate(sk.names) if n.startswith("r_")]
    left = [i for i, n in enumerate(sk.names) if n.startswith("l_")]
    # no bleeding across the body (measured: exactly 0)
    assert W[v[:, 0] > 0.3][:, right].sum(axis=1).max() < 0.01
    assert W[v[:, 0] < -0.3][:, left].sum(axis=1).max() < 0.01
    for s in ("l_", "r_"):
        e, j = sk.index(s + "elbow"), sk.index(s + "wrist")
        u = sk.rest[j] - sk.rest[e]
        hand = ((v - sk.rest[j]) @ u > 0.0) & (np.sign(sk.rest[j][0]) * v[:, 0] > 0.4)
        assert hand.sum() > 1000
        # the hand follows the wrist-elbow chain (measured: 1 - 1e-16)
        assert W[hand][:, [e, j]].sum(axis=1).min() > 0.99
        assert W[hand, j].mean() > 0.9                      # measured 0.96 / 0.95


@pytest.mark.parametrize("side", ["l", "r"])
def test_candy_wrapper_lbs_collapses_dqs_keeps_volume(body, side):
    v, t, sk, idx, w = body
    r = candy_wrapper(v, t, sk, idx, w, angle_deg=90.0, side=side)
    # measured on mean_all.obj, wrist twisted 90 degrees, region from mid
    # forearm to the palm (0.5-1.4 forearm lengths; left 968 vertices,
    # 0.49 l, right 1021, 0.54 l):
    #   LBS volume 0.824 / 0.815 of rest, wrist section area 0.510 / 0.497
    #       (half-half blend at the joint: cos^2 45 = 0.5)
    #   DQS volume 1.0016 / 0.9968, wrist section 1.004 / 0.987 (its blend
    #       is rigid; what is left is the weights varying over the region)
    assert r["lbs_volume_ratio"] < 0.92
    assert r["lbs_wrist_area_ratio"] < 0.7
    assert abs(r["dqs_volume_ratio"] - 1.0) < 0.01
    assert abs(r["dqs_wrist_area_ratio"] - 1.0) < 0.03
    # the whole body: LBS loses 89 / 102 cm^3 (0.12 / 0.14 %), all of it in the
    # region; DQS changes it by 1e-5 / 3e-5 of its 73 l
    rest = r["rest_body_volume"]
    assert (rest - r["lbs_body_volume"]) > 0.5 * (r["rest_volume"] - r["lbs_volume"])
    assert abs(r["dqs_body_volume"] / rest - 1.0) < 1e-4


def test_bone_segments_of_the_body(body):
    v, t, sk, _, _ = body
    bones = bone_segments(v, t, sk)
    mesh = ClosedMesh(v, t)
    # every segment lies inside the body (checked at 9 points each)
    s = np.linspace(0.0, 1.0, 9)[:, None, None]
    pts = bones.heads[None] + s * (bones.tails - bones.heads)[None]
    assert mesh.inside(pts.reshape(-1, 3)).all()
    # leaves reach into their extremity: the head bone goes up, the hands
    # and feet bones are at least 5 cm long
    for name in ("head", "l_wrist", "r_wrist", "l_ankle", "r_ankle"):
        j = sk.index(name)
        assert np.linalg.norm(bones.tails[j] - bones.heads[j]) > 0.05, name
    assert bones.tails[sk.index("head")][1] > sk.rest[sk.index("head")][1] + 0.1
    # girdles: the pelvis and chest own segments to all their children
    assert sorted(bones.owner[len(sk.names):].tolist()) == [0, 0, 2, 2]


def test_sections_of_a_sphere():
    vs, ts = icosphere(4)
    S = sections(vs, ts, (0.0, 1.0, 0.0), 0.5)
    assert len(S) == 1
    # polygon inscribed in the circle of radius sqrt(0.75): area slightly below pi r^2
    assert 0.97 * np.pi * 0.75 < S.area[0] < np.pi * 0.75
    np.testing.assert_allclose(S.centroid[0], [0.0, 0.5, 0.0], atol=1e-3)
