"""Axis-aligned bounding-box hierarchies over mesh primitives.

EG07 tutorial, Part 1 §2.3: collision detection between
deformable meshes is accelerated with a bounding volume hierarchy built
top-down once and then updated; AABBs and k-DOPs are the usual bounding
volumes for cloth.

Why AABBs
---------
The hierarchy is *refit* at the start of every collision phase (the tree
topology stays fixed, EG07 tutorial, Part 1 §5.8.2: "the structure of this
hierarchy is kept constant throughout the simulation"), so the two hot
operations are the bottom-up refit and the box-box overlap test.  For an
AABB both are 3 min/max pairs and 3 interval tests.  An 18-DOP encloses
diagonal (sheared, folded) cloth more tightly but costs 9 slab intervals
per overlap test and per refit; with a refit every phase the AABB is the
usual choice for cloth, and is what we use.

Primitives
----------
A primitive is a row of an int64 array ``prims (m, k)`` of vertex ids with
k = 3 (triangles), 2 (edges) or 1 (points).  Its box is the box of its
vertices at ``x`` and, if given, at ``x_end`` (a *swept* box enclosing the
linear trajectory over a step, for continuous collision detection), grown
by ``pad`` (the thickness) on every side.

Flat layout (class ``BVH``)
---------------------------
``n`` nodes, node 0 is the root, every child has a larger index than its
parent (nodes are numbered breadth first), so a reverse sweep is a valid
bottom-up order.

    lo, hi     float64 (n, 3)   node boxes
    left,right int64 (n,)       children, -1 for a leaf
    first,count int64 (n,)      primitives under the node are
                                order[first:first+count] (contiguous for
                                internal nodes too; for leaves count <= leaf_size)
    parent     int64 (n,)       -1 for the root
    order      int64 (m,)       primitive ids in tree order
    plo, phi   float64 (m, 3)   primitive boxes, indexed by primitive id

The split is the median (by count) along the longest axis of the centroid
bounds, ties broken by primitive id, so the tree is a deterministic function
of the boxes: every rank that builds it gets the same node numbering.
"""
from __future__ import annotations

import numpy as np
from numba import njit


class BVH:
    """Flat AABB tree; see the module docstring for the array layout."""

    __slots__ = ("lo", "hi", "left", "right", "first", "count", "parent",
                 "order", "plo", "phi", "leaf_size")

    def __init__(self, lo, hi, left, right, first, count, parent, order, plo, phi, leaf_size):
        self.lo, self.hi = lo, hi
        self.left, self.right = left, right
        self.first, self.count = first, count
        self.parent, self.order = parent, order
        self.plo, self.phi = plo, phi
        self.leaf_size = int(leaf_size)

    @property
    def n_nodes(self) -> int:
        return int(self.left.shape[0])

    @property
    def n_prims(self) -> int:
        return int(self.plo.shape[0])

    def root_box(self):
        """(lo, hi) of the root; an empty box (+inf, -inf) for an empty tree."""
        if self.n_nodes == 0:
            return np.full(3, np.inf), np.full(3, -np.inf)
        return self.lo[0].copy(), self.hi[0].copy()


def _as_prims(prims) -> np.ndarray:
    prims = np.asarray(prims, dtype=np.int64)
    if prims.ndim == 1:
        prims = prims[:, None]
    if prims.ndim != 2 or prims.shape[1] not in (1, 2, 3):
        raise ValueError(f"primitives must be (m, k) vertex ids with k in 1..3, got {prims.shape}")
    return np.ascontiguousarray(prims)


@njit(cache=True)
def _prim_boxes(prims, x, x_end, pad, plo, phi):
    """Box of every primitive over its vertices at x and x_end, grown by pad."""
    m, k = prims.shape
    for i in range(m):
        for a in range(3):
            lo = np.inf
            hi = -np.inf
            for j in range(k):
                v = prims[i, j]
                lo = min(lo, x[v, a], x_end[v, a])
                hi = max(hi, x[v, a], x_end[v, a])
            plo[i, a] = lo - pad
            phi[i, a] = hi + pad


def primitive_boxes(prims, x, x_end=None, pad: float = 0.0):
    """(plo, phi), each (m, 3): the (swept, padded) box of every primitive."""
    prims = _as_prims(prims)
    x = np.ascontiguousarray(x, dtype=np.float64)
    x_end = x if x_end is None else np.ascontiguousarray(x_end, dtype=np.float64)
    plo = np.empty((prims.shape[0], 3))
    phi = np.empty((prims.shape[0], 3))
    _prim_boxes(prims, x, x_end, float(pad), plo, phi)
    return plo, phi


@njit(cache=True)
def _before(key, a, b):
    """Strict order of primitives a, b: by key, ties by primitive id."""
    return key[a] < key[b] or (key[a] == key[b] and a < b)


