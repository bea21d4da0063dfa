"""Bridson-style collision response (distcloth.collision.impulses).

EG07 tutorial, Part 1 §2.3 / Bridson et al. 2002: repulsion at x0 (§7.2,
friction §7.3), CCD impulses (§7.1) and rigid impact zones (§7.4) on one
index space of cloth vertices and kinematic (inv_mass 0) collider vertices.  Serial numpy tests: every MPI
rank runs them identically."""
from __future__ import annotations

import numpy as np
from meshes import grid_mesh
import pytest

from distcloth.collision import impulses as I
from distcloth.collision.ccd import edge_edge_ccd, vertex_face_ccd
from distcloth.collision.proximity import (edge_edge_contacts, mesh_edges, segment_segment,
                                           vertex_face_contacts)
from serial_oracles import count_self_intersections, serial_candidates


# ---------------------------------------------------------------- helpers

def panel(z=0.0, lo=-1.0, hi=1.0):
    """Two-triangle square in the plane z (normal +z)."""
    x = np.array([[lo, lo, z], [hi, lo, z], [hi, hi, z], [lo, hi, z]])
    return x, np.array([[0, 1, 2], [0, 2, 3]], np.int64)


def smooth_field(rng, nmodes=6, amp=1.0, k=6.0):
    """Random smooth velocity field: a few random 3D Fourier modes."""
    K = rng.normal(size=(nmodes, 3)) * k
    A = rng.normal(size=(nmodes, 3)) * amp
    ph = rng.uniform(0, 2 * np.pi, nmodes)
    return lambda x: np.sin(x @ K.T + ph) @ A


def curved_cloth(n=14):
    """15 x 15 vertices on the unit square, gently curved.  Not flat on
    purpose: a rigid impact zone keeps a flat region exactly flat, and the
    tri-tri oracle is ill-conditioned for (near-)coplanar triangles sharing
    a vertex (it reports touching for collinear opposite edges)."""
    x, tri = grid_mesh(n, n, 1.0 / n)
    x[:, 2] = 0.08 * np.sin(4 * x[:, 0]) * np.cos(3 * x[:, 1])
    return x, tri


def momentum(m, u):
    return (m[:, None] * u).sum(0)


def angular(m, x, u):
    return (m[:, None] * np.cross(x, u)).sum(0)


def n_hits(x0, x1, tri, edges, inv_mass, finder, eta):
    vf, ee = I.clean_pairs(*finder(x0, x1), tri, edges, inv_mass)
    r = vertex_face_ccd(x0, x1, tri, vf, eta)
    q = edge_edge_ccd(x0, x1, edges, ee, eta)
    return int(np.isfinite(r.t).sum() + np.isfinite(q.t).sum())


# ---------------------------------------------------------------- kinematic colliders

@pytest.mark.parametrize("xy", [(0.3, -0.2), (0.25, 0.25)])      # inside a face / on the diagonal
def test_fast_vertex_stops_at_static_panel(xy):
    P, ptri = panel()
    x0 = np.vstack([P, [[xy[0], xy[1], 0.5]]])
    inv = np.array([0, 0, 0, 0, 1.0])
    edges = mesh_edges(ptri)
    th, h = 0.01, 0.1
    u = np.zeros((5, 3))
    u[4] = (0.0, 0.0, -10.0)                     # 1.0 per step = 100 thicknesses, through the panel
    finder = serial_candidates(ptri, edges, th)
    un, st = I.resolve(x0, u, h, inv, ptri, edges, th, 0.0, finder)
    x1 = x0 + h * un
    assert st["remaining"] == 0 and st["ccd_hits"][0] >= 1
    assert np.array_equal(un[:4], u[:4])                          # panel untouched
    assert x1[4, 2] > 0 and abs(x1[4, 2] - th) < 0.05 * th        # its side, ~thickness away
    np.testing.assert_allclose(x1[4, :2], xy, atol=1e-12)         # no friction in CCD: no slide
    # the fail-safe alone: a zone with a static collider keeps the vertex at x0
    uz, zs = I.impact_zones(x0, u, h, inv, ptri, edges, th, finder)
    assert zs["remaining"] == 0 and zs["zones"] == 1
    assert np.array_equal(uz[4], np.zeros(3)) and np.array_equal(uz[:4], u[:4])


