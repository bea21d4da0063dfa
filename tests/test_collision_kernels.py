"""Collision kernels (distcloth.collision): BVH, stack traversal, proximity,
CCD, triangle-triangle intersection.  Serial numpy tests: every MPI rank
runs them identically."""
from __future__ import annotations

import numpy as np
from meshes import grid_mesh
import pytest
from scipy.optimize import minimize

from distcloth.collision import bvh as B
from distcloth.collision import ccd as C
from distcloth.collision import proximity as P
from distcloth.collision import traverse as T
from distcloth.collision import tritri as TT
from serial_oracles import count_self_intersections, refit_boxes


# ---------------------------------------------------------------- helpers

def crumpled_grid(rng, nx=16, ny=16):
    x, tri = grid_mesh(nx, ny, h=1.0 / nx)
    x[:, 2] = 0.15 * np.sin(7 * x[:, 0]) * np.cos(5 * x[:, 1]) + 0.03 * rng.standard_normal(len(x))
    return x, tri


def soup(rng, m, size=0.15):
    c = rng.random((m, 1, 3))
    x = (c + size * rng.standard_normal((m, 3, 3))).reshape(-1, 3)
    return x, np.arange(3 * m, dtype=np.int64).reshape(m, 3)


def brute_overlaps(lo1, hi1, lo2, hi2, self_=False):
    ov = np.all((lo1[:, None] <= hi2[None]) & (lo2[None] <= hi1[:, None]), axis=2)
    if self_:
        ov = np.triu(ov, 1)
    i, j = np.nonzero(ov)
    return np.stack([i, j], axis=1)


def check_invariants(b: B.BVH, prims=None, x=None, x_end=None, pad=0.0):
    n, m = b.n_nodes, b.n_prims
    if m == 0:
        assert n == 0
        return
    assert np.array_equal(np.sort(b.order), np.arange(m))
    leaf = b.left < 0
    assert np.all(b.count[leaf] <= b.leaf_size) and np.all(b.count[leaf] >= 1)
    # leaves partition the primitives
    cover = np.zeros(m, int)
    for i in np.flatnonzero(leaf):
        cover[b.order[b.first[i]:b.first[i] + b.count[i]]] += 1
    assert np.all(cover == 1)
    inner = np.flatnonzero(~leaf)
    for side in (b.left, b.right):
        ch = side[inner]
        assert np.all(ch > inner) and np.array_equal(b.parent[ch], inner)
        assert np.all(b.lo[ch] >= b.lo[inner]) and np.all(b.hi[ch] <= b.hi[inner])
    assert b.parent[0] == -1 and np.all(b.parent[1:] < np.arange(1, n))
    # internal ranges are the union of the children's
    assert np.array_equal(b.first[inner], b.first[b.left[inner]])
    assert np.array_equal(b.count[inner], b.count[b.left[inner]] + b.count[b.right[inner]])
    for i in np.flatnonzero(leaf):
        ids = b.order[b.first[i]:b.first[i] + b.count[i]]
        assert np.all(b.plo[ids] >= b.lo[i]) and np.all(b.phi[ids] <= b.hi[i])
    if prims is not None:
        plo, phi = B.primitive_boxes(prims, x, x_end, pad)
        assert np.array_equal(plo, b.plo) and np.array_equal(phi, b.phi)
        pts = x[prims].reshape(m, -1, 3)
        assert np.all(pts.min(1) - pad >= b.plo - 1e-15) and np.all(pts.max(1) + pad <= b.phi + 1e-15)


# ---------------------------------------------------------------- BVH

@pytest.mark.parametrize("k", [1, 2, 3])
@pytest.mark.parametrize("leaf_size", [1, 4])
def test_bvh_invariants_build_and_refit(k, leaf_size):
    rng = np.random.default_rng(10 * k + leaf_size)
    x = rng.random((120, 3))
    prims = rng.integers(0, 120, (97, k))
    b = B.build_bvh(prims, x, pad=0.01, leaf_size=leaf_size)
    check_invariants(b, prims, x, pad=0.01)
    # same input, same tree (every rank gets the same numbering)
    b2 = B.build_bvh(prims, x, pad=0.01, leaf_size=leaf_size)
    assert all(np.array_equal(getattr(b, f), getattr(b2, f)) for f in B.BVH.__slots__[:-1])
    for step in range(3):
        x_end = x + 0.2 * rng.standard_normal(x.shape)
        B.refit(b, prims, x, x_end, pad=0.02)
        check_invariants(b, prims, x, x_end, pad=0.02)
        x = x_end


