"""ImageSpaceCollider (Vassilev et al. 2001 §4 maps behind the collider query interface):
contact agreement with a brute-force exact signed distance on the torso,
the analytic sphere, exactness on a tilted plane, the paper's inside test,
body velocity of a moving sphere, coverage, caching and the Eq. 15 wrapper."""
from __future__ import annotations

from pathlib import Path

import numpy as np
from meshes import icosphere, winding_number
import pytest

from distcloth.collision.colliders import MeshCollider, RigidMotion, load_mesh_collider
from distcloth.collision.image_collider import ImageSpaceCollider
from distcloth.collision.imagespace import lookup, pixel_index, velocity_response

ROOT = Path(__file__).resolve().parents[1]
TORSO = ROOT / "configs" / "meshes" / "torso.obj"
CONTACT = 0.005                      # contact distance d (m)


# ---------------------------------------------------------------- exact oracle

def closest_on_triangles(p, a, b, c):
    """Closest points (n, m, 3) of points p (n, 3) on every triangle (a, b, c)
    (m, 3 each): Ericson, Real-Time Collision Detection §5.1.5, with the
    Voronoi regions evaluated as masks (vertex regions override edge regions
    override the face interior)."""
    p = p[:, None, :]
    ab, ac = (b - a)[None], (c - a)[None]
    ap, bp, cp = p - a[None], p - b[None], p - c[None]

    def dot(u, v):
        return np.einsum("ijk,ijk->ij", *np.broadcast_arrays(u, v))

    d1, d2, d3 = dot(ab, ap), dot(ac, ap), dot(ab, bp)
    d4, d5, d6 = dot(ac, bp), dot(ab, cp), dot(ac, cp)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        den = va + vb + vc
        v, w = np.nan_to_num(vb / den), np.nan_to_num(vc / den)          # face interior
        regions = [((va <= 0) & (d4 >= d3) & (d5 >= d6), 1 - (d4 - d3) / ((d4 - d3) + (d5 - d6)),
                    (d4 - d3) / ((d4 - d3) + (d5 - d6))),                 # edge bc
                   ((vb <= 0) & (d2 >= 0) & (d6 <= 0), 0.0, d2 / (d2 - d6)),   # edge ac
                   ((vc <= 0) & (d1 >= 0) & (d3 <= 0), d1 / (d1 - d3), 0.0),   # edge ab
                   ((d6 >= 0) & (d5 <= d6), 0.0, 1.0),                    # vertex c
                   ((d3 >= 0) & (d4 <= d3), 1.0, 0.0),                    # vertex b
                   ((d1 <= 0) & (d2 <= 0), 0.0, 0.0)]                     # vertex a
        for mask, rv, rw in regions:
            v, w = np.where(mask, rv, v), np.where(mask, rw, w)
    return a[None] + v[..., None] * ab + w[..., None] * ac


def exact_signed_distance(pts, x, tri, chunk=32):
    """Brute force over all triangles: (signed distance, closest point,
    outward normal at it), sign by the winding number."""
    a, b, c = (x[tri[:, k]] for k in range(3))
    dist = np.empty(pts.shape[0])
    closest = np.empty_like(pts)
    for s in range(0, pts.shape[0], chunk):
        cp = closest_on_triangles(pts[s:s + chunk], a, b, c)
        d = np.linalg.norm(pts[s:s + chunk, None] - cp, axis=2)
        k = np.argmin(d, axis=1)
        rows = np.arange(k.shape[0])
        dist[s:s + chunk], closest[s:s + chunk] = d[rows, k], cp[rows, k]
    sign = np.where(winding_number(pts, x, tri) > 0.5, -1.0, 1.0)
    assert dist.min() > 1e-9                   # the normal below is (p - c*)/|p - c*|
    return sign * dist, closest, sign[:, None] * (pts - closest) / dist[:, None]


def face_normals(x, tri):
    n = np.cross(x[tri[:, 1]] - x[tri[:, 0]], x[tri[:, 2]] - x[tri[:, 0]])
    return n / np.linalg.norm(n, axis=1)[:, None]


