"""A body driven by motion capture as a collider: placement, skin velocities,
the rest pose while it settles, volume under dual-quaternion skinning, bad
animation settings, and a cloth on the moving shoulder (docs/bodies.md)."""
from __future__ import annotations

import h5py
import numpy as np
import pytest
import yaml

from conftest import ROOT, run_cli
from distcloth.body.animated import AnimatedBody
from distcloth.body.bvh import read_bvh
from distcloth.body.clip import Timeline
from distcloth.body.skinning import mesh_volume
from distcloth.collision.colliders import SkinnedMeshCollider, load_collider_mesh, placement_map
from distcloth.collision.mesh_query import MeshProximity
from distcloth.config.load import config_from_dict
from distcloth.config.schema import CMU_UNIT
from distcloth.parallel.comm import Comm
from distcloth.run import run
from distcloth.scene.meshio import read_mesh

BODY = ROOT / "configs" / "meshes" / "mean_all.obj"
WALK = ROOT / "configs" / "motion" / "cmu_07_01_walk.bvh"
TIMELINE = Timeline(settle=0.2, blend_in=0.3, ease_in=0.2, start=1 / 120)


@pytest.fixture(scope="module")
def walking():
    x, tri = read_mesh(str(BODY))
    return AnimatedBody(x, tri, read_bvh(str(WALK), scale=CMU_UNIT), TIMELINE, "dqs", "keep")


class _Spec:
    """The placement keys of a colliders: entry."""
    def __init__(self, path, **kw):
        self.files, self.frame_rate, self.friction, self.thickness = (str(path),), None, 0.0, 0.0
        self.up_axis, self.scale = kw.get("up_axis", "y"), kw.get("scale", 1.0)
        self.rotation = kw.get("rotation", (0.0, 0.0, 0.0))
        self.translation = kw.get("translation")
        self.geometry = tuple(kw.get("geometry", {}).items())


@pytest.mark.parametrize("kw", [
    {}, {"rotation": (0.0, 0.0, 30.0), "translation": (0.1, -0.2, 0.3)},
    {"up_axis": "z", "scale": 2.0, "rotation": (10.0, 20.0, 0.0), "geometry": {"center": (1.0, 2.0, 3.0)}},
])
def test_placement_map_is_the_collider_placement(tmp_path, kw):
    # a skinned body is placed by one affine map: it must put the rest mesh
    # where load_collider_mesh puts the file (round-off of metre coordinates)
    x, tri = read_mesh(str(BODY))
    spec = _Spec(BODY, **kw)
    placed = load_collider_mesh(spec).frames[0]
    A, b = placement_map(spec, x)
    assert np.abs(x @ A.T + b - placed).max() < 1e-12


class _Sliding:
    """A stand-in body: its rest mesh translated at a constant velocity."""
    def __init__(self, x, tri, v):
        self.rest, self.triangles, self.v, self.end_time = x, tri, np.asarray(v), 1.0

    def positions(self, t):
        return self.rest + t * self.v

    def velocities(self, t):
        return np.broadcast_to(self.v, self.rest.shape)


def test_skinned_collider_places_positions_and_velocities():
    x = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    tri = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    A = np.array([[0.0, -2.0, 0.0], [2.0, 0.0, 0.0], [0.0, 0.0, 2.0]])     # turn 90° about z, scale 2
    b = np.array([1.0, 2.0, 3.0])
    c = SkinnedMeshCollider(_Sliding(x, tri, [0.5, 0.0, 0.0]), A, b)
    assert c.is_deforming and c.drive_end == 1.0
    # y = A (x + t v) + b, v_world = A v (exact in binary floating point here)
    assert np.array_equal(c.vertices(0.5), (x + [0.25, 0.0, 0.0]) @ A.T + b)
    assert np.array_equal(c.velocities(0.5), np.broadcast_to([0.0, 1.0, 0.0], x.shape))