def test_edge_crossing_kinematic_edge_is_stopped():
    x0 = np.array([[-1.0, 0.0, 0.0], [1.0, 0.1, 0.05],            # kinematic edge
                   [0.1, -1.0, 0.3], [-0.1, 1.0, 0.5]])           # free edge above it
    inv = np.array([0.0, 0.0, 1.0, 2.0])
    edges = np.array([[0, 1], [2, 3]], np.int64)
    tri = np.zeros((0, 3), np.int64)
    u = np.array([[0.0, 0.0, 0.2], [0.0, 0.0, 0.2], [0.5, 0.0, -6.0], [0.0, 0.3, -9.0]])
    th, h = 0.01, 0.1
    finder = serial_candidates(tri, edges, th)
    pairs = np.array([[0, 1]])
    assert np.isfinite(edge_edge_ccd(x0, x0 + h * u, edges, pairs).t[0])   # crosses unresolved
    un, st = I.resolve(x0, u, h, inv, tri, edges, th, 0.0, finder)
    x1 = x0 + h * un
    assert st["remaining"] == 0
    assert np.array_equal(un[:2], u[:2])
    assert not np.isfinite(edge_edge_ccd(x0, x1, edges, pairs).t[0])
    d, s, t, *n = segment_segment(x1[0], x1[1], x1[2], x1[3])
    assert 0.9 * th < d < 1.5 * th and n[2] > 0                   # free edge stays above


# ---------------------------------------------------------------- free-free: conservation

def _two_triangles(rng):
    A = np.array([[0.0, 0.0, 0.2], [0.3, 0.05, 0.22], [0.1, 0.3, 0.18]])
    B = np.array([[0.05, 0.02, -0.2], [0.28, 0.1, -0.19], [0.12, 0.27, -0.23]])
    x0 = np.vstack([A, B])
    tri = np.array([[0, 1, 2], [3, 4, 5]], np.int64)
    u = np.vstack([np.tile([0.3, 0.1, -5.0], (3, 1)), np.tile([-0.2, 0.0, 5.0], (3, 1))])
    u += 0.3 * rng.standard_normal((6, 3))                        # some spin
    inv = rng.uniform(0.5, 2.0, 6)
    return x0, tri, mesh_edges(tri), u, inv


def test_head_on_triangles_conserve_momentum():
    rng = np.random.default_rng(3)
    x0, tri, edges, u, inv = _two_triangles(rng)
    m = 1.0 / inv
    th, h = 0.01, 0.1
    finder = serial_candidates(tri, edges, th)
    assert n_hits(x0, x0 + h * u, tri, edges, inv, finder, 1e-5) > 0     # they pass through
    p0, L0 = momentum(m, u), angular(m, x0, u)
    # impulses only (no fail-safe)
    ui, st = I.resolve(x0, u, h, inv, tri, edges, th, 0.0, finder, max_zone_iterations=0)
    assert st["ccd_hits"][0] > 0
    np.testing.assert_allclose(momentum(m, ui), p0, rtol=0, atol=1e-13 * np.abs(m[:, None] * u).sum())
    # the whole pipeline
    ur, st = I.resolve(x0, u, h, inv, tri, edges, th, 0.0, finder)
    assert st["remaining"] == 0 and n_hits(x0, x0 + h * ur, tri, edges, inv, finder, 1e-5) == 0
    np.testing.assert_allclose(momentum(m, ur), p0, rtol=0, atol=1e-13 * np.abs(m[:, None] * u).sum())
    # impact zones alone: one rigid zone conserving linear and angular momentum
    uz, zs = I.impact_zones(x0, u, h, inv, tri, edges, th, finder)
    assert zs["remaining"] == 0 and zs["zones"] == 1 and zs["zone_vertices"] == 6
    assert n_hits(x0, x0 + h * uz, tri, edges, inv, finder, 1e-5) == 0
    scale = np.abs(m[:, None] * u).sum()
    np.testing.assert_allclose(momentum(m, uz), p0, rtol=0, atol=1e-13 * scale)
    np.testing.assert_allclose(angular(m, x0, uz), L0, rtol=0, atol=1e-13 * scale)
    # and the zone moves rigidly (linearised): u = v + w x r
    r = x0 - (m[:, None] * x0).sum(0) / m.sum()
    G = np.einsum("ij,kj->ik", r[1:] - r[0], uz[1:] - uz[0])       # (r_i - r_0).(u_i - u_0) = 0
    np.testing.assert_allclose(np.diag(G), 0, atol=1e-12)


# ---------------------------------------------------------------- friction