@njit(cache=True)
def _sort_range(order, f, c, key, tmp):
    """Sort order[f:f+c] by (key, id): bottom-up merge sort (O(c log c),
    and cheaper to compile than np.argsort(kind="mergesort") + np.sort)."""
    src = order[f:f + c]
    dst = tmp[:c]
    width = 1
    while width < c:
        for lo in range(0, c, 2 * width):
            mid = min(lo + width, c)
            hi = min(lo + 2 * width, c)
            i = lo
            j = mid
            for k in range(lo, hi):
                if i < mid and (j >= hi or not _before(key, src[j], src[i])):
                    dst[k] = src[i]
                    i += 1
                else:
                    dst[k] = src[j]
                    j += 1
        src, dst = dst, src
        width *= 2
    for k in range(c):
        order[f + k] = src[k]


@njit(cache=True)
def _build_topology(cen, leaf_size):
    """Top-down median split, nodes numbered breadth first (children after
    their parent).  Returns (left, right, first, count, parent, order)."""
    m = cen.shape[0]
    cap = max(2 * m - 1, 0)
    left = np.full(cap, -1, np.int64)
    right = np.full(cap, -1, np.int64)
    first = np.zeros(cap, np.int64)
    count = np.zeros(cap, np.int64)
    parent = np.full(cap, -1, np.int64)
    order = np.arange(m).astype(np.int64)
    if m == 0:
        return left, right, first, count, parent, order
    key = np.empty(m)
    tmp = np.empty(m, np.int64)
    count[0] = m
    n = 1
    i = 0
    while i < n:
        c = count[i]
        if c > leaf_size:
            f = first[i]
            axis = 0
            best = -1.0
            for a in range(3):
                lo = np.inf
                hi = -np.inf
                for j in range(f, f + c):
                    v = cen[order[j], a]
                    lo = min(lo, v)
                    hi = max(hi, v)
                if hi - lo > best:
                    best = hi - lo
                    axis = a
            for j in range(f, f + c):
                key[order[j]] = cen[order[j], axis]
            _sort_range(order, f, c, key, tmp)
            mid = c // 2
            left[i] = n
            right[i] = n + 1
            first[n] = f
            count[n] = mid
            first[n + 1] = f + mid
            count[n + 1] = c - mid
            parent[n] = i
            parent[n + 1] = i
            n += 2
        i += 1
    return left[:n], right[:n], first[:n], count[:n], parent[:n], order


@njit(cache=True)
def _refit_nodes(left, right, first, count, order, plo, phi, lo, hi):
    """Bottom-up box update: children have larger indices than parents."""
    for i in range(left.shape[0] - 1, -1, -1):
        l = left[i]
        if l < 0:
            for a in range(3):
                lo[i, a] = np.inf
                hi[i, a] = -np.inf
            for j in range(first[i], first[i] + count[i]):
                p = order[j]
                for a in range(3):
                    lo[i, a] = min(lo[i, a], plo[p, a])
                    hi[i, a] = max(hi[i, a], phi[p, a])
        else:
            r = right[i]
            for a in range(3):
                lo[i, a] = min(lo[l, a], lo[r, a])
                hi[i, a] = max(hi[l, a], hi[r, a])


def build_from_boxes(plo, phi, leaf_size: int = 4) -> BVH:
    """BVH over primitives given by their boxes (m, 3) each."""
    if leaf_size < 1:
        raise ValueError("leaf_size must be >= 1")
    plo = np.ascontiguousarray(plo, dtype=np.float64).reshape(-1, 3)
    phi = np.ascontiguousarray(phi, dtype=np.float64).reshape(-1, 3)
    cen = 0.5 * (plo + phi)
    left, right, first, count, parent, order = _build_topology(cen, int(leaf_size))
    n = left.shape[0]
    lo = np.empty((n, 3))
    hi = np.empty((n, 3))
    _refit_nodes(left, right, first, count, order, plo, phi, lo, hi)
    return BVH(lo, hi, left, right, first, count, parent, order, plo, phi, leaf_size)


def build_bvh(prims, x, x_end=None, pad: float = 0.0, leaf_size: int = 4) -> BVH:
    """BVH over ``prims (m, k)`` (triangles, edges or points) at positions
    ``x (n, 3)``; with ``x_end`` the boxes are swept over x -> x_end.
    m = 0 gives an empty tree (0 nodes)."""
    plo, phi = primitive_boxes(prims, x, x_end, pad)
    return build_from_boxes(plo, phi, leaf_size)


def refit(bvh: BVH, prims, x, x_end=None, pad: float = 0.0) -> BVH:
    """Recompute every box in place for new positions; the topology is kept."""
    prims = _as_prims(prims)
    if prims.shape[0] != bvh.n_prims:
        raise ValueError("refit with a different number of primitives")
    x = np.ascontiguousarray(x, dtype=np.float64)
    x_end = x if x_end is None else np.ascontiguousarray(x_end, dtype=np.float64)
    _prim_boxes(prims, x, x_end, float(pad), bvh.plo, bvh.phi)
    _refit_nodes(bvh.left, bvh.right, bvh.first, bvh.count, bvh.order,
                 bvh.plo, bvh.phi, bvh.lo, bvh.hi)
    return bvh


