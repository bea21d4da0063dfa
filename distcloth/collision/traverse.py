"""BVH-vs-BVH traversal as independent tests on an explicit stack.

EG07 tutorial, Part 1 §5.8.1: the recursive test of two
hierarchies is a depth first traversal driven by a stack of pending tests;
tests can be popped from the top and executed in place, or removed from the
*bottom* of the stack and handed to another task (they originate closer to
the root, so they carry more work).  §5.8.2: with the hierarchies replicated
on every rank a test is just four integers (obj1, node1, obj2, node2), so
tasks are cheap to ship.

Test rows and objects
---------------------
A test is an int64 row ``(obj1, node1, obj2, node2)``; ``obj`` indexes a
tuple of trees packed into one ``Forest`` (all node arrays concatenated,
object o owning nodes ``node_off[o]:node_off[o+1]`` and primitives
``prim_off[o]:prim_off[o+1]``; node and primitive ids in tests and results
stay *local* to their object).  Trees over different primitive types
(triangles, edges, points) pack the same way: the traversal only looks at
boxes.

Semantics of a test:

* boxes disjoint -> dropped;
* obj1 == obj2 and node1 == node2 (self test): a leaf emits its unordered
  primitive pairs, an internal node pushes (L, L), (R, R), (L, R);
* both leaves: every primitive pair whose *primitive* boxes overlap is
  emitted (so the result is exactly the set of box-overlapping pairs,
  independent of the tree shapes);
* otherwise the node with more primitives (node1 on ties) that is not a leaf
  is split and its two child tests are pushed.

Results are rows ``(obj1, p1, obj2, p2)``; when obj1 == obj2 the pair is
canonical (p1 < p2) and p1 == p2 is never emitted.  Each unordered pair of
one self test, and each pair of a cross test, is emitted exactly once, so a
set of disjoint root tests (e.g. one self test per object and one cross test
per pair of objects) produces no duplicates.  Root tests on the same object
must be either identical nodes or disjoint sub-trees.

The stack is a plain int64 array ``(cap, 4)`` with ``top`` valid rows; rows
``[0:k]`` (the bottom) can be cut off with ``take_bottom`` and run anywhere
else: the union of the results is unchanged.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .bvh import BVH

# status codes of traverse_chunk
DONE, MAX_TESTS, OUT_FULL, STACK_FULL = 0, 1, 2, 3


class Forest:
    """Several BVHs packed into concatenated arrays (see module docstring)."""

    __slots__ = ("node_off", "prim_off", "lo", "hi", "left", "right", "first",
                 "count", "order", "plo", "phi", "max_leaf")

    def __init__(self, trees):
        trees = list(trees)
        nn = [t.n_nodes for t in trees]
        nm = [t.n_prims for t in trees]
        self.node_off = np.concatenate([[0], np.cumsum(nn)]).astype(np.int64)
        self.prim_off = np.concatenate([[0], np.cumsum(nm)]).astype(np.int64)
        cat = lambda name, shape: (np.ascontiguousarray(np.concatenate([getattr(t, name) for t in trees]))
                                   if trees else np.empty(shape))
        self.lo, self.hi = cat("lo", (0, 3)), cat("hi", (0, 3))
        self.plo, self.phi = cat("plo", (0, 3)), cat("phi", (0, 3))
        self.left = cat("left", 0).astype(np.int64)
        self.right = cat("right", 0).astype(np.int64)
        self.first = cat("first", 0).astype(np.int64)
        self.count = cat("count", 0).astype(np.int64)
        self.order = cat("order", 0).astype(np.int64)
        leaves = self.left < 0
        self.max_leaf = int(self.count[leaves].max()) if leaves.any() else 1

    @property
    def n_objects(self) -> int:
        return int(self.node_off.shape[0] - 1)

    def n_nodes(self, obj: int) -> int:
        return int(self.node_off[obj + 1] - self.node_off[obj])


def as_forest(trees) -> Forest:
    if isinstance(trees, Forest):
        return trees
    if isinstance(trees, BVH):
        trees = (trees,)
    return Forest(trees)


@njit(cache=True)
def _overlap(lo1, hi1, i, lo2, hi2, j):
    for a in range(3):
        if lo1[i, a] > hi2[j, a] or lo2[j, a] > hi1[i, a]:
            return False
    return True


@njit(cache=True)
def traverse_chunk(stack, top, max_tests, node_off, prim_off, lo, hi, left, right,
                   first, count, order, plo, phi, max_leaf, out, n_out):
    """Pop and run up to ``max_tests`` tests; child tests are pushed, pairs
    appended to ``out[n_out:]``.

    Before popping a test the kernel checks that its worst case fits (at
    most max_leaf**2 pairs, at most 3 pushes after the pop), so a test is
    never half done: on OUT_FULL / STACK_FULL the caller enlarges the array
    and calls again.  Returns (top, tests_run, n_out, status)."""
    cap_s = stack.shape[0]
    cap_o = out.shape[0]
    done = 0
    status = DONE
    while top > 0:
        if done >= max_tests:
            status = MAX_TESTS
            break
        if n_out + max_leaf * max_leaf > cap_o:
            status = OUT_FULL
            break
        if top + 2 > cap_s:
            status = STACK_FULL
            break
        top -= 1
        o1 = stack[top, 0]
        n1 = stack[top, 1]
        o2 = stack[top, 2]
        n2 = stack[top, 3]
        done += 1
        if node_off[o1 + 1] == node_off[o1] or node_off[o2 + 1] == node_off[o2]:
            continue                                   # an empty tree
        g1 = node_off[o1] + n1
        g2 = node_off[o2] + n2
        same_obj = o1 == o2
        if same_obj and n1 == n2:                      # self test of one node
            if left[g1] < 0:
                base = prim_off[o1]
                f = base + first[g1]
                c = count[g1]
                for i in range(c):
                    p = order[f + i]
                    for j in range(i + 1, c):
                        q = order[f + j]
                        if _overlap(plo, phi, base + p, plo, phi, base + q):
                            out[n_out, 0] = o1
                            out[n_out, 1] = min(p, q)
                            out[n_out, 2] = o1
                            out[n_out, 3] = max(p, q)
                            n_out += 1
            else:
                l = left[g1]
                r = right[g1]
                stack[top, 0] = o1; stack[top, 1] = l; stack[top, 2] = o1; stack[top, 3] = r
                stack[top + 1, 0] = o1; stack[top + 1, 1] = r; stack[top + 1, 2] = o1; stack[top + 1, 3] = r
                stack[top + 2, 0] = o1; stack[top + 2, 1] = l; stack[top + 2, 2] = o1; stack[top + 2, 3] = l
                top += 3
            continue
        if not _overlap(lo, hi, g1, lo, hi, g2):
            continue
        leaf1 = left[g1] < 0
        leaf2 = left[g2] < 0
        if leaf1 and leaf2:
            b1 = prim_off[o1]
            b2 = prim_off[o2]
            f1 = b1 + first[g1]
            f2 = b2 + first[g2]
            for i in range(count[g1]):
                p = order[f1 + i]
                for j in range(count[g2]):
                    q = order[f2 + j]
                    if same_obj and p == q:
                        continue
                    if _overlap(plo, phi, b1 + p, plo, phi, b2 + q):
                        out[n_out, 0] = o1
                        out[n_out, 2] = o2
                        if same_obj and q < p:
                            out[n_out, 1] = q
                            out[n_out, 3] = p
                        else:
                            out[n_out, 1] = p
                            out[n_out, 3] = q
                        n_out += 1
            continue
        split1 = leaf2 or (not leaf1 and count[g1] >= count[g2])
        if split1:
            l = left[g1]
            r = right[g1]
            stack[top, 0] = o1; stack[top, 1] = r; stack[top, 2] = o2; stack[top, 3] = n2
            stack[top + 1, 0] = o1; stack[top + 1, 1] = l; stack[top + 1, 2] = o2; stack[top + 1, 3] = n2
        else:
            l = left[g2]
            r = right[g2]
            stack[top, 0] = o1; stack[top, 1] = n1; stack[top, 2] = o2; stack[top, 3] = r
            stack[top + 1, 0] = o1; stack[top + 1, 1] = n1; stack[top + 1, 2] = o2; stack[top + 1, 3] = l
        top += 2
    return top, done, n_out, status


class TraversalState:
    """A stack of pending tests and an output buffer that grow on demand."""

    def __init__(self, tests, stack_cap: int = 1024, out_cap: int = 4096):
        tests = np.asarray(tests, dtype=np.int64).reshape(-1, 4)
        self.stack = np.empty((max(stack_cap, 2 * tests.shape[0] + 4), 4), np.int64)
        # push in reverse so the first test is popped first
        self.stack[:tests.shape[0]] = tests[::-1]
        self.top = tests.shape[0]
        self.out = np.empty((out_cap, 4), np.int64)
        self.n_out = 0
        self.tests_run = 0

    def pending(self) -> np.ndarray:
        return self.stack[:self.top]

    def run(self, forest: Forest, max_tests: int) -> int:
        """Run at most max_tests tests (growing buffers as needed); returns
        the number of tests run."""
        ran = 0
        while self.top > 0 and ran < max_tests:
            self.top, k, self.n_out, status = traverse_chunk(
                self.stack, self.top, max_tests - ran, forest.node_off, forest.prim_off,
                forest.lo, forest.hi, forest.left, forest.right, forest.first, forest.count,
                forest.order, forest.plo, forest.phi, forest.max_leaf, self.out, self.n_out)
            ran += k
            if status == OUT_FULL:
                self.out = _grown(self.out, self.n_out + forest.max_leaf ** 2)
            elif status == STACK_FULL:
                self.stack = _grown(self.stack, self.top + 3)
        self.tests_run += ran
        return ran

    def take_bottom(self, k: int) -> np.ndarray:
        """Remove the k bottom tests (closest to the root, EG07 tutorial,
        Part 1 §5.8.2) and return them as an independent task (k, 4)."""
        self.stack, self.top, rows = take_bottom(self.stack, self.top, k)
        return rows

    def pairs(self) -> np.ndarray:
        return self.out[:self.n_out]


def _grown(a: np.ndarray, need: int) -> np.ndarray:
    b = np.empty((max(2 * a.shape[0], need), a.shape[1]), a.dtype)
    b[:a.shape[0]] = a
    return b


def take_bottom(stack: np.ndarray, top: int, k: int):
    """Cut rows [0:k] off the bottom of a stack: returns (stack, top - k, rows)."""
    k = max(0, min(int(k), int(top)))
    rows = stack[:k].copy()
    stack[:top - k] = stack[k:top].copy()
    return stack, top - k, rows


def run_tests(trees, tests, chunk: int = 1 << 16) -> np.ndarray:
    """Run the given root tests to completion; raw result rows (n, 4) in
    emission order (no sorting, no de-duplication)."""
    forest = as_forest(trees)
    state = TraversalState(tests)
    while state.top > 0:
        state.run(forest, chunk)
    return state.pairs().copy()


def unique_rows(a: np.ndarray) -> np.ndarray:
    """Sorted unique rows of a 2D integer array, lexicographic (first
    column first).  Non-negative rows whose columns pack into one int64 key
    (column j times the product of the later columns' ranges) are sorted as
    keys, unless they already are: one 1D sort instead of a lexsort over
    the columns (np.unique(axis=0), which sorts a structured view, is ~10x
    slower still on millions of rows)."""
    if a.shape[0] == 0:
        return a
    a = np.asarray(a)
    span = a.max(axis=0).astype(np.int64) + 1
    if a.min() >= 0 and float(np.prod(span.astype(np.float64))) < 2.0 ** 62:
        scale = np.ones(a.shape[1], dtype=np.int64)
        for j in range(a.shape[1] - 2, -1, -1):
            scale[j] = scale[j + 1] * span[j + 1]
        key = a.astype(np.int64) @ scale
        if not np.all(key[1:] > key[:-1]):      # already sorted unique: an O(n) check
            key = np.unique(key)
        out = np.empty((key.size, a.shape[1]), dtype=a.dtype)
        for j in range(a.shape[1]):
            out[:, j], key = np.divmod(key, scale[j])
        return out
    a = a[np.lexsort(a.T[::-1])]
    keep = np.ones(a.shape[0], np.bool_)
    keep[1:] = np.any(a[1:] != a[:-1], axis=1)
    return a[keep]


def canonical(pairs: np.ndarray) -> np.ndarray:
    """Sorted unique rows."""
    return unique_rows(np.asarray(pairs, dtype=np.int64).reshape(-1, 4))


def all_pairs(trees, root_tests=None) -> np.ndarray:
    """Candidate pairs (obj1, p1, obj2, p2) of the root tests, sorted unique.

    Default root tests: a self test of every object and a cross test of every
    pair of objects (o1 < o2)."""
    forest = as_forest(trees)
    if root_tests is None:
        root_tests = default_root_tests(forest.n_objects)
    return canonical(run_tests(forest, root_tests))


def default_root_tests(n_objects: int) -> np.ndarray:
    i, j = np.triu_indices(n_objects)
    z = np.zeros_like(i)
    return np.stack([i, z, j, z], axis=1).astype(np.int64)


def self_pairs(bvh: BVH) -> np.ndarray:
    """Box-overlapping primitive pairs (p, q), p < q, of one tree, sorted."""
    return all_pairs((bvh,), np.array([[0, 0, 0, 0]]))[:, [1, 3]]


def cross_pairs(a: BVH, b: BVH) -> np.ndarray:
    """Box-overlapping pairs (p in a, q in b), sorted."""
    return all_pairs((a, b), np.array([[0, 0, 1, 0]]))[:, [1, 3]]
