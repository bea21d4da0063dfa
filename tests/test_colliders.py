"""Collider geometry: analytic signed distances, keyframed rigid motion, mesh
colliders and their loader, and the shipped torso body mesh."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from distcloth.collision.colliders import (AnalyticCollider, Box, Capsule, MeshCollider, Plane,
                                           RigidMotion, Sphere, load_collider_mesh,
                                           load_mesh_collider, rotvec_to_matrix)
from distcloth.collision.contact import rigid_motion as rigid_motion_of
from distcloth.scene.meshio import read_mesh, write_obj

ROOT = Path(__file__).resolve().parents[1]


def fd_gradient(fun, points, eps=1e-6):
    """Central-difference gradient of a scalar field evaluated on many points."""
    grad = np.zeros_like(points)
    for k in range(3):
        step = np.zeros(3)
        step[k] = eps
        grad[:, k] = (fun(points + step) - fun(points - step)) / (2 * eps)
    return grad


def box_surface_samples(center, half, n):
    """Dense grid on the six faces of a box."""
    out = []
    s = np.linspace(-1.0, 1.0, n)
    a, b = np.meshgrid(s, s, indexing="ij")
    a, b = a.ravel(), b.ravel()
    for axis in range(3):
        u, v = (axis + 1) % 3, (axis + 2) % 3
        for sign in (-1.0, 1.0):
            p = np.zeros((a.size, 3))
            p[:, axis] = sign * half[axis]
            p[:, u] = a * half[u]
            p[:, v] = b * half[v]
            out.append(p + center)
    return np.concatenate(out)


def min_distance(points, samples):
    d2 = ((points[:, None, :] - samples[None, :, :]) ** 2).sum(axis=2)
    return np.sqrt(d2.min(axis=1))


# ---------------------------------------------------------------- analytic shapes

def test_plane_signed_distance_and_unnormalised_normal():
    plane = Plane(normal=(0.0, 0.0, 2.0), offset=1.0)          # z = 0.5
    y = np.array([[0.3, -2.0, 0.5], [0.0, 0.0, 0.0], [1.0, 1.0, 2.0]])
    phi, n = plane.signed_distance(y)
    np.testing.assert_allclose(phi, [0.0, -0.5, 1.5], atol=1e-15)
    np.testing.assert_allclose(n, np.tile([0.0, 0.0, 1.0], (3, 1)))
    tilted = Plane(normal=(1.0, 1.0, 0.0), offset=0.0)
    phi, n = tilted.signed_distance(np.array([[1.0, 1.0, 5.0]]))
    np.testing.assert_allclose(phi, [np.sqrt(2.0)])
    np.testing.assert_allclose(n[0], [2 ** -0.5, 2 ** -0.5, 0.0])


def test_sphere_signed_distance_exact():
    rng = np.random.default_rng(1)
    c, r = np.array([0.2, -0.1, 0.4]), 0.3
    y = c + rng.uniform(-0.8, 0.8, size=(500, 3))
    phi, n = Sphere(c, r).signed_distance(y)
    np.testing.assert_allclose(phi, np.linalg.norm(y - c, axis=1) - r, atol=1e-15)
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-14)
    np.testing.assert_allclose(y - phi[:, None] * n, c + r * n, atol=1e-14)   # closest point
    phi0, n0 = Sphere(c, r).signed_distance(c[None])                          # centre: any unit normal
    assert phi0[0] == pytest.approx(-r) and np.linalg.norm(n0[0]) == pytest.approx(1.0)


def test_capsule_signed_distance_brute_force():
    rng = np.random.default_rng(2)
    a, b, r = np.array([-0.2, 0.1, 0.0]), np.array([0.3, -0.1, 0.25]), 0.12
    y = rng.uniform(-0.6, 0.6, size=(400, 3))
    segment = a + np.linspace(0.0, 1.0, 20001)[:, None] * (b - a)
    step = np.linalg.norm(b - a) / 20000
    brute = min_distance(y, segment) - r
    phi, n = Capsule(a, b, r).signed_distance(y)
    assert (phi <= brute + 1e-14).all() and (brute - phi < step).all()
    assert ((phi < 0) == (brute < 0)).sum() >= y.shape[0] - 1
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-14)


@pytest.mark.parametrize("inside", [False, True])
def test_box_signed_distance_brute_force(inside):
    rng = np.random.default_rng(3 + inside)
    c, h = np.array([0.1, 0.0, -0.2]), np.array([0.3, 0.2, 0.1])
    box = Box(c, h)
    if inside:
        y = c + rng.uniform(-1, 1, size=(300, 3)) * h
    else:
        y = c + rng.uniform(-3, 3, size=(600, 3)) * h
        y = y[(np.abs(y - c) > h).any(axis=1)]
    n_grid = 121
    samples = box_surface_samples(c, h, n_grid)
    spacing = 2 * h.max() / (n_grid - 1)
    brute = min_distance(y, samples)
    phi, n = box.signed_distance(y)
    assert ((phi < 0) == inside).all()
    # sampled surface: true distance <= sampled <= true + half-diagonal of a grid cell
    assert (np.abs(phi) <= brute + 1e-14).all()
    assert (brute - np.abs(phi) <= spacing / np.sqrt(2) + 1e-14).all()
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-14)
    # closest surface point y - phi n lies on the box surface
    foot = y - phi[:, None] * n
    q = np.abs(foot - c) - h
    np.testing.assert_allclose(q.max(axis=1), 0.0, atol=1e-14)


def _off_medial(shape, y):
    """Mask of points clear of the shape's medial set (where the gradient of
    phi jumps), so a finite-difference gradient is meaningful."""
    if isinstance(shape, Sphere):
        return np.linalg.norm(y - shape.center, axis=1) > 1e-2
    if isinstance(shape, Capsule):
        ab = shape.b - shape.a
        s = np.clip((y - shape.a) @ ab / (ab @ ab), 0, 1)
        return np.linalg.norm(y - shape.a - s[:, None] * ab, axis=1) > 1e-2
    q = np.sort(np.abs(y - shape.center) - shape.half_extents, axis=1)
    inside = q[:, 2] < 0
    # inside: unique nearest face; outside: not on a face/edge boundary plane
    clear_inside = q[:, 2] - q[:, 1] > 1e-3
    clear_outside = (np.abs(np.abs(y - shape.center) - shape.half_extents) > 1e-3).all(axis=1)
    return np.where(inside, clear_inside, clear_outside)


@pytest.mark.parametrize("shape", [
    Sphere((0.1, 0.2, -0.1), 0.25),
    Capsule((0.0, 0.0, -0.2), (0.1, 0.05, 0.3), 0.15),
    Box((0.0, 0.1, 0.0), (0.25, 0.15, 0.35)),
    Plane((0.3, -0.2, 1.0), 0.1),
])
def test_normal_is_gradient_of_phi(shape):
    rng = np.random.default_rng(5)
    y = rng.uniform(-0.6, 0.6, size=(400, 3))
    if not isinstance(shape, Plane):
        y = y[_off_medial(shape, y)]
    phi, n = shape.signed_distance(y)
    grad = fd_gradient(lambda p: shape.signed_distance(p)[0], y)
    np.testing.assert_allclose(n, grad, atol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-14)


# ---------------------------------------------------------------- rigid motion

def keyed_motion():
    times = [0.0, 0.5, 1.2, 2.0]
    translations = [[0, 0, 0], [0.1, -0.2, 0.3], [0.4, 0.0, 0.1], [0.4, 0.1, -0.2]]
    rotations = [[0, 0, 0], [0.0, 0.0, 1.0], [0.5, -0.3, 2.0], [1.0, 1.0, -1.0]]
    return RigidMotion(times, translations, rotations), times, translations, rotations


def test_rotvec_to_matrix_rodrigues():
    rv = np.array([0.3, -1.1, 0.7])
    theta = np.linalg.norm(rv)
    k = rv / theta
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    expected = np.eye(3) + np.sin(theta) * K + (1 - np.cos(theta)) * K @ K
    np.testing.assert_allclose(rotvec_to_matrix(rv), expected, atol=1e-14)
    np.testing.assert_allclose(rotvec_to_matrix([0, 0, 0]), np.eye(3))


def test_motion_exact_at_keys_and_held_outside():
    motion, times, translations, rotations = keyed_motion()
    for t, p, rv in zip(times, translations, rotations):
        R, q = motion.transform(t)
        np.testing.assert_allclose(R, rotvec_to_matrix(rv), atol=1e-13)
        np.testing.assert_allclose(q, p, atol=1e-15)
    R_before, p_before = motion.transform(-1.0)
    np.testing.assert_allclose(R_before, np.eye(3), atol=1e-15)
    R_after, p_after = motion.transform(5.0)
    np.testing.assert_allclose(R_after, rotvec_to_matrix(rotations[-1]), atol=1e-13)
    np.testing.assert_allclose(p_after, translations[-1])
    for t in (-1.0, 2.0, 5.0):
        v, w = motion.velocity(t)
        assert not v.any() and not w.any()


def test_motion_identity_and_slerp_midpoint():
    R, p = RigidMotion().transform(3.0)
    np.testing.assert_array_equal(R, np.eye(3))
    assert not p.any()
    assert not RigidMotion().point_velocity(np.ones((2, 3)), 1.0).any()
    spin = RigidMotion([0.0, 1.0], [[0, 0, 0], [1.0, 2.0, 0.0]], [[0, 0, 0], [0, 0, 2.0]])
    R, p = spin.transform(0.25)
    np.testing.assert_allclose(R, rotvec_to_matrix([0, 0, 0.5]), atol=1e-14)
    np.testing.assert_allclose(p, [0.25, 0.5, 0.0])
    v, w = spin.velocity(0.25)
    np.testing.assert_allclose(v, [1.0, 2.0, 0.0])
    np.testing.assert_allclose(w, [0.0, 0.0, 2.0], atol=1e-14)


def test_motion_rotation_orthonormal_and_point_velocity_is_derivative():
    motion, *_ = keyed_motion()
    rng = np.random.default_rng(7)
    x_body = rng.normal(size=(20, 3))
    h = 1e-6
    for t in np.linspace(0.01, 1.99, 23):
        R, _ = motion.transform(t)
        np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-13)
        assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-13)
        y = motion.to_world(x_body, t)
        fd = (motion.to_world(x_body, t + h) - motion.to_world(x_body, t - h)) / (2 * h)
        np.testing.assert_allclose(motion.point_velocity(y, t), fd, atol=1e-7)
        np.testing.assert_allclose(motion.to_body(y, t), x_body, atol=1e-13)


def test_analytic_collider_moving_box():
    motion, *_ = keyed_motion()
    box = Box((0.05, 0.0, 0.0), (0.2, 0.1, 0.3))
    col = AnalyticCollider(box, motion, friction=0.3, thickness=0.002)
    rng = np.random.default_rng(8)
    t = 0.8
    y_body = rng.uniform(-0.5, 0.5, size=(300, 3))
    y_body = y_body[_off_medial(box, y_body)]
    y = motion.to_world(y_body, t)
    phi, n, vel = col.query(y, t)
    phi_body, n_body = box.signed_distance(y_body)
    np.testing.assert_allclose(phi, phi_body, atol=1e-13)
    grad = fd_gradient(lambda p: col.signed_distance(p, t)[0], y)
    np.testing.assert_allclose(n, grad, atol=1e-6)
    # velocity of the closest surface point = d/dt of its moving body position
    foot_body = y_body - phi_body[:, None] * n_body
    h = 1e-6
    fd = (motion.to_world(foot_body, t + h) - motion.to_world(foot_body, t - h)) / (2 * h)
    np.testing.assert_allclose(vel, fd, atol=1e-7)


@pytest.mark.parametrize("when", [-0.5, 2.0, 3.5])
def test_a_body_at_rest_answers_as_the_general_transform_does(when):
    """A static body skips the transform and a held one the velocity: the
    same answers as the general path (world = body frame; zero velocity)."""
    rng = np.random.default_rng(9)
    y = rng.uniform(-1.0, 1.0, size=(400, 3))
    y[0] = [0.1, -0.2, 0.3]                        # a sphere's centre: the fallback normal
    sphere = Sphere((0.1, -0.2, 0.3), 0.4)
    phi, n, vel = AnalyticCollider(sphere).query(y, 1.0)
    phi_body, n_body = sphere.signed_distance(y)
    np.testing.assert_array_equal(phi, phi_body)
    np.testing.assert_array_equal(n, n_body)
    assert np.array_equal(n[0], [0.0, 0.0, 1.0]) and not vel.any()
    motion, *_ = keyed_motion()
    assert not motion.moving(when) and motion.moving(0.8)
    col = AnalyticCollider(sphere, motion)
    phi, n, vel = col.query(y, when)
    R, p = motion.transform(when)
    phi_body, n_body = sphere.signed_distance((y - p) @ R)
    np.testing.assert_allclose(phi, phi_body, atol=1e-14)
    np.testing.assert_allclose(n, n_body @ R.T, atol=1e-14)
    assert not vel.any()
    np.testing.assert_array_equal(motion.point_velocity(y, when), 0.0)


# ---------------------------------------------------------------- mesh colliders

def small_mesh():
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float)
    tri = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    return v, tri


def test_mesh_sequence_interpolation_and_velocities():
    v, tri = small_mesh()
    rng = np.random.default_rng(9)
    frames = [v, v + rng.normal(size=v.shape) * 0.1, v + rng.normal(size=v.shape) * 0.1]
    times = [0.0, 0.1, 0.3]
    col = MeshCollider.sequence(frames, tri, times)
    assert col.is_deforming and col.n_vertices == 4
    np.testing.assert_array_equal(col.triangles, tri)
    for k, t in enumerate(times):
        np.testing.assert_allclose(col.vertices(t), frames[k], atol=1e-15)
    np.testing.assert_allclose(col.vertices(0.2), 0.5 * (frames[1] + frames[2]), atol=1e-15)
    np.testing.assert_allclose(col.velocities(0.2), (frames[2] - frames[1]) / 0.2, atol=1e-12)
    np.testing.assert_allclose(col.velocities(0.0), (frames[1] - frames[0]) / 0.1, atol=1e-12)
    h = 1e-7
    fd = (col.vertices(0.05 + h) - col.vertices(0.05 - h)) / (2 * h)
    np.testing.assert_allclose(col.velocities(0.05), fd, atol=1e-6)
    np.testing.assert_allclose(col.vertices(-1.0), frames[0])
    np.testing.assert_allclose(col.vertices(9.0), frames[2])
    assert not col.velocities(-1.0).any() and not col.velocities(9.0).any()


def test_static_mesh_with_motion_and_deforming_with_motion():
    v, tri = small_mesh()
    motion, *_ = keyed_motion()
    static = MeshCollider.static(v, tri, motion=motion)
    assert not static.is_deforming
    t, h = 0.7, 1e-6
    np.testing.assert_allclose(static.vertices(t), motion.to_world(v, t))
    fd = (static.vertices(t + h) - static.vertices(t - h)) / (2 * h)
    np.testing.assert_allclose(static.velocities(t), fd, atol=1e-7)
    seq = MeshCollider.sequence([v, 1.5 * v], tri, [0.0, 1.0], motion=motion)
    fd = (seq.vertices(t + h) - seq.vertices(t - h)) / (2 * h)
    np.testing.assert_allclose(seq.velocities(t), fd, atol=1e-7)
    plain = MeshCollider.static(v, tri)
    np.testing.assert_array_equal(plain.vertices(3.0), v)
    assert not plain.velocities(3.0).any()


def test_mesh_collider_rejects_bad_input():
    v, tri = small_mesh()
    with pytest.raises(ValueError, match="strictly increasing"):
        MeshCollider.sequence([v, v], tri, [0.0, 0.0])
    with pytest.raises(ValueError, match="frame times"):
        MeshCollider.sequence([v, v], tri, [0.0, 1.0, 2.0])
    with pytest.raises(ValueError, match="does not exist"):
        MeshCollider.static(v, tri + 1)


def test_load_mesh_collider(tmp_path):
    v, tri = small_mesh()
    paths = []
    for k in range(3):
        paths.append(tmp_path / f"frame{k}.obj")
        write_obj(str(paths[-1]), v * (1 + 0.1 * k), tri)
    static = load_mesh_collider(paths[0], friction=0.2, thickness=0.001)
    assert not static.is_deforming and static.friction == 0.2 and static.thickness == 0.001
    np.testing.assert_allclose(static.vertices(1.0), v)
    seq = load_mesh_collider(paths, frame_rate=10.0)
    np.testing.assert_allclose(seq.frame_times, [0.0, 0.1, 0.2])
    np.testing.assert_allclose(seq.velocities(0.15), 0.1 * v / 0.1, atol=1e-12)
    with pytest.raises(ValueError, match="frame_times or a positive frame_rate"):
        load_mesh_collider(paths)
    # a frame with another vertex count
    bad = tmp_path / "bad_count.obj"
    write_obj(str(bad), np.vstack([v, [[2.0, 2.0, 2.0]]]), tri)
    with pytest.raises(ValueError, match=r"frame 1 .*bad_count.obj.* 5 vertices"):
        load_mesh_collider([paths[0], bad], frame_times=[0.0, 1.0])
    # same count, other triangles
    flipped = tmp_path / "flipped.obj"
    write_obj(str(flipped), v, tri[:, ::-1])
    with pytest.raises(ValueError, match=r"frame 2 .*flipped.obj.*different triangles"):
        load_mesh_collider([paths[0], paths[1], flipped], frame_times=[0.0, 1.0, 2.0])


def collider_spec(tmp_path, paths, **keys):
    """The checked ``colliders:`` entry of a mesh collider (through the scene schema)."""
    from distcloth.config.load import config_from_dict
    raw = {"cloth": [{"mesh": {"grid": {"size": [1, 1], "resolution": [2, 2]}}}],
           "effects": ["gravity", "collisions"],
           "colliders": [{"name": "body", "shape": "mesh",
                          "file": [str(p) for p in paths] if len(paths) > 1 else str(paths[0]),
                          **keys}]}
    return config_from_dict(raw, str(tmp_path), "scene.yaml").colliders[0]


def y_up_body():
    """A lopsided y-up 'body': a box 0.4 wide (x), 1.7 tall (y), 0.3 deep (z),
    its feet at y = 0, with a nose vertex sticking out along +z at head height."""
    lo, hi = np.array([-0.2, 0.0, -0.15]), np.array([0.2, 1.7, 0.15])
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                        for z in (lo[2], hi[2])])
    nose = np.array([[0.0, 1.6, 0.25]])
    v = np.vstack([corners, nose])
    tri = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                    [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 8], [5, 7, 8],
                    [7, 3, 8], [3, 1, 8]])
    return v, tri


def test_y_up_mesh_is_turned_and_centred(tmp_path):
    v, tri = y_up_body()
    path = tmp_path / "body.obj"
    write_obj(str(path), v, tri)
    spec = collider_spec(tmp_path, [path], up_axis="y", center=[1.0, 2.0, 0.85])
    x = load_collider_mesh(spec).vertices(0.0)
    lo, hi = x.min(axis=0), x.max(axis=0)
    np.testing.assert_allclose(0.5 * (lo + hi), [1.0, 2.0, 0.85], atol=1e-12)
    # the file's +y (height) is now +z, its +z (the nose's side) is -y, x unchanged
    np.testing.assert_allclose(hi - lo, [0.4, 0.4, 1.7], atol=1e-12)
    assert lo[2] == pytest.approx(0.0, abs=1e-12)       # feet on the floor
    nose = x[8]      # file offset from corner 0: (0.2, 1.6, 0.4), turned to (x, -z, y)
    np.testing.assert_allclose(nose - x[0], [0.2, -0.4, 1.6], atol=1e-12)
    assert nose[1] == pytest.approx(lo[1]) and nose[2] == pytest.approx(lo[2] + 1.6)


def test_mesh_placement_order_sequence_and_motion(tmp_path):
    v, tri = y_up_body()
    shift = np.array([0.0, 0.0, 0.1])                   # frame 1: the file body moved along its z
    paths = [tmp_path / "f0.obj", tmp_path / "f1.obj"]
    write_obj(str(paths[0]), v, tri)
    write_obj(str(paths[1]), v + shift, tri)
    keys = dict(up_axis="y", scale=2.0, rotation=[0.0, 0.0, 90.0], translation=[0.5, 0.0, 0.0],
                frame_rate=10.0, motion={"times": [0.0, 1.0], "translations": [[0, 0, 0],
                                                                               [0, 0, 1]]})
    spec = collider_spec(tmp_path, paths, **keys)
    mesh = load_collider_mesh(spec, rigid_motion_of(spec))
    # by hand: turn (x, y, z) -> (x, -z, y), scale, rotate 90 degrees about z around
    # frame 0's bounding-box centre, translate
    turned = 2.0 * np.stack([v[:, 0], -v[:, 2], v[:, 1]], axis=1)
    pivot = 0.5 * (turned.min(axis=0) + turned.max(axis=0))
    rz = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    expected = (turned - pivot) @ rz.T + pivot + [0.5, 0.0, 0.0]
    np.testing.assert_allclose(mesh.frames[0], expected, atol=1e-12)
    # the same transform for frame 1: its file shift along z turned to -y, doubled, turned to +x
    np.testing.assert_allclose(mesh.frames[1] - mesh.frames[0],
                               np.tile([0.2, 0.0, 0.0], (v.shape[0], 1)), atol=1e-12)
    # the rigid motion moves the placed mesh
    np.testing.assert_allclose(mesh.vertices(2.0), mesh.frames[1] + [0.0, 0.0, 1.0], atol=1e-12)


def test_mesh_without_placement_is_read_bit_for_bit(tmp_path):
    v, tri = y_up_body()
    path = tmp_path / "body.obj"
    write_obj(str(path), v * np.pi, tri)
    read, _ = read_mesh(str(path))
    assert np.array_equal(load_collider_mesh(collider_spec(tmp_path, [path])).frames[0], read)


# ---------------------------------------------------------------- shipped body mesh

def test_torso_mesh_is_closed_and_outward():
    v, tri = read_mesh(str(ROOT / "configs" / "meshes" / "torso.obj"))
    assert 2000 <= tri.shape[0] <= 5000
    # watertight and consistently oriented: each directed edge once, its reverse once
    edges = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    keys = edges[:, 0] * v.shape[0] + edges[:, 1]
    assert np.unique(keys).shape[0] == keys.shape[0]
    assert np.isin(edges[:, 1] * v.shape[0] + edges[:, 0], keys).all()
    assert np.unique(tri).shape[0] == v.shape[0]                  # no stray vertices
    assert v.shape[0] - keys.shape[0] // 2 + tri.shape[0] == 2    # Euler: a sphere
    a, b, c = (v[tri[:, i]] for i in range(3))
    assert (np.linalg.norm(np.cross(b - a, c - a), axis=1) > 1e-10).all()
    volume = np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0
    assert 0.02 < volume < 0.06                                    # m^3, positive: outward
    lo, hi = v.min(axis=0), v.max(axis=0)
    assert hi[2] - lo[2] == pytest.approx(0.70, abs=1e-9) and lo[2] == pytest.approx(0.0, abs=1e-12)
    np.testing.assert_allclose(0.5 * (lo[:2] + hi[:2]), 0.0, atol=1e-3)