@pytest.mark.parametrize("mu", [0.0, 0.3, 50.0])
def test_friction_bounded_by_normal_change(mu):
    P, ptri = panel()
    th, h = 0.01, 0.01
    x0 = np.vstack([P, [[0.3, -0.2, 0.5 * th]]])
    inv = np.array([0, 0, 0, 0, 1.0])
    edges = mesh_edges(ptri)
    u = np.zeros((5, 3))
    u[4] = (2.0, 1.0, -0.3)                      # sliding and approaching
    vf = vertex_face_contacts(x0, ptri, np.array([[4, 0], [4, 1]]), th)
    ee = edge_edge_contacts(x0, edges, np.zeros((0, 2), np.int64), th)
    assert vf.vertex.size == 1
    un = I.repulsion(x0, u, h, inv, ptri, edges, vf, ee, th, friction=mu)
    dvn = un[4, 2] - u[4, 2]
    dvt = np.linalg.norm(un[4, :2] - u[4, :2])
    np.testing.assert_allclose(un[4, 2], 0.5 * th / h, rtol=1e-12)   # reaches thickness by step end
    assert dvt <= mu * dvn + 1e-12
    if mu == 0.0:
        np.testing.assert_allclose(un[4, :2], u[4, :2], atol=1e-14)
    elif mu < 1:
        np.testing.assert_allclose(dvt, mu * dvn, rtol=1e-12)      # kinetic: the full bound
        assert np.cross(un[4, :2], u[4, :2]) == pytest.approx(0, abs=1e-12)   # opposes sliding
    else:
        np.testing.assert_allclose(un[4, :2], 0, atol=1e-12)       # static: stuck
    assert np.array_equal(un[:4], u[:4])


# ---------------------------------------------------------------- determinism

def _violent_field():
    """A curved cloth under a smooth random velocity field that folds it
    through itself within a step: (x0, tri, edges, inv_mass, u, th, h, finder)."""
    x0, tri = curved_cloth()
    edges = mesh_edges(tri)
    u = smooth_field(np.random.default_rng(0), amp=3.0)(x0)
    th = 0.01
    return x0, tri, edges, np.ones(len(x0)), u, th, 0.05, serial_candidates(tri, edges, th)


