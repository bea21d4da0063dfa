"""Small meshes the collision tests share (an icosphere, a split-square grid)
and the generalised winding number used as an inside/outside oracle."""
from __future__ import annotations

import numpy as np


def icosphere(level: int) -> tuple[np.ndarray, np.ndarray]:
    """Unit icosphere, outward oriented, by midpoint subdivision."""
    g = (1 + 5 ** 0.5) / 2
    v = np.array([[-1, g, 0], [1, g, 0], [-1, -g, 0], [1, -g, 0], [0, -1, g], [0, 1, g],
                  [0, -1, -g], [0, 1, -g], [g, 0, -1], [g, 0, 1], [-g, 0, -1], [-g, 0, 1]], float)
    f = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9],
                  [5, 11, 4], [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2],
                  [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10],
                  [8, 6, 7], [9, 8, 1]])
    verts = list(v / np.linalg.norm(v, axis=1)[:, None])
    for _ in range(level):
        cache: dict[tuple[int, int], int] = {}

        def mid(a, b):
            key = (min(a, b), max(a, b))
            if key not in cache:
                m = verts[a] + verts[b]
                verts.append(m / np.linalg.norm(m))
                cache[key] = len(verts) - 1
            return cache[key]

        f = np.array([[a, mid(a, b), mid(c, a)] for a, b, c in f]
                     + [[b, mid(b, c), mid(a, b)] for a, b, c in f]
                     + [[c, mid(c, a), mid(b, c)] for a, b, c in f]
                     + [[mid(a, b), mid(b, c), mid(c, a)] for a, b, c in f])
    return np.array(verts), f


def grid_mesh(nx, ny, h=1.0):
    """Split-square grid: vertices (nx+1)(ny+1), triangles 2 nx ny."""
    i, j = np.meshgrid(np.arange(nx + 1), np.arange(ny + 1), indexing="ij")
    x = np.stack([i.ravel() * h, j.ravel() * h, np.zeros(i.size)], axis=1)
    v = lambda a, b: a * (ny + 1) + b
    a, b = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    a, b = a.ravel(), b.ravel()
    tri = np.concatenate([np.stack([v(a, b), v(a + 1, b), v(a + 1, b + 1)], 1),
                          np.stack([v(a, b), v(a + 1, b + 1), v(a, b + 1)], 1)])
    return x, tri.astype(np.int64)


def winding_number(pts, x, tri, chunk=256):
    """Generalised winding number (solid angles, Van Oosterom & Strackee 1983):
    ~1 inside a closed outward mesh, ~0 outside."""
    out = np.empty(pts.shape[0])
    for s in range(0, pts.shape[0], chunk):
        p = pts[s:s + chunk, None, :]
        a, b, c = (x[tri[:, k]][None] - p for k in range(3))
        la, lb, lc = (np.linalg.norm(v, axis=2) for v in (a, b, c))
        det = np.einsum("ijk,ijk->ij", a, np.cross(b, c))
        dots = (la * lb * lc + np.einsum("ijk,ijk->ij", a, b) * lc
                + np.einsum("ijk,ijk->ij", b, c) * la + np.einsum("ijk,ijk->ij", c, a) * lb)
        out[s:s + chunk] = 2.0 * np.arctan2(det, dots).sum(axis=1) / (4.0 * np.pi)
    return out