def sample_points(isc, points, t=0.0):
    """The surface sample the collider compares a point with: its pixel
    centre at the depth of the nearer layer."""
    maps = isc.maps(t)
    i, j, _ = pixel_index(maps, points)
    uc, vc = maps.pixel_centres()
    w = points[:, isc.axis]
    front, back = maps.front_depth[i, j], maps.back_depth[i, j]
    with np.errstate(invalid="ignore"):
        depth = np.where(2.0 * w >= front + back, front, back)
    out = np.empty_like(points)
    out[:, (isc.axis + 1) % 3], out[:, (isc.axis + 2) % 3], out[:, isc.axis] = uc[i], vc[j], depth
    return out


# ---------------------------------------------------------------- torso vs exact geometry

@pytest.fixture(scope="module")
def torso_shell():
    """3000 cloth-like points in a shell from 1 cm inside to 2 cm outside the
    torso surface, with the exact signed distance, closest point and normal."""
    col = load_mesh_collider(TORSO)
    x, tri = col.vertices(0.0), col.triangles
    fn = face_normals(x, tri)
    area = 0.5 * np.linalg.norm(np.cross(x[tri[:, 1]] - x[tri[:, 0]], x[tri[:, 2]] - x[tri[:, 0]]),
                                axis=1)
    rng = np.random.default_rng(2024)
    n = 3000
    f = rng.choice(tri.shape[0], n, p=area / area.sum())
    r = rng.random((n, 2))
    r[r.sum(axis=1) > 1] = 1 - r[r.sum(axis=1) > 1]
    a, b, c = (x[tri[f, k]] for k in range(3))
    pts = a + r[:, :1] * (b - a) + r[:, 1:] * (c - a) + rng.uniform(-0.01, 0.02, (n, 1)) * fn[f]
    dist, closest, normal = exact_signed_distance(pts, x, tri)
    return col, pts, dist, closest, normal


def normal_spread(col, closest, normal, radius, chunk=500):
    """Largest angle between the normal at each closest point and the faces
    within ``radius`` of it (by bounding sphere: distance to the centroid
    minus the largest centroid-corner distance, <= the true distance, so a
    superset of those faces)."""
    x, tri = col.vertices(0.0), col.triangles
    fn = face_normals(x, tri)
    centroid = x[tri].mean(axis=1)
    size = np.linalg.norm(x[tri] - centroid[:, None], axis=2).max(axis=1)
    out = np.empty(closest.shape[0])
    for s in range(0, closest.shape[0], chunk):
        gap = np.linalg.norm(closest[s:s + chunk, None] - centroid[None], axis=2) - size[None]
        cos = np.where(gap <= radius[s:s + chunk, None], normal[s:s + chunk] @ fn.T, 1.0)
        out[s:s + chunk] = np.arccos(np.clip(cos.min(axis=1), -1.0, 1.0))
    return out


def contact_tolerance(isc, pts, dist, closest, normal, n_map):
    """Per point (resolved, tol): where the map resolves the surface, the
    estimated phi is within tol of the exact distance D.

    Let c* be the closest point (p = c* + D n*), c the surface sample of the
    point's pixel (the pixel centre at the layer's depth) and n_c the map
    normal there; the estimate is phi = (p - c) . n_c (module docstring), so

        phi - D = -D (1 - n* . n_c) + (c* - c) . n_c .

    * Lateral (Eq. 14 x–y bound with the slope): c lies over the pixel centre,
      at most h = half the pixel diagonal (Eq. 14 pitch) from p laterally,
      and c* lies |D| sin θ from p laterally (n* tilted by θ from the axis),
      so the lateral gap is <= h + |D| sin θ; over a surface patch tilted by
      at most θ (cos θ = the smaller |n . axis| of n* and n_c) the distance
      along the surface is L = (h + |D| sin θ) / cos θ.
    * Curvature: (c* - c) . n_c <= L sin Γ where Γ bounds the angle between
      n_c and the surface normals between c and c*: the angle γ between n_c
      and n* plus the largest angle between n* and the faces within 2L of c*
      (within 2L since the patch is tilted by less than 60 degrees).
    For Vassilev et al.'s rule (subpixel=False) the term delta . n_t is missing:
    add h sin θ.  Points over uncovered pixels and points where the surface
    is steeper than 60 degrees to the image plane (cos θ < 1/2) are not
    resolved by a depth map: no claim (counted below).
    """
    a = isc.axis
    h = 0.5 * np.hypot(*isc.error_bound)
    cos_t = np.minimum(np.abs(normal[:, a]), np.abs(n_map[:, a]))
    resolved = np.linalg.norm(n_map, axis=1) > 0
    resolved &= cos_t >= 0.5
    sin_t = np.sqrt(1.0 - cos_t ** 2)
    reach = (h + np.abs(dist) * sin_t) / np.maximum(cos_t, 0.5)
    cos_g = np.clip(np.einsum("ij,ij->i", normal, n_map), -1.0, 1.0)
    spread = normal_spread(isc.collider, closest, normal, 2.0 * reach)
    turn = np.minimum(np.arccos(cos_g) + spread, 0.5 * np.pi)
    tol = np.abs(dist) * (1.0 - cos_g) + reach * np.sin(turn) + 1e-12
    if not isc.subpixel:
        tol += h * sin_t
    # the lateral claim itself: the sample is within `reach` of c* (first order)
    c = sample_points(isc, pts)
    assert np.median(np.linalg.norm(c - closest, axis=1)[resolved] / reach[resolved]) < 1.0
    return resolved, tol