def test_body_rests_while_it_settles_then_walks(walking):
    # identity transforms while settling: the rest mesh bit for bit, no velocity
    assert np.array_equal(walking.positions(0.1), walking.rest)
    assert not walking.velocities(0.1).any()
    x = walking.positions_at([0.2 + 0.3 + 1.0])[0]
    # a second into the walk the body has moved away from its rest pose by
    # more than a stride's part (root motion kept): at least 0.5 m somewhere
    assert np.linalg.norm(x - walking.rest, axis=1).max() > 0.5


@pytest.mark.parametrize("t", [0.35, 0.9, 1.7])
def test_skin_velocity_is_the_derivative_of_the_skin(walking, t):
    # central differences over 2e-4 s against a difference over 2e-3 s: the
    # pose is smooth within a capture frame (8.3 ms) but not across frames
    # (slerp is C0 there), so compare away from frame boundaries' kinks:
    # agreement to 2 % of the fastest vertex's speed
    v = walking.velocities(t)
    a, b = walking.positions_at([t - 1e-3, t + 1e-3])
    fd = (b - a) / 2e-3
    scale = np.linalg.norm(fd, axis=1).max()
    assert scale > 0.1
    assert np.linalg.norm(v - fd, axis=1).max() < 0.02 * scale


def test_dual_quaternion_skinning_keeps_the_volume_on_the_walk(walking):
    # DQS is a blend of rigid motions: the body's volume over the walk stays
    # within 1.5 % of rest (measured: under 1 %; the girdles and the spine
    # bend, where no skinning is volume-exact)
    v0 = mesh_volume(walking.rest, walking.triangles)
    for t in (0.6, 1.2, 1.8, 2.4):
        x = walking.positions_at([t])[0]
        assert abs(mesh_volume(x, walking.triangles) / v0 - 1.0) < 0.015


def test_walking_skin_stretches_smoothly(walking):
    # the skin is not cloth, but a garment resting on it with friction takes
    # its stretch: no edge of the walking body more than doubles (measured
    # at most 1.7 times with the weights' continuous truncation; plain top-4
    # truncation gave neighbours at the sides of the waist an upper arm's and
    # a thigh's 10 % and stretched edges between them 3.7 times)
    e = np.concatenate([walking.triangles[:, [0, 1]], walking.triangles[:, [1, 2]],
                        walking.triangles[:, [2, 0]]])
    rest = np.linalg.norm(np.diff(walking.rest[e], axis=1)[:, 0], axis=1)
    for x in walking.positions_at(np.arange(0.5, walking.end_time, 0.05)):
        assert (np.linalg.norm(np.diff(x[e], axis=1)[:, 0], axis=1) / rest).max() < 2.0


def _shoulder_raw(out, extra=None, end=0.2):
    """A small cloth dropped on the left shoulder of the walking body."""
    return {
        "scene": "cloth_on_walking_shoulder",
        "cloth": [{"name": "cloth",
                   "mesh": {"grid": {"size": [0.24, 0.24], "resolution": [9, 9]},
                            "center": [0.18, 0.0, 1.49]},
                   "material": {"preset": "cotton"}, "thickness": 0.003}],
        "effects": ["gravity", "membrane", "bending", "damping", "collisions"],
        "colliders": [{"name": "body", "shape": "mesh", "file": str(BODY), "up_axis": "y",
                       "friction": 0.3,
                       "animation": {"motion": str(WALK), "settle": 0.0, "blend_in": 0.1,
                                     "ease_in": 0.0, "clip_start": 0.0084,
                                     **(extra or {})}}],
        "time": {"end": end, "step": 0.005, "integrator": "backward_euler"},
        "output": {"file": str(out), "every": 0.05, "preview": False},
    }


def _shoulder_scene(tmp_path, extra=None):
    return config_from_dict(_shoulder_raw(tmp_path / "out.h5", extra), str(tmp_path), "scene.yaml")