def combine_roots(lo, hi) -> BVH:
    """Top-level tree over the root boxes ``lo, hi (r, 3)`` of r sub-trees.

    EG07 tutorial, Part 1 §5.8.2: each rank builds the BVH of its own sub-mesh,
    the root boxes are all-gathered and combined into a global hierarchy
    that every rank replicates.  Leaves hold exactly one sub-tree id
    (leaf_size 1) so ``graft`` can splice the sub-trees in.  Empty sub-trees
    (lo > hi, e.g. a rank without primitives) are left out of the tree."""
    lo = np.ascontiguousarray(lo, dtype=np.float64).reshape(-1, 3)
    hi = np.ascontiguousarray(hi, dtype=np.float64).reshape(-1, 3)
    valid = np.flatnonzero(np.all(lo <= hi, axis=1))
    top = build_from_boxes(lo[valid], hi[valid], leaf_size=1)
    top.order = valid[top.order]
    top.plo, top.phi = lo.copy(), hi.copy()
    return top


def graft(top: BVH, subs: list[BVH]):
    """Splice the sub-trees into the leaves of ``top`` (from ``combine_roots``)
    giving one BVH over all primitives.

    Global primitive ids are sub-tree ids offset by ``prim_off[s]`` (the
    primitives of sub-tree s in order), i.e. the tree is over the
    concatenation of the sub-trees' primitive arrays.  Node layout: the
    internal nodes of ``top`` first (in their order), then sub-tree s as the
    contiguous block ``node_off[s]:node_off[s]+subs[s].n_nodes`` — a rank can
    refit its own block and exchange just that.

    Returns (bvh, node_off (r+1,), prim_off (r+1,))."""
    sizes = np.array([s.n_prims for s in subs], dtype=np.int64)
    nn = np.array([s.n_nodes for s in subs], dtype=np.int64)
    prim_off = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    internal = np.flatnonzero(top.left >= 0)
    n_int = internal.shape[0]
    node_off = (n_int + np.concatenate([[0], np.cumsum(nn)])).astype(np.int64)
    n_total = int(node_off[-1])
    plo = np.concatenate([s.plo for s in subs]) if subs else np.empty((0, 3))
    phi = np.concatenate([s.phi for s in subs]) if subs else np.empty((0, 3))
    if top.n_nodes == 0:
        e = np.empty(0, np.int64)
        return (BVH(np.empty((0, 3)), np.empty((0, 3)), e, e.copy(), e.copy(), e.copy(),
                    e.copy(), e.copy(), plo, phi, 1), node_off, prim_off)

    # new index of every top node: internal nodes keep their relative order,
    # a leaf becomes the root of its sub-tree
    leaf_sub = top.order[top.first]                    # sub id held by each top node's range start
    new_id = np.where(top.left >= 0, np.cumsum(top.left >= 0) - 1, node_off[leaf_sub])
    remap = lambda a: np.where(a >= 0, new_id[np.maximum(a, 0)], -1)

    # primitive positions: sub-trees laid out in top-leaf order
    seq = top.order                                      # sub ids in top order (each leaf one)
    pos = np.concatenate([[0], np.cumsum(sizes[seq])]).astype(np.int64)
    pos_of = np.zeros(len(subs), np.int64)
    pos_of[seq] = pos[:-1]

    lo = np.empty((n_total, 3))
    hi = np.empty((n_total, 3))
    left = np.empty(n_total, np.int64)
    right = np.empty(n_total, np.int64)
    first = np.empty(n_total, np.int64)
    count = np.empty(n_total, np.int64)
    parent = np.empty(n_total, np.int64)
    order = np.empty(int(prim_off[-1]), np.int64)

    lo[:n_int], hi[:n_int] = top.lo[internal], top.hi[internal]
    left[:n_int], right[:n_int] = remap(top.left[internal]), remap(top.right[internal])
    parent[:n_int] = remap(top.parent[internal])
    first[:n_int] = pos[top.first[internal]]
    count[:n_int] = pos[top.first[internal] + top.count[internal]] - first[:n_int]
    for s, sub in enumerate(subs):
        if sub.n_nodes == 0:
            continue
        blk = slice(node_off[s], node_off[s + 1])
        lo[blk], hi[blk] = sub.lo, sub.hi
        left[blk] = np.where(sub.left >= 0, sub.left + node_off[s], -1)
        right[blk] = np.where(sub.right >= 0, sub.right + node_off[s], -1)
        parent[blk] = np.where(sub.parent >= 0, sub.parent + node_off[s], -1)
        first[blk] = sub.first + pos_of[s]
        count[blk] = sub.count
        order[pos_of[s]:pos_of[s] + sizes[s]] = sub.order + prim_off[s]
    # the sub-tree roots hang below the parents of the top leaves they replace
    top_leaves = np.flatnonzero(top.left < 0)
    parent[node_off[leaf_sub[top_leaves]]] = remap(top.parent[top_leaves])
    leaf_size = max([s.leaf_size for s in subs] + [1])
    return (BVH(lo, hi, left, right, first, count, parent, order, plo, phi, leaf_size),
            node_off, prim_off)