@pytest.mark.parametrize("subpixel", [True, False])
def test_torso_contacts_agree_with_exact_distance(torso_shell, subpixel):
    col, pts, dist, closest, normal = torso_shell
    exact_touch = dist < CONTACT
    assert 0.2 < exact_touch.mean() < 0.7
    disagree = {}
    for res in (32, 256):
        # axis 1: the torso's front/back view (every line along y crosses it once)
        isc = ImageSpaceCollider(col, res, axis=1, subpixel=subpixel)
        phi, n_map, _ = isc.query(pts, 0.0)
        resolved, tol = contact_tolerance(isc, pts, dist, closest, normal, n_map)
        wrong = (phi < CONTACT) != exact_touch
        # every disagreement the map resolves is a point within tol of the contact distance
        bad = wrong & resolved & (np.abs(dist - CONTACT) > tol)
        assert not bad.any(), (res, dist[bad], phi[bad], tol[bad])
        assert (np.abs(phi - dist)[resolved] <= tol[resolved]).all()
        disagree[res] = wrong.sum()
        if res == 256:
            assert resolved.mean() > 0.6                        # front/back of the torso
            assert (np.abs(dist - CONTACT) <= tol)[resolved].mean() < 0.2   # the test has bite
            assert (wrong & resolved).mean() < 0.01
            assert wrong.mean() < 0.05                          # incl. silhouettes
    # finer maps, fewer disagreements
    assert disagree[256] < 0.75 * disagree[32], disagree


# ---------------------------------------------------------------- analytic sphere

SPHERE_C = np.array([0.1, -0.05, 0.2])
SPHERE_R = 0.25


@pytest.fixture(scope="module")
def sphere():
    unit, tri = icosphere(4)
    x = SPHERE_C + SPHERE_R * unit
    fn = face_normals(x, tri)
    chord = SPHERE_R - np.einsum("ij,ij->i", fn, x[tri[:, 0]] - SPHERE_C).min()
    return x, tri, chord


def shell(n, width, seed):
    rng = np.random.default_rng(seed)
    dirs = rng.normal(size=(n, 3))
    dirs /= np.linalg.norm(dirs, axis=1)[:, None]
    dist = rng.uniform(-width, width, n)
    return SPHERE_C + (SPHERE_R + dist)[:, None] * dirs, dist, dirs