@pytest.mark.parametrize("reach", [None, 0.1])
def test_cloth_rides_the_walking_shoulder(shared_tmp, comm, reach):
    # a small cloth dropped on the left shoulder while the body blends into
    # the walk: the run completes, no cloth vertex ends inside the moving
    # body deeper than 10 % of the contact offset (the garment bound of
    # docs/garments.md); with a reach only the shoulder's parts are in the
    # contact (an open cut of the body that keeps signed distances)
    cfg = _shoulder_scene(shared_tmp, None if reach is None else {"reach": reach})
    assert run(cfg, Comm(comm), quiet=True, progress=False) == 0
    with h5py.File(shared_tmp / "out.h5", "r") as f:
        assert f.attrs["status"] == "completed"
        k = int(f.attrs["frames_written"])
        x, t = f["frames/positions"][k - 1], float(f["frames/time"][k - 1])
    from distcloth.collision.contact import make_collider
    body = make_collider(cfg.colliders[0], True).body
    phi, _, _ = MeshProximity(body).query(x, t, 0.1)
    assert phi.min() > -0.1 * 0.003, phi.min()
    # the cloth moved with the shoulder (blend-in swings the arms down)
    assert np.isfinite(x).all()


@pytest.mark.rank0_only
@pytest.mark.parametrize("setting, key", [
    ("colliders.0.animation.motion=BAD", "colliders.0.animation.motion"),
    ("colliders.0.animation.clip_start=100", "colliders.0.animation"),
    ("colliders.0.animation.skinning=quaternion", "colliders.0.animation.skinning"),
    ("colliders.0.animation.joints.pelvis=Hipz", "colliders.0.animation.joints"),
    ("colliders.0.animation.joints.tail=Hips", "colliders.0.animation.joints.tail"),
    ("colliders.0.method=image", "colliders.0.animation.reach"),
])
def test_bad_animation_exits_2_before_work(tmp_path, setting, key):
    bad = tmp_path / "bad.bvh"
    bad.write_text("HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0 0\n  CHANNELS 3 Xposition Yposition\n")
    setting = setting.replace("BAD", str(bad))
    out = tmp_path / "walk.h5"
    p = run_cli(["run", ROOT / "configs" / "skirt_walking.yaml", "--output", out,
                 "--set", setting], ranks=2, timeout=300)
    assert p.returncode == 2, (p.returncode, p.stderr)
    lines = [ln for ln in p.stderr.splitlines() if ln.startswith("distcloth: config error")]
    assert len(lines) == 1 and key in lines[0], p.stderr
    assert "Traceback" not in p.stderr and not out.exists()


def test_a_skirt_reaches_the_hips_and_legs_not_the_arms_or_head(walking):
    # a band of points around the hips (a skirt's top) with a 10 cm reach:
    # the pelvis and the hips are in reach, the forearms, hands and head are not
    from distcloth.body.regions import reachable_bones, region_triangles, submesh
    sk = walking.skeleton
    pelvis = sk.rest[sk.index("pelvis")]
    angle = np.linspace(0.0, 2 * np.pi, 60, endpoint=False)
    band = pelvis + np.stack([0.19 * np.cos(angle), np.zeros_like(angle), 0.15 * np.sin(angle)], 1)
    bones = reachable_bones(walking.rest, walking.idx, walking.w, band, 0.1)
    names = {sk.names[b] for b in bones}
    assert {"pelvis", "l_hip", "r_hip"} <= names
    assert not names & {"l_elbow", "l_wrist", "r_elbow", "r_wrist", "head", "neck"}
    keep = region_triangles(walking.triangles, walking.idx, walking.w, bones)
    ids, tri = submesh(walking.triangles, keep)
    # the part is a proper subset, re-indexed onto its own vertices
    assert 0 < keep.sum() < keep.size and tri.max() == ids.size - 1
    assert np.array_equal(ids[tri], walking.triangles[keep])
    # no vertex of a hand is in the part
    hand = walking.rest[:, 0] > 0.5
    assert not np.isin(np.flatnonzero(hand), ids).any()


