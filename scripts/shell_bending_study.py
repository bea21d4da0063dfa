"""Linear heavy cantilever with the per-triangle curvature bending (bending_shell.py),
with and without a curvature-jump penalty between neighbouring interior triangles.

A study of the hourglass softness documented in distcloth/physics/bending_shell.py:
the isometric shell energy (z only, small load: linear theory), clamped at x <= 0,
solved directly (scipy sparse LU), tip deflection against the clamp-corrected
elastica of tests/test_elastica.py.  The penalty 1/2 gamma B A_e |K_T1 - K_T2|_F^2
(A_e = (A_T1 + A_T2)/3, interior edges whose triangles have all three hinges) is a
prototype here, not a model of distcloth.

    .venv/bin/python scripts/shell_bending_study.py
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spl

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
import test_elastica as te  # noqa: E402
from distcloth.physics.bending_shell import shell_rest_geometry, shell_stencils  # noqa: E402
from distcloth.scene.grid import grid_triangles, grid_vertices  # noqa: E402

L, B, Q = te.L, 1.0, 1.0


def interior_edge_triangles(tri):
    src, dst = tri[:, [1, 2, 0]].ravel(), tri[:, [2, 0, 1]].ravel()
    n = tri.max() + 1
    key = np.minimum(src, dst) * n + np.maximum(src, dst)
    o = np.argsort(key, kind="stable")
    k = key[o]
    st = np.flatnonzero(np.r_[True, k[1:] != k[:-1]])
    two = st[np.diff(np.r_[st, len(k)]) == 2]
    return o[two] // 3, o[two + 1] // 3


def tip_deflection(x, tri, gamma, free_edge):
    st, pr = shell_stencils(tri)
    Qm, _, W, A, K3 = shell_rest_geometry(x, st, pr, B, free_edge=free_edge)
    n = len(x)
    H6 = np.einsum("tia,tij,tjb->tab", W, Qm, W)
    rows = [np.repeat(st[:, :, None], 6, 2).ravel()]
    cols = [np.repeat(st[:, None, :], 6, 1).ravel()]
    vals = [H6.ravel()]
    if gamma:
        t1, t2 = interior_edge_triangles(tri)
        keep = pr[t1].all(1) & pr[t2].all(1)
        t1, t2 = t1[keep], t2[keep]
        G = np.einsum("taj,tjb->tab", K3, W)           # 3-D curvature of the stencil heights
        idx = np.concatenate([st[t1], st[t2]], 1)
        D = np.concatenate([G[t1], -G[t2]], 2)
        Ae = (A[t1] + A[t2]) / 3
        Hs = gamma * B * Ae[:, None, None] * np.einsum("eka,ekb->eab", D, D)
        rows.append(np.repeat(idx[:, :, None], 12, 2).ravel())
        cols.append(np.repeat(idx[:, None, :], 12, 1).ravel())
        vals.append(Hs.ravel())
    H = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                      shape=(n, n))
    area = np.zeros(n)
    np.add.at(area, tri.ravel(), np.repeat(A / 3, 3))
    free = x[:, 0] > 1e-9
    z = np.zeros(n)
    z[free] = spl.spsolve(H[free][:, free].tocsc(), -Q * area[free])
    return -z[x[:, 0] > L - 1e-9].mean()


def mesh(kind, h):
    if kind == "delaunay":
        return te.strip_mesh(h)
    nx, ny = int(round(L / h)), int(round(te.W / h)) + 1
    x = grid_vertices((L + h, te.W), (nx + 2, ny))
    x[:, 0] += -h - x[:, 0].min()
    return x, grid_triangles((nx + 2, ny), kind)


def main():
    spacings = (0.01, 0.005, 0.0025)
    print("| gamma | free edge | " + " | ".join(
        f"{k} h={h * 1e3:g} mm" for k in ("regular", "alternating", "delaunay") for h in spacings)
        + " |")
    print("|---:|---|" + "---:|" * 9)
    for gamma in (0.0, 1.0, 3.0, 10.0):
        for fe in ("zero_curvature", "min_norm"):
            cells = []
            for kind in ("regular", "alternating", "delaunay"):
                for h in spacings:
                    d = tip_deflection(*mesh(kind, h), gamma, fe)
                    ref = te.heavy_elastica(Q, B, L, clamp=h / 2, unloaded=h)
                    cells.append(f"{100 * (d / ref - 1):+.2f} %")
            print(f"| {gamma:g} | {fe} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