@pytest.mark.parametrize("axis", [0, 2])
def test_sphere_phi_within_bound(sphere, axis):
    """phi against the analytic sphere distance where the surface is within
    60 degrees of facing the view axis.  Bound (see the module docstring):
    with c the surface sample and n_c its map normal, phi - D =
    (p - c) . n_c - (|p - C| - R).  Writing c = C + (R - e) r_c (0 <= e <= the
    mesh's chord error) and n_c = r_c + eta (|eta| <= beta, the Gouraud normal's
    deviation from the radius, measured on the maps):
        |phi - D| <= chord + |p - C| (1 - cos alpha) + beta |p - c|,
    alpha the angle at C between p and c, <= L / R with L the Eq. 14 lateral
    reach (h + |D| sin θ) / cos θ (h = half the pixel diagonal), and
    |p - c| <= (|D| + h) / cos θ + chord."""
    x, tri, chord = sphere
    col = MeshCollider.static(x, tri)
    pts, dist, dirs = shell(4000, 0.02, seed=axis)
    for res in (64, 512):
        isc = ImageSpaceCollider(col, res, axis=axis)
        phi, n_map, _ = isc.query(pts)
        maps = isc.maps(0.0)
        uc, vc = maps.pixel_centres()
        beta = 0.0
        for depth, nrm in ((maps.front_depth, maps.front_normal),
                           (maps.back_depth, maps.back_normal)):
            y = np.empty(depth.shape + (3,))
            y[..., (axis + 1) % 3], y[..., (axis + 2) % 3] = np.meshgrid(uc, vc, indexing="ij")
            y[..., axis] = depth
            r = y[maps.covered] - SPHERE_C
            r /= np.linalg.norm(r, axis=1)[:, None]
            cos = np.einsum("ij,ij->i", r, nrm[maps.covered])
            beta = max(beta, np.arccos(np.clip(cos, -1, 1)).max())
        assert beta < 0.01
        h = 0.5 * np.hypot(*isc.error_bound)
        cos_t = np.minimum(np.abs(dirs[:, axis]), np.abs(n_map[:, axis]))
        ok = np.isfinite(phi) & (cos_t >= 0.5)
        assert ok.mean() > 0.4
        sin_t = np.sqrt(1 - cos_t ** 2)
        reach = (h + np.abs(dist) * sin_t) / np.maximum(cos_t, 0.5)
        bound = (chord + (SPHERE_R + np.abs(dist)) * (1 - np.cos(reach / SPHERE_R))
                 + beta * ((np.abs(dist) + h) / np.maximum(cos_t, 0.5) + chord))
        assert (np.abs(phi - dist)[ok] <= bound[ok]).all()
        # the normal is the outward radial direction within the sampled patch
        cos_n = np.einsum("ij,ij->i", n_map, dirs)
        assert (cos_n[ok] > np.cos(reach[ok] / SPHERE_R + beta) - 1e-12).all()
        # deep inside (not within the shell) a depth map still sees the body
        deep = isc.query(SPHERE_C[None] + 0.01)[0]
        assert deep[0] < -0.2