def test_bvh_empty_single_and_ties():
    x = np.zeros((3, 3))
    e = B.build_bvh(np.zeros((0, 3), np.int64), x)
    assert e.n_nodes == 0 and e.n_prims == 0
    assert len(T.self_pairs(e)) == 0
    one = B.build_bvh(np.array([[0, 1, 2]]), np.eye(3))
    check_invariants(one)
    assert one.n_nodes == 1 and np.allclose(one.lo[0], 0) and np.allclose(one.hi[0], 1)
    # all centroids equal: median split by primitive id still terminates
    same = B.build_bvh(np.zeros((50, 1), np.int64), x, leaf_size=2)
    check_invariants(same)
    assert len(T.self_pairs(same)) == 50 * 49 // 2


# ---------------------------------------------------------------- traversal

def _self_case(rng, kind):
    if kind == "soup":
        x, tri = soup(rng, 300)
    else:
        x, tri = crumpled_grid(rng)
    return x, tri


@pytest.mark.parametrize("kind", ["soup", "grid"])
def test_self_traversal_matches_brute_force(kind):
    rng = np.random.default_rng(1)
    x, tri = _self_case(rng, kind)
    b = B.build_bvh(tri, x, pad=0.005)
    got = T.self_pairs(b)
    ref = brute_overlaps(b.plo, b.phi, b.plo, b.phi, self_=True)
    assert len(ref) > 0 and np.array_equal(got, ref)
    # the raw traversal output has no duplicates
    raw = T.run_tests((b,), [[0, 0, 0, 0]])
    assert len(raw) == len(ref)


@pytest.mark.parametrize("kind", ["soup", "grid"])
def test_two_tree_traversal_matches_brute_force(kind):
    """Triangles of one tree against the vertices (points) of another and
    edges against edges: mixed primitive types in one Forest."""
    rng = np.random.default_rng(2)
    x, tri = _self_case(rng, kind)
    pts = np.arange(len(x))[:, None]
    edges = P.mesh_edges(tri)
    bt = B.build_bvh(tri, x, pad=0.01)
    bp = B.build_bvh(pts, x, pad=0.01, leaf_size=3)
    be = B.build_bvh(edges, x + 0.01, pad=0.01)
    got = T.cross_pairs(bt, bp)
    assert np.array_equal(got, brute_overlaps(bt.plo, bt.phi, bp.plo, bp.phi))
    # three objects, default root tests: 3 self tests + 3 cross tests
    rows = T.all_pairs((bt, bp, be))
    for o1 in range(3):
        for o2 in range(o1, 3):
            a, b = (bt, bp, be)[o1], (bt, bp, be)[o2]
            sel = rows[(rows[:, 0] == o1) & (rows[:, 2] == o2)][:, [1, 3]]
            ref = brute_overlaps(a.plo, a.phi, b.plo, b.phi, self_=o1 == o2)
            assert np.array_equal(sel, ref), (o1, o2)