def test_order_independent_and_reproducible():
    x0, tri, edges, inv, u, th, h, base = _violent_field()
    rng = np.random.default_rng(7)

    def shuffled(x0_, x1_):
        vf, ee = base(x0_, x1_)
        vf = np.vstack([vf, vf[: len(vf) // 3]])                  # duplicates are fine too
        ee = np.vstack([ee, ee[: len(ee) // 3]])
        ee = np.where(rng.random((len(ee), 1)) < 0.5, ee[:, ::-1], ee)   # either orientation
        return vf[rng.permutation(len(vf))], ee[rng.permutation(len(ee))]

    ua, sa = I.resolve(x0, u, h, inv, tri, edges, th, 0.3, base)
    ub, sb = I.resolve(x0, u, h, inv, tri, edges, th, 0.3, base)
    uc, sc = I.resolve(x0, u, h, inv, tri, edges, th, 0.3, shuffled)
    assert sa["ccd_hits"][0] > 100
    assert np.array_equal(ua, ub) and np.array_equal(ua, uc)
    assert sa == sb == sc


def test_reused_candidates_change_nothing():
    # ReusedCandidates finds the pairs once with a bigger pad and reuses
    # them while the end positions move less than the slack: the pipeline's
    # result must be bitwise the one of a fresh detection every pass
    x0, tri, edges, inv, u, th, h, base = _violent_field()

    def detect(a, b, pad):
        return serial_candidates(tri, edges, pad)(a, b)

    ua, sa = I.resolve(x0, u, h, inv, tri, edges, th, 0.3, base)
    assert sa["ccd_hits"][0] > 100 and len(sa["ccd_hits"]) > 2
    # this field moves the end positions by more than th between passes, so
    # a slack of th/2 re-detects; 5 th lets the passes reuse their pairs
    for slack in (0.5 * th, 5 * th):
        reused = I.ReusedCandidates(detect, th, slack)
        ub, sb = I.resolve(x0, u, h, inv, tri, edges, th, 0.3, reused)
        assert np.array_equal(ua, ub) and sa == sb
    assert reused.detections < reused.calls      # it did reuse
    # impact zones alone, where reused pairs are only re-tested when a vertex
    # of theirs changed velocity: the same zones and velocities
    za, qa = I.impact_zones(x0, u, h, inv, tri, edges, th, base)
    zb, qb = I.impact_zones(x0, u, h, inv, tri, edges, th, I.ReusedCandidates(detect, th, 5 * th))
    assert qa["zone_iterations"] > 2 and qa["remaining"] == 0
    assert np.array_equal(za, zb)
    assert {k: v for k, v in qa.items() if k != "parent"} == \
        {k: v for k, v in qb.items() if k != "parent"}
    # a move beyond the slack is detected afresh
    n = reused.detections
    reused(x0, x0 + h * ub + 6 * th)
    assert reused.detections == n + 1


# ---------------------------------------------------------------- crumpling cloth

@pytest.mark.parametrize("collider", [False, True])
def test_crumpling_cloth_stays_intersection_free(collider):
    """A 15 x 15 cloth driven by a violent random smooth velocity field
    (h |grad u| ~ 1: without response it folds through itself within a few
    steps), optionally pressed onto a kinematic panel moving up.  With
    ``resolve`` every step the exact tri-tri oracle finds no intersection
    at the end of any step; without it, it does."""
    x, tri = curved_cloth()
    nc = len(x)
    th, h, steps = 0.01, 0.05, 5
    inv = np.ones(nc)
    if collider:
        P, ptri = panel(z=-0.12, lo=-1.0, hi=2.0)
        x = np.vstack([x, P])
        tri = np.vstack([tri, nc + ptri])
        inv = np.r_[inv, np.zeros(4)]
    edges = mesh_edges(tri)
    finder = serial_candidates(tri, edges, th)

    def drive(field, xs):
        u = np.zeros_like(xs)
        u[:nc] = field(xs[:nc])
        if collider:
            u[:nc, 2] -= 1.0
            u[nc:, 2] = 0.5
        return u

    zones = 0
    for do_resolve in (False, True):
        field = smooth_field(np.random.default_rng(1), amp=2.0)
        xs = x.copy()
        for _ in range(steps):
            u = drive(field, xs)
            if do_resolve:
                un, st = I.resolve(xs, u, h, inv, tri, edges, th, 0.3, finder)
                assert np.array_equal(un[nc:], u[nc:])             # kinematic rows untouched
                assert st["remaining"] == 0
                zones += st["zones"]
                u = un
            xs = xs + h * u
            if do_resolve:
                assert count_self_intersections(xs, tri) == 0
                if collider:
                    assert np.all(xs[:nc, 2] > xs[nc, 2])           # above the panel
        if not do_resolve:
            assert count_self_intersections(xs, tri) > 0
    assert zones > 0                                                # the fail-safe was exercised


def test_pair_weights_move_the_outer_layer_only():
    # a vertex-face pair (vertex 3 over face 0-1-2): with the face on layer 0
    # and the vertex on layer 1 only the vertex gets an impulse; on one layer
    # both; and an outer vertex that cannot move (pinned) leaves the true masses
    ids = np.array([[3, 0, 1, 2]])
    inv = np.array([1.0, 2.0, 3.0, 4.0])
    assert np.array_equal(I.pair_weights(inv, ids), [[4.0, 1.0, 2.0, 3.0]])
    layered = I.pair_weights(inv, ids, np.array([0.0, 0.0, 0.0, 1.0]))
    assert np.array_equal(layered, [[4.0, 0.0, 0.0, 0.0]])
    same = I.pair_weights(inv, ids, np.zeros(4))
    assert np.array_equal(same, [[4.0, 1.0, 2.0, 3.0]])
    pinned = I.pair_weights(np.array([1.0, 2.0, 3.0, 0.0]), ids, np.array([0.0, 0.0, 0.0, 1.0]))
    assert np.array_equal(pinned, [[0.0, 1.0, 2.0, 3.0]])


def test_repulsion_between_layers_lifts_the_outer_sheet_and_keeps_the_inner():
    # two parallel triangles 1 mm apart, thickness 3 mm: with layers the
    # repulsion moves the upper (outer) one away by the whole 2 mm overlap
    # over the step and leaves the lower one exactly still; without, both move
    x0 = np.array([[-1.0, -1.0, 0.0], [3.0, -1.0, 0.0], [-1.0, 3.0, 0.0],
                   [0.2, 0.2, 0.001], [1.2, 0.2, 0.001], [0.2, 1.2, 0.001]])
    tri = np.array([[0, 1, 2], [3, 4, 5]])
    edges = mesh_edges(tri)
    inv = np.ones(6)
    h, d = 0.01, 0.003
    vf = np.array([[3, 0], [4, 0], [5, 0], [0, 1], [1, 1], [2, 1]])
    pvf = vertex_face_contacts(x0, tri, vf, d)
    pee = edge_edge_contacts(x0, edges, np.zeros((0, 2), np.int64), d)
    u = np.zeros((6, 3))
    layers = np.array([0.0, 0, 0, 1, 1, 1])
    lifted = I.repulsion(x0, u, h, inv, tri, edges, pvf, pee, d, iterations=16, priority=layers)
    assert np.array_equal(lifted[:3], u[:3])
    gap = x0[3:, 2] + h * lifted[3:, 2]
    # Jacobi passes reach the target from below to within 1 % of the overlap
    assert np.all(gap > d - 0.01 * (d - 0.001)) and np.all(gap < d + 1e-9)
    both = I.repulsion(x0, u, h, inv, tri, edges, pvf, pee, d, iterations=16)
    assert (both[:3, 2] < 0).all() and (both[3:, 2] > 0).all()