def test_tilted_plane_is_exact():
    """A flat-shaded tilted box: for points whose closest point is inside the
    top face, phi is the exact plane distance at any resolution (the
    sub-pixel tangent-plane estimate); Vassilev et al.'s rule errs by <= h sin θ."""
    corners = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], float)
    tri = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                    [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    rot = RigidMotion([0.0], rotations=[[0.4, -0.25, 0.0]]).transform(0.0)[0]
    x = (corners * [0.2, 0.15, 0.05]) @ rot.T
    centre_to_face = x[tri].mean(axis=1)
    assert (np.einsum("ij,ij->i", face_normals(x, tri), centre_to_face) > 0).all()   # outward
    col = MeshCollider.static(x, tri)
    top = rot[:, 2]
    rng = np.random.default_rng(5)
    n = 2000
    lateral = rng.uniform(-0.6, 0.6, (n, 2)) * [0.2, 0.15]
    dist = rng.uniform(-0.02, 0.02, n)
    pts = lateral[:, :1] * rot[:, 0] + lateral[:, 1:] * rot[:, 1] + (0.05 + dist)[:, None] * top
    for res in ((37, 23), (200, 150)):
        isc = ImageSpaceCollider(col, res, axis=2, smooth_normals=False)
        phi, normal, _ = isc.query(pts)
        np.testing.assert_allclose(phi, dist, rtol=0, atol=1e-13)
        np.testing.assert_allclose(normal, np.broadcast_to(top, normal.shape), atol=1e-13)
        pixel = ImageSpaceCollider(col, res, axis=2, smooth_normals=False, subpixel=False)
        err = np.abs(pixel.query(pts)[0] - dist)
        h = 0.5 * np.hypot(*isc.error_bound)
        assert err.max() <= h * np.sqrt(1 - top[2] ** 2) + 1e-13 and err.max() > 1e-3 * h


def test_pixel_rule_sign_is_the_eq12_inside_test(sphere):
    """subpixel=False: phi < 0 exactly where lookup (Vassilev et al. 2001 Eq. 12) says inside."""
    x, tri, _ = sphere
    isc = ImageSpaceCollider(MeshCollider.static(x, tri), (90, 70), axis=0, subpixel=False)
    pts, _, _ = shell(5000, 0.03, seed=9)
    phi, normal, _ = isc.query(pts)
    inside = lookup(isc.maps(0.0), pts).inside
    clear = np.abs(normal[:, 0]) > 1e-6
    np.testing.assert_array_equal((phi < 0)[clear], inside[clear])
    assert inside.sum() > 1000


# ---------------------------------------------------------------- moving body, caching

def test_translated_sphere_velocity_and_cache(sphere):
    x, tri, chord = sphere
    shift = np.array([0.3, -0.1, 0.2])
    motion = RigidMotion([0.0, 0.5, 1.5], [[0, 0, 0], 0.5 * shift, 1.5 * shift])
    isc = ImageSpaceCollider(MeshCollider.static(x, tri, motion=motion), 128, axis=2)
    static = ImageSpaceCollider(MeshCollider.static(x, tri), 128, axis=2)
    pts, dist, _ = shell(3000, 0.02, seed=4)
    base = static.query(pts)
    for t in (0.25, 1.0, 1.0, 2.0):
        phi, normal, velocity = isc.query(pts + t * shift if t < 1.5 else pts + 1.5 * shift, t)
        hit = np.isfinite(phi)
        assert hit.mean() > 0.5
        expected = shift if t < 1.5 else np.zeros(3)           # held after the last key
        np.testing.assert_allclose(velocity[hit], np.broadcast_to(expected, (hit.sum(), 3)),
                                   atol=1e-12)
        assert not velocity[~hit].any()
        # the maps moved with the body: the same answers as the static sphere
        np.testing.assert_array_equal(hit, np.isfinite(base[0]))
        np.testing.assert_allclose(phi[hit], base[0][hit], atol=1e-9)
        np.testing.assert_allclose(normal[hit], base[1][hit], atol=1e-9)
    assert isc.n_renders == 3                                   # t = 1.0 twice: cached
    static.query(pts, 7.0)
    assert static.n_renders == 1 and not base[2].any()          # static: rendered once
    static.resolution = 64
    static.query(pts)
    assert static.n_renders == 2 and static.resolution == (64, 64)


def test_uncovered_and_far_points_get_inf(sphere):
    x, tri, _ = sphere
    isc = ImageSpaceCollider(MeshCollider.static(x, tri), 100, axis=2, margin=0.02)
    (u0, u1), (v0, v1) = isc.bounds(0.0)
    assert u0 == pytest.approx(SPHERE_C[0] - SPHERE_R - 0.02, abs=1e-3)
    pts = np.array([[u1 + 0.01, SPHERE_C[1], SPHERE_C[2]],                  # off the map
                    [SPHERE_C[0], v0 - 1e-6, SPHERE_C[2]],                   # off the map
                    [u0 + 0.01, v0 + 0.01, SPHERE_C[2]],                     # map corner, no body
                    [SPHERE_C[0], SPHERE_C[1], SPHERE_C[2] + SPHERE_R + 0.1],   # above, covered
                    [SPHERE_C[0], SPHERE_C[1], SPHERE_C[2] + 0.1]])          # inside
    phi, normal, velocity = isc.query(pts)
    assert np.isposinf(phi[:3]).all() and not normal[:3].any() and not velocity[:3].any()
    assert phi[3] == pytest.approx(0.1, abs=1e-3) and phi[4] == pytest.approx(-0.15, abs=1e-3)
    phi, normal, _ = isc.query(pts, max_distance=0.05)
    assert np.isposinf(phi[:4]).all() and not normal[3].any()
    assert phi[4] == pytest.approx(-0.15, abs=1e-3)             # deep inside is kept
    assert np.isposinf(isc.signed_distance(pts)[0][:3]).all()
    np.testing.assert_allclose(isc.error_bound, (2 * (SPHERE_R + 0.02) / 100,) * 2, rtol=5e-3)
    with pytest.raises(ValueError):
        isc.query(pts, max_distance=-1.0)
    with pytest.raises(ValueError):
        ImageSpaceCollider(MeshCollider.static(x, tri), 0)


def test_eq15_with_the_maps_normal_and_body_velocity(sphere):
    x, tri, _ = sphere
    isc = ImageSpaceCollider(MeshCollider.static(x, tri), 64, axis=2)
    pts = SPHERE_C + np.array([[0.0, 0.0, SPHERE_R - 0.001], [0.05, 0.02, -0.24]])
    phi, normal, v_body = isc.query(pts)
    assert (phi < 0).all()
    v = np.array([[0.3, 0.0, -1.0], [0.0, 0.1, 2.0]])
    res = velocity_response(v, normal, v_body, 0.5, 0.0)
    np.testing.assert_allclose(np.einsum("ij,ij->i", res - v_body, normal), 0.0, atol=1e-14)