def test_a_body_part_keeps_signed_distances_near_the_garment(walking):
    # the part cut out of the closed body answers like the whole body where
    # the garment is (inside negative, the same distance), though it is open
    from distcloth.body.regions import reachable_bones, region_triangles, submesh
    from distcloth.collision.colliders import MeshCollider
    sk = walking.skeleton
    pelvis = sk.rest[sk.index("pelvis")]
    rng = np.random.default_rng(3)
    pts = pelvis + rng.uniform(-0.25, 0.25, (400, 3)) * [1.0, 0.4, 1.0]
    bones = reachable_bones(walking.rest, walking.idx, walking.w, pts, 0.1)
    ids, tri = submesh(walking.triangles, region_triangles(walking.triangles, walking.idx,
                                                           walking.w, bones))
    whole = MeshProximity(MeshCollider.static(walking.rest, walking.triangles))
    cut = MeshCollider.static(walking.rest[ids], tri)
    cut.cut_of_closed = True
    part = MeshProximity(cut)
    assert whole.closed and part.closed
    a, _, _ = whole.query(pts, 0.0, 0.05)
    b, _, _ = part.query(pts, 0.0, 0.05)
    near = np.isfinite(a)
    assert near.sum() > 50 and (a[near] < 0).any()
    assert np.array_equal(np.isfinite(b), near)
    # same closest distance and sign (round-off of the same triangles)
    assert np.abs(a[near] - b[near]).max() < 1e-12


@pytest.mark.rank0_only
def test_walking_shoulder_agrees_on_one_two_and_three_ranks(tmp_path):
    # the cloth on the moving shoulder (0.1 s: contact, friction, the
    # triangle pipeline against the skinned body, with the reach cut) on 1, 2
    # and 3 ranks with CG converged to 1e-12: the same frames to 1e-7 m (the
    # garments' bound without a body in docs/garments.md; contact decisions
    # did not flip here)
    scene = _shoulder_raw("out.h5", {"reach": 0.1}, end=0.1)
    path = tmp_path / "shoulder.yaml"
    path.write_text(yaml.safe_dump(scene))
    frames = {}
    for n in (1, 2, 3):
        out = tmp_path / f"r{n}.h5"
        p = run_cli(["run", path, "--output", out, "--quiet", "--set", "solver.ksp_rtol=1e-12",
                     "--set", "solver.ksp_norm_type=unpreconditioned"], ranks=n, timeout=300)
        assert p.returncode == 0, p.stderr
        with h5py.File(out, "r") as f:
            frames[n] = f["frames/positions"][:int(f.attrs["frames_written"])]
    for n in (2, 3):
        assert frames[n].shape == frames[1].shape
        assert np.abs(frames[n] - frames[1]).max() < 1e-7


def test_reach_changes_nothing_where_the_cut_parts_stay_away(shared_tmp, comm):
    # the cloth on the walking shoulder with the whole body in its contact and
    # with only the parts in reach (EG07 tutorial Part 2 §2.3): where the
    # parts left out never come near the cloth, the restricted contact finds
    # the same closest points and triangle pairs.  Not bitwise: the part is a
    # mesh of its own (its vertices and faces numbered anew, its own tree), so
    # sums and pair orders differ in round-off, and CG, stopping at its
    # relative tolerance, carries such a perturbation up to the tolerance's
    # size.  So the two agree within the solver's tolerance: measured
    # 7.4e-7 m at ksp_rtol 1e-5 and 7e-13 m at 1e-10 over 0.2 s; asserted at
    # 1e-10 (bound 1e-9 m: a difference that does not shrink with the
    # tolerance would be a different contact, of the order of mm)
    frames = []
    for name, extra in (("whole", None), ("reach", {"reach": 0.1})):
        raw = _shoulder_raw(shared_tmp / f"{name}.h5", extra)
        raw["solver"] = {"ksp_rtol": 1e-10}
        cfg = config_from_dict(raw, str(shared_tmp), "scene.yaml")
        assert run(cfg, Comm(comm), quiet=True, progress=False) == 0
        with h5py.File(shared_tmp / f"{name}.h5", "r") as f:
            frames.append(f["frames/positions"][:])
            contacts = f["diagnostics/contacts"][:]
    assert frames[0].shape == frames[1].shape and frames[0].shape[0] == 5
    assert np.nanmax(contacts) >= 3                       # the cloth lands on the shoulder
    assert np.abs(frames[0] - frames[1]).max() < 1e-9
