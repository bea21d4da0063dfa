"""Serial counterparts of the distributed collision code, as oracles for tests."""
from __future__ import annotations

import numpy as np

from distcloth.collision import bvh as B
from distcloth.collision.traverse import cross_pairs, self_pairs
from distcloth.collision.tritri import self_intersecting_pairs


def serial_candidates(tri, edges, thickness: float, leaf_size: int = 4):
    """Candidate finder ``f(x0, x1) -> (vf (k, 2) [vertex, face], ee (l, 2)
    [ea < eb])`` from the serial BVH code: swept boxes of x0 -> x1, each
    padded by ``thickness`` (so every pair that comes within 2 thickness
    is listed).  The simulator passes the distributed detector's finder."""
    tri = np.ascontiguousarray(tri, dtype=np.int64).reshape(-1, 3)
    edges = np.ascontiguousarray(edges, dtype=np.int64).reshape(-1, 2)
    pad = float(thickness)

    def find(x0, x1):
        pts = np.arange(np.asarray(x0).shape[0], dtype=np.int64)[:, None]
        vb = B.build_bvh(pts, x0, x1, pad, leaf_size)
        fb = B.build_bvh(tri, x0, x1, pad, leaf_size)
        eb = B.build_bvh(edges, x0, x1, pad, leaf_size)
        return cross_pairs(vb, fb), self_pairs(eb)
    return find


def count_self_intersections(x, tri, candidate_pairs=None) -> int:
    """Number of intersecting triangle pairs of the mesh (tritri's rules)."""
    return int(self_intersecting_pairs(x, tri, candidate_pairs).shape[0])


def refit_boxes(bvh, plo, phi):
    """Refit a tree from given primitive boxes (e.g. the root boxes of sub-trees)."""
    bvh.plo[...] = plo
    bvh.phi[...] = phi
    B._refit_nodes(bvh.left, bvh.right, bvh.first, bvh.count, bvh.order,
                   bvh.plo, bvh.phi, bvh.lo, bvh.hi)
    return bvh