def test_stack_split_from_bottom_is_lossless():
    """EG07 tutorial, Part 1 §5.8.1: tests taken from the bottom of the stack and
    run elsewhere, the union equals the uninterrupted traversal exactly."""
    rng = np.random.default_rng(3)
    x, tri = crumpled_grid(rng)
    bt = B.build_bvh(tri, x, pad=0.01)
    bp = B.build_bvh(np.arange(len(x))[:, None], x, pad=0.01)
    forest = T.Forest((bt, bp))
    roots = np.array([[0, 0, 0, 0], [0, 0, 1, 0]])
    full = T.run_tests(forest, roots)
    assert len(full) == len(T.canonical(full))            # no duplicates at all
    for trial in range(5):
        state = T.TraversalState(roots, stack_cap=8, out_cap=16)   # forces buffer growth
        tasks = []
        while state.top > 0:
            state.run(forest, int(rng.integers(1, 60)))
            if state.top > 1 and rng.random() < 0.5:
                tasks.append(state.take_bottom(int(rng.integers(1, state.top))))
        parts = [state.pairs()]
        for task in tasks:                                  # each task independently
            sub = T.TraversalState(task)
            while sub.top > 0:
                # a task may itself be split again
                sub.run(forest, 25)
                if sub.top > 2:
                    parts.append(T.run_tests(forest, sub.take_bottom(sub.top // 2)))
            parts.append(sub.pairs())
        union = np.concatenate(parts)
        assert len(union) == len(full)                      # nothing lost, nothing twice
        assert np.array_equal(T.canonical(union), T.canonical(full))


def test_take_bottom_rows():
    stack = np.arange(40, dtype=np.int64).reshape(10, 4)
    stack, top, rows = T.take_bottom(stack, 7, 3)
    assert top == 4
    assert np.array_equal(rows, np.arange(12).reshape(3, 4))
    assert np.array_equal(stack[:4], np.arange(12, 28).reshape(4, 4))


def test_combined_top_tree_equals_single_bvh():
    """EG07 tutorial, Part 1 §5.8.2: per-rank sub-BVHs, a top tree over their
    root boxes; grafted, or used to seed sub-tree root tests, the
    candidates equal those of one BVH over the whole mesh."""
    rng = np.random.default_rng(4)
    x, tri = crumpled_grid(rng)
    # four "ranks" by x-slab of the triangle centroids, plus an empty one
    owner = np.minimum((x[tri].mean(1)[:, 0] * 4).astype(int), 3)
    chunks = [tri[owner == r] for r in (0, 1, 2)] + [tri[:0]] + [tri[owner == 3]]
    subs = [B.build_bvh(c, x, pad=0.01) for c in chunks]
    roots = np.array([s.root_box() for s in subs])            # (r, 2, 3): the all-gather
    top = B.combine_roots(roots[:, 0], roots[:, 1])
    assert sorted(top.order) == [0, 1, 2, 4]
    glued, node_off, prim_off = B.graft(top, subs)
    check_invariants(glued)
    whole = np.concatenate(chunks)
    one = B.build_bvh(whole, x, pad=0.01)
    ref = T.self_pairs(one)
    assert np.array_equal(T.self_pairs(glued), ref)
    for s, sub in enumerate(subs):                            # contiguous sub-tree blocks
        blk = slice(node_off[s], node_off[s + 1])
        assert np.array_equal(glued.lo[blk], sub.lo)
    # refit of the glued tree = the glued refit sub-trees
    x2 = x + 0.05 * rng.standard_normal(x.shape)
    B.refit(glued, whole, x2, pad=0.01)
    check_invariants(glued, whole, x2, pad=0.01)
    assert np.array_equal(T.self_pairs(glued), T.self_pairs(B.build_bvh(whole, x2, pad=0.01)))
    # task form: self traversal of the top tree gives the sub-tree pairs to test
    subs = [B.refit(s, c, x2, pad=0.01) for s, c in zip(subs, chunks)]
    roots = np.array([s.root_box() for s in subs])
    refit_boxes(top, roots[:, 0], roots[:, 1])
    sub_pairs = T.all_pairs((top,), [[0, 0, 0, 0]])[:, [1, 3]]
    live = np.unique(top.order)
    tests = [[s, 0, s, 0] for s in live] + [[i, 0, j, 0] for i, j in sub_pairs]
    rows = T.all_pairs(tuple(subs), tests)
    glob = np.stack([prim_off[rows[:, 0]] + rows[:, 1], prim_off[rows[:, 2]] + rows[:, 3]], 1)
    glob = np.unique(np.sort(glob, axis=1), axis=0)
    assert np.array_equal(glob, T.self_pairs(B.build_bvh(whole, x2, pad=0.01)))


# ---------------------------------------------------------------- proximity

def test_point_triangle_against_optimiser():
    rng = np.random.default_rng(5)
    cons = ({"type": "eq", "fun": lambda w: w.sum() - 1.0},)
    for case in range(150):
        a, b, c = rng.standard_normal((3, 3))
        if case % 10 == 0:                              # thin sliver
            c = a + (b - a) * 0.5 + 1e-4 * rng.standard_normal(3)
        p = rng.standard_normal(3) * 1.5
        d, w0, w1, w2, *n = P.point_triangle(p, a, b, c)
        w = np.array([w0, w1, w2])
        q = w @ np.array([a, b, c])
        assert np.all(w >= -1e-12) and abs(w.sum() - 1) < 1e-12
        assert abs(np.linalg.norm(p - q) - d) < 1e-12
        assert np.allclose(q + d * np.array(n), p, atol=1e-12)
        X = np.array([a, b, c])
        res = minimize(lambda w: np.sum((w @ X - p) ** 2), np.full(3, 1 / 3), jac=lambda w: 2 * X @ (w @ X - p),
                       bounds=[(0, 1)] * 3, constraints=cons, method="SLSQP", options={"ftol": 1e-14})
        dref = np.sqrt(res.fun)
        assert d <= dref + 1e-9 and d >= dref - 1e-6
    # dense barycentric sampling on a few cases: never beaten
    s = np.linspace(0, 1, 81)
    u, v = np.meshgrid(s, s)
    keep = u + v <= 1
    W = np.stack([1 - u[keep] - v[keep], u[keep], v[keep]], 1)
    for _ in range(10):
        X = rng.standard_normal((3, 3))
        p = rng.standard_normal(3)
        d = P.point_triangle(p, *X)[0]
        dmin = np.linalg.norm(W @ X - p, axis=1).min()
        assert d <= dmin + 1e-12 and d >= dmin - np.abs(X).max() * 0.05


def test_point_triangle_degenerate_and_on_face():
    a, b, c = np.zeros(3), np.array([1.0, 0, 0]), np.array([2.0, 0, 0])     # collinear
    d, *w, _, _, _ = P.point_triangle(np.array([1.5, 1.0, 0]), a, b, c)
    assert abs(d - 1.0) < 1e-14 and abs(np.dot(w, [0, 1, 2]) - 1.5) < 1e-14
    d, *rest = P.point_triangle(np.array([0.25, 0.25, 0]), np.zeros(3), np.eye(3)[0], np.eye(3)[1])
    assert d == 0 and np.allclose(rest[3:], [0, 0, 1])       # face normal on the face


def test_segment_segment_against_optimiser():
    rng = np.random.default_rng(6)
    for case in range(200):
        a0, a1, b0, b1 = rng.standard_normal((4, 3))
        if case % 4 == 1:                                   # parallel
            b1 = b0 + rng.uniform(-2, 2) * (a1 - a0)
        elif case % 4 == 2:                                 # collinear, overlapping or not
            b0 = a0 + rng.uniform(-1, 2) * (a1 - a0)
            b1 = a0 + rng.uniform(-1, 2) * (a1 - a0)
        elif case % 20 == 3:                                # point-like segment
            b1 = b0.copy()
        d, s, t, *n = P.segment_segment(a0, a1, b0, b1)
        pa, pb = a0 + s * (a1 - a0), b0 + t * (b1 - b0)
        assert 0 <= s <= 1 and 0 <= t <= 1
        assert abs(np.linalg.norm(pb - pa) - d) < 1e-12
        assert abs(np.linalg.norm(n) - 1) < 1e-12
        assert np.allclose(pa + d * np.array(n), pb, atol=1e-12)
        f = lambda st: np.sum((b0 + st[1] * (b1 - b0) - a0 - st[0] * (a1 - a0)) ** 2)
        best = min(minimize(f, x0, bounds=[(0, 1)] * 2, method="L-BFGS-B",
                            options={"ftol": 1e-15, "gtol": 1e-12}).fun
                   for x0 in ([0.5, 0.5], [0.1, 0.9], [0.9, 0.1]))
        dref = np.sqrt(max(best, 0.0))
        assert d <= dref + 1e-9 and d >= dref - 1e-6, case


def test_contact_filters_sorted_and_skip_shared():
    rng = np.random.default_rng(7)
    x, tri = grid_mesh(6, 6, h=0.1)
    x2 = x.copy()
    x2[:, 2] = 0.004                                       # a second sheet 4 mm above
    xx = np.concatenate([x, x2])
    tt = np.concatenate([tri, tri + len(x)])
    verts = np.arange(len(xx))
    pairs = np.stack(np.meshgrid(verts, np.arange(len(tt)), indexing="ij"), -1).reshape(-1, 2)
    pairs = pairs[rng.permutation(len(pairs))]
    c = P.vertex_face_contacts(xx, tt, pairs, thickness=0.005)
    assert np.all(c.distance < 0.005)
    assert not np.any(tt[c.face] == c.vertex[:, None])     # shared vertices skipped
    key = c.vertex * len(tt) + c.face
    assert np.all(np.diff(key) > 0)                         # canonical order
    # every vertex of the upper sheet is 4 mm above some lower triangle
    up = c.vertex >= len(x)
    assert set(c.vertex[up]) == set(range(len(x), len(xx)))
    assert np.allclose(c.distance[up & (c.face < len(tri))], 0.004)
    assert np.allclose(c.normal[up & (c.face < len(tri))], [0, 0, 1])
    c2 = P.vertex_face_contacts(xx, tt, pairs[::-1], thickness=0.005)
    assert all(np.array_equal(u, v) for u, v in zip(c, c2))
    e = P.mesh_edges(tt)
    ep = np.stack(np.triu_indices(len(e), 1), 1)
    ee = P.edge_edge_contacts(xx, e, ep[rng.permutation(len(ep))][:, ::-1], thickness=0.005)
    assert np.all(ee.edge_a < ee.edge_b) and np.all(np.diff(ee.edge_a * len(e) + ee.edge_b) > 0)
    shared = (e[ee.edge_a][:, :, None] == e[ee.edge_b][:, None, :]).any((1, 2))
    assert not shared.any() and np.all(ee.distance < 0.005)


# ---------------------------------------------------------------- CCD

def _random_crossing(rng, t_star, h, speed):
    """Triangle and vertex trajectories that meet at t_star, w_star; the
    vertex moves `speed` thicknesses along the normal relative to the
    triangle over the step."""
    tri_star = rng.standard_normal((3, 3))
    w_star = rng.dirichlet([2, 2, 2])
    p_star = w_star @ tri_star
    n = np.cross(tri_star[1] - tri_star[0], tri_star[2] - tri_star[0])
    n /= np.linalg.norm(n)
    v_tri = 0.3 * rng.standard_normal(3) + 1e-3 * rng.standard_normal((3, 3))   # nearly rigid
    drift = 0.1 * rng.standard_normal(3)
    v_p = v_tri.mean(0) - speed * h * n + drift - (drift @ n) * n
    x0 = np.concatenate([[p_star - t_star * v_p], tri_star - t_star * v_tri])
    x1 = np.concatenate([[p_star + (1 - t_star) * v_p], tri_star + (1 - t_star) * v_tri])
    return x0, x1, w_star, n


def test_ccd_vertex_through_fast_triangle():
    rng = np.random.default_rng(8)
    h = 1e-3
    tri = np.array([[1, 2, 3]])
    for trial in range(50):
        t_star = rng.uniform(0.1, 0.9)
        x0, x1, w_star, n = _random_crossing(rng, t_star, h, speed=20.0)
        # neither end is within the thickness: proximity alone misses it
        assert len(P.vertex_face_contacts(x0, tri, [[0, 0]], h).vertex) == 0
        assert len(P.vertex_face_contacts(x1, tri, [[0, 0]], h).vertex) == 0
        r = C.vertex_face_ccd(x0, x1, tri, [[0, 0]])
        assert abs(r.t[0] - t_star) < 1e-9, (trial, r.t[0], t_star)
        assert np.allclose(r.weights[0], w_star, atol=1e-7)
        assert np.allclose(r.normal[0], n, atol=1e-6)      # side the vertex came from


def test_ccd_no_false_positive_parallel_motion():
    rng = np.random.default_rng(9)
    h = 1e-3
    tri = np.array([[1, 2, 3]])
    edges = np.array([[0, 1], [2, 3]])
    for _ in range(50):
        X = rng.standard_normal((3, 3))
        n = np.cross(X[1] - X[0], X[2] - X[0])
        n /= np.linalg.norm(n)
        p = X.mean(0) + 5 * h * n
        v = rng.standard_normal(3) * 2.0
        x0 = np.concatenate([[p], X])
        r = C.vertex_face_ccd(x0, x0 + v, tri, [[0, 0]])                 # same translation
        assert np.isinf(r.t[0])
        vin = v - (v @ n) * n                                           # vertex sweeps across, parallel
        r = C.vertex_face_ccd(x0, x0 + np.concatenate([[vin * 3], np.zeros((3, 3))]), tri, [[0, 0]])
        assert np.isinf(r.t[0])
        # two parallel edges 5h apart translating together, and one sliding along
        a = rng.standard_normal(3)
        d = rng.standard_normal(3)
        off = np.cross(d, rng.standard_normal(3))
        off *= 5 * h / np.linalg.norm(off)
        e0 = np.array([a, a + d, a + off - 0.3 * d, a + off + 0.7 * d])
        assert np.isinf(C.edge_edge_ccd(e0, e0 + v, edges, [[0, 1]]).t[0])
        slide = np.zeros((4, 3)); slide[2:] = 2 * d
        assert np.isinf(C.edge_edge_ccd(e0, e0 + slide, edges, [[0, 1]]).t[0])


def test_ccd_edge_edge_crossing():
    rng = np.random.default_rng(10)
    h = 1e-3
    edges = np.array([[0, 1], [2, 3]])
    for trial in range(50):
        t_star = rng.uniform(0.05, 0.95)
        s_star, u_star = rng.uniform(0.1, 0.9, 2)
        X = rng.standard_normal(3)
        da, db = rng.standard_normal((2, 3))
        ends = np.array([X - s_star * da, X + (1 - s_star) * da, X - u_star * db, X + (1 - u_star) * db])
        n = np.cross(da, db)
        n /= np.linalg.norm(n)
        v = 0.3 * rng.standard_normal(3) + 1e-3 * rng.standard_normal((4, 3))
        v[2:] += 20 * h * n                                 # b moves 20 thicknesses through a
        x0, x1 = ends - t_star * v, ends + (1 - t_star) * v
        r = C.edge_edge_ccd(x0, x1, edges, [[0, 1]])
        assert abs(r.t[0] - t_star) < 1e-9, (trial, r.t[0], t_star)
        assert np.allclose(r.weights[0], [s_star, u_star], atol=1e-6)
        assert np.allclose(r.normal[0], -n, atol=1e-6)     # a -> b before the hit: b came from -n
        assert np.isinf(C.edge_edge_ccd(x0, x0 + (x1 - x0) * (t_star - 0.01), edges, [[0, 1]]).t[0])


def test_ccd_with_swept_bvh_sheet_through_sheet():
    """A sheet falls 20 thicknesses through a static one in one step: the
    swept boxes give the candidates and every vertex over the lower sheet
    hits it at t = 1/2."""
    h = 1e-3
    xa, ta = grid_mesh(8, 8, h=0.1)                       # static, z = 0
    xb, tb = grid_mesh(5, 5, h=0.1)
    xb[:, :2] += 0.13
    xb0, xb1 = xb + [0, 0, 10 * h], xb - [0, 0, 10 * h]
    bt = B.build_bvh(ta, xa, xa, pad=h)
    bv = B.build_bvh(np.arange(len(xb))[:, None], xb0, xb1, pad=h)
    pairs = T.cross_pairs(bt, bv)[:, ::-1]                 # (vertex, face)
    x0 = np.concatenate([xb0, xa])
    x1 = np.concatenate([xb1, xa])
    r = C.vertex_face_ccd(x0, x1, ta + len(xb), pairs)
    hit = np.isfinite(r.t)
    assert set(pairs[hit, 0]) == set(range(len(xb)))
    assert np.allclose(r.t[hit], 0.5, atol=1e-12)
    assert np.allclose(r.normal[hit], [0, 0, 1])
    # edge-edge on the same step: a pair of crossing edges is found
    ea, eb = P.mesh_edges(ta) + len(xb), P.mesh_edges(tb)
    be_a = B.build_bvh(ea, x0, x1, pad=h)
    be_b = B.build_bvh(eb, x0, x1, pad=h)
    ep = T.cross_pairs(be_a, be_b)
    e = np.concatenate([ea, eb])
    r = C.edge_edge_ccd(x0, x1, e, np.stack([ep[:, 0], ep[:, 1] + len(ea)], 1))
    assert np.isfinite(r.t).sum() > 0 and np.allclose(r.t[np.isfinite(r.t)], 0.5, atol=1e-12)


def test_cubic_roots_degenerate_forms():
    out = np.empty(8)
    cases = [((-0.25, 0, 0, 1), [0.25 ** (1 / 3)]),                    # t^3 = 1/4
             ((0.06, -0.5, 1, 0), [0.2, 0.3]),                          # quadratic
             ((-0.7, 1, 0, 0), [0.7]),                                  # linear
             ((1, 0, 0, 0), []),                                        # constant
             ((-0.006, 0.11, -0.6, 1), [0.1, 0.2, 0.3]),                # three roots
             ((0.0625, -0.5, 1, 0), [0.25]),                            # double root
             ((0, 0.5, -1.5, 1), [0.0, 0.5, 1.0])]                      # roots at the ends
    for k, roots in cases:
        n = C.cubic_roots01(*map(float, k), out)
        got = out[:n]
        for r in roots:
            assert np.min(np.abs(got - r)) < 1e-7, (k, got)
        assert np.all(np.abs(np.polyval(k[::-1], got)) < 1e-9)


# ---------------------------------------------------------------- triangle-triangle

def _dot(a, b):
    return np.einsum("...i,...i->...", a, b)


def seg_tri_oracle(a, b, p, q, r):
    """Closed segment ab meets closed triangle pqr, by brute force on the
    sign of volumes (no projection): rows of (N, 3) arrays."""
    n = np.cross(q - p, r - p)
    da, db = _dot(a - p, n), _dot(b - p, n)
    reach = ~(((da > 0) & (db > 0)) | ((da < 0) & (db < 0)))
    vol = lambda u, v, w, z: _dot(np.cross(v - u, w - u), z - u)
    s1, s2, s3 = vol(a, b, p, q), vol(a, b, q, r), vol(a, b, r, p)
    line = ((s1 >= 0) & (s2 >= 0) & (s3 >= 0)) | ((s1 <= 0) & (s2 <= 0) & (s3 <= 0))

    def inside(z):                                   # coplanar point in closed triangle
        return ((_dot(np.cross(q - p, z - p), n) >= 0) & (_dot(np.cross(r - q, z - q), n) >= 0)
                & (_dot(np.cross(p - r, z - r), n) >= 0))

    def within(u, v, z):                             # z collinear with uv: in the closed segment
        return np.all((np.minimum(u, v) <= z) & (z <= np.maximum(u, v)), axis=-1)

    def segs(u, v, w, z):                            # coplanar closed segments uv, wz
        o1, o2 = _dot(np.cross(v - u, w - u), n), _dot(np.cross(v - u, z - u), n)
        o3, o4 = _dot(np.cross(z - w, u - w), n), _dot(np.cross(z - w, v - w), n)
        proper = (o1 * o2 < 0) & (o3 * o4 < 0)
        return (proper | ((o1 == 0) & within(u, v, w)) | ((o2 == 0) & within(u, v, z))
                | ((o3 == 0) & within(w, z, u)) | ((o4 == 0) & within(w, z, v)))

    cop = inside(a) | inside(b) | segs(a, b, p, q) | segs(a, b, q, r) | segs(a, b, r, p)
    return np.where((da == 0) & (db == 0), cop, reach & line)


def tri_tri_oracle(A, Bt):
    """Closed triangles meet iff an edge of one meets the other."""
    hit = np.zeros(len(A), bool)
    for X, Y in ((A, Bt), (Bt, A)):
        for i in range(3):
            hit |= seg_tri_oracle(X[:, i], X[:, (i + 1) % 3], Y[:, 0], Y[:, 1], Y[:, 2])
    return hit


def _nondegenerate(X):
    return np.any(np.cross(X[:, 1] - X[:, 0], X[:, 2] - X[:, 0]) != 0, axis=1)


@pytest.mark.parametrize("span", [1, 2, 4])
def test_tritri_integer_grid_exact(span):
    """Small integer coordinates: every determinant is exact in double, so
    predicate and oracle must agree on every degenerate case too (coplanar,
    touching at a vertex/edge, collinear edges)."""
    rng = np.random.default_rng(11 + span)
    A = rng.integers(-span, span + 1, (6000, 3, 3)).astype(float)
    Bt = rng.integers(-span, span + 1, (6000, 3, 3)).astype(float)
    if span == 2:                                              # many exactly coplanar pairs
        Bt[::2, :, 2] = A[::2, :1, 2]
        A[::2, :, 2] = A[::2, :1, 2]
    keep = _nondegenerate(A) & _nondegenerate(Bt)
    A, Bt = A[keep], Bt[keep]
    got = TT.tri_tri_batch(A, Bt)
    ref = tri_tri_oracle(A, Bt)
    assert np.array_equal(got, ref), np.flatnonzero(got != ref)[:5]
    assert np.array_equal(TT.tri_tri_batch(Bt, A), ref)       # symmetric
    assert np.array_equal(TT.tri_tri_batch(A[:, ::-1], Bt[:, [1, 2, 0]]), ref)   # winding-free
    assert 0.05 < ref.mean() < 0.95


def test_tritri_tilted_plane_integer():
    """Coplanar triangles in a plane that is no coordinate plane (z = x + 2y,
    so the 2D branch must pick a projection), and coplanar-ish pairs (one
    vertex lifted by one unit on a span of 60: a tilt of about 1 degree).
    Integers keep every determinant exact."""
    rng = np.random.default_rng(15)
    n = 3000
    uv = rng.integers(-30, 31, (2, n, 3, 2))
    A, Bt = (np.concatenate([w, (w[..., :1] + 2 * w[..., 1:])], axis=-1).astype(float) for w in uv)
    Bt[n // 2:, 0, 2] += rng.choice([-1.0, 1.0], n - n // 2)
    keep = _nondegenerate(A) & _nondegenerate(Bt)
    A, Bt = A[keep], Bt[keep]
    ref = tri_tri_oracle(A, Bt)
    assert np.array_equal(TT.tri_tri_batch(A, Bt), ref)
    assert np.array_equal(TT.tri_tri_batch(Bt, A), ref)
    assert 0.1 < ref[: n // 3].mean() < 0.9 and 0.1 < ref[-n // 3:].mean() < 0.9


def test_tritri_random_float_and_coplanar():
    rng = np.random.default_rng(12)
    n = 4000
    A = 0.5 * rng.random((n, 1, 3)) + 0.4 * rng.standard_normal((n, 3, 3))
    Bt = 0.5 * rng.random((n, 1, 3)) + 0.4 * rng.standard_normal((n, 3, 3))
    ref = tri_tri_oracle(A, Bt)
    assert np.array_equal(TT.tri_tri_batch(A, Bt), ref)
    assert 0.1 < ref.mean() < 0.9
    # exactly coplanar (z = 0.25) float triangles: the 2D branch
    A[:, :, 2] = 0.25
    Bt[:, :, 2] = 0.25
    ref = tri_tri_oracle(A, Bt)
    assert np.array_equal(TT.tri_tri_batch(A, Bt), ref)


def test_tritri_touching_conventions():
    """Closed sets: touching counts as intersecting."""
    t1 = np.array([[0, 0, 0], [2, 0, 0], [0, 2, 0]], float)
    cases = [([[0, 0, 0], [-1, 0, 1], [0, -1, 1]], True),       # common vertex position
             ([[1, 0, 0], [1, -1, 1], [1, -1, -1]], True),      # vertex on edge
             ([[0.5, 0.5, 0], [1, 1, 3], [2, -1, 3]], True),    # vertex on face
             ([[0.5, 0.5, 1e-9], [1, 1, 3], [2, -1, 3]], False),  # just above
             ([[1, 1, 0], [3, 3, 0], [3, 1, 0]], True),         # coplanar, edge contact
             ([[1.01, 1.01, 0], [3, 3, 0], [3, 1, 0]], False),  # coplanar, apart
             ([[0.2, 0.2, 0], [0.4, 0.2, 0], [0.2, 0.4, 0]], True)]  # coplanar, inside
    for t2, expected in cases:
        t2 = np.array(t2, float)
        assert TT.tri_tri_intersect(t1[0], t1[1], t1[2], t2[0], t2[1], t2[2]) == expected, t2
        assert tri_tri_oracle(t1[None], t2[None])[0] == expected


def test_tritri_shared_vertex_rule():
    v, a, b = np.zeros(3), np.array([1.0, 0, 0]), np.array([0, 1.0, 0])
    x = lambda *pts: np.array([v, a, b, *pts])
    tri = np.array([[0, 1, 2], [0, 3, 4]])
    assert count_self_intersections(x([0.2, 0.2, 1], [0.2, 0.2, -1]), tri) == 1   # pierces
    assert count_self_intersections(x([1, 1, 1], [2, -1, 1]), tri) == 0          # only v
    assert count_self_intersections(x([0.3, 1, 0], [1, 0.3, 0]), tri) == 1       # coplanar overlap
    assert count_self_intersections(x([-1, 0.1, 0], [-1, -1, 0]), tri) == 0      # coplanar, apart
    assert count_self_intersections(x([0, 1, 0.5], [1, 0, 0.5]), np.array([[0, 1, 2], [0, 1, 3]])) == 0


def _mesh_oracle(x, tri):
    """All pairs by brute force with the numpy oracle and the shared-vertex rule."""
    i, j = np.triu_indices(len(tri), 1)
    same = tri[i][:, :, None] == tri[j][:, None, :]           # (pairs, 3, 3)
    shared = same.sum((1, 2))
    X = x[tri]
    hit = np.zeros(len(i), bool)
    s0 = shared == 0
    hit[s0] = tri_tri_oracle(X[i[s0]], X[j[s0]])
    s1 = np.flatnonzero(shared == 1)
    ti, tj = tri[i[s1]], tri[j[s1]]
    oi = ti[~same[s1].any(2)].reshape(-1, 2)                   # edge opposite the shared vertex
    oj = tj[~same[s1].any(1)].reshape(-1, 2)
    hit[s1] = (seg_tri_oracle(x[oi[:, 0]], x[oi[:, 1]], *np.moveaxis(x[tj], 1, 0))
               | seg_tri_oracle(x[oj[:, 0]], x[oj[:, 1]], *np.moveaxis(x[ti], 1, 0)))
    return np.stack([i[hit], j[hit]], 1)


def test_count_self_intersections_mesh():
    rng = np.random.default_rng(13)
    x, tri = grid_mesh(10, 10, h=0.1)
    assert count_self_intersections(x, tri) == 0               # flat sheet
    # fold: the right half turned over the left one about x = 0.5 (175 degrees)
    # and pushed down, so it passes through the left half along a line
    xf = x.copy()
    right = x[:, 0] > 0.5
    ang = np.deg2rad(175.0)
    dx = x[right, 0] - 0.5
    xf[right, 0] = 0.5 + np.cos(ang) * dx
    xf[right, 2] = np.sin(ang) * dx - 0.03 + 0.003 * rng.standard_normal(right.sum())
    got = TT.self_intersecting_pairs(xf, tri)
    ref = _mesh_oracle(xf, tri)
    assert len(ref) > 0 and np.array_equal(got, ref)
    all_i = np.stack(np.triu_indices(len(tri), 1), 1)
    assert np.array_equal(TT.self_intersecting_pairs(xf, tri, all_i), ref)   # BVH misses nothing
    # heavy 3D noise: neighbours sharing one vertex pierce each other too
    xn = x + 0.08 * rng.standard_normal(x.shape)
    got = TT.self_intersecting_pairs(xn, tri)
    shared = (tri[got[:, 0]][:, :, None] == tri[got[:, 1]][:, None, :]).sum((1, 2))
    assert np.any(shared == 0) and np.any(shared == 1)
    assert np.array_equal(got, _mesh_oracle(xn, tri))


def test_nearly_coplanar_disjoint_triangles_do_not_intersect():
    # two triangles of the flat ribbon lying on its tilted ramp
    # (configs/ribbon.yaml, step 65, exact coordinates): coplanar to 1e-17 m
    # and 7 mm apart in their plane; without the orient3d error filter the
    # signs of rounding noise reported an intersection both ways round
    from distcloth.collision.tritri import tri_tri_intersect
    P = np.array([[-0.062412385249151, 0.36616976610630403, 0.38740297363781795],
                  [-0.049927157408656025, 0.3861041784214118, 0.38540953240630715],
                  [-0.06241072025441475, 0.38610297305955626, 0.3854096529424927]])
    Q = np.array([[-0.07489454227073498, 0.3861009069022923, 0.3854098595582191],
                  [-0.06240828543901254, 0.4060343602569031, 0.38341651422275796],
                  [-0.07489253047520174, 0.4060322233408098, 0.3834167279143673]])
    assert not tri_tri_intersect(P[0], P[1], P[2], Q[0], Q[1], Q[2])
    assert not tri_tri_intersect(Q[0], Q[1], Q[2], P[0], P[1], P[2])
    # slid onto Q and tilted so that a corner pierces it: a crossing (exactly
    # coplanar overlaps are covered by the tests above)
    shifted = Q + 0.3 * (Q[1] - Q[0])
    n = np.cross(Q[1] - Q[0], Q[2] - Q[0])
    n /= np.linalg.norm(n)
    pierce = shifted + 0.002 * n
    pierce[0] -= 0.006 * n
    assert tri_tri_intersect(pierce[0], pierce[1], pierce[2], Q[0], Q[1], Q[2])
    assert tri_tri_intersect(Q[0], Q[1], Q[2], pierce[0], pierce[1], pierce[2])
