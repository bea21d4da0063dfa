"""Check the start placement of sewing patterns around the bundled body.

    .venv/bin/python scripts/check_garment_start.py [PATTERN...] [--edge 0.03]
        [--body configs/meshes/mean_all.obj] [--clearance 0.015]

Default patterns: the four in configs/garments (skirt, tshirt, trousers,
dress).  Each is meshed at ``--edge`` (m) and checked against the body mesh
(y up, metres, as the patterns are placed):

* inside: vertices inside the body, by the generalized winding number
  (Jacobson et al. 2013: the sum of the solid angles the body's triangles
  subtend, van Oosterom and Strackee's formula), exact for a closed body and
  still meaningful for a leaky one; points outside the body's box skip it;
* clearance: the smallest distance between garment and body surfaces, the
  smaller of garment vertex -> body triangles and body vertex -> garment
  triangles (BVH closest points of collision/mesh_query.py), and the number
  of garment vertices closer than ``--clearance``;
* panel crossings: intersecting triangle pairs of different panels;
* outward: the share of triangles whose outside (counter-clockwise side)
  faces away from the nearest body point: the panels' right side out;
* oriented manifold: the vertices of every stitch merged (union-find on the
  pairs), no triangle collapses, every edge is used by at most two
  triangles and then in opposite directions; the boundary loops and the
  Euler characteristic give the genus (0 for every garment);
* per stitch: the start distance of the paired vertices (min / median /
  max) and how many straight paths between them pass through the body
  (the sewing springs pull along them; the cloth there would have to go
  around, or be caught on, the body).
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np
from numba import njit
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

# the scene package first: collision.colliders and scene import each other, and
# entering through scene is the order that resolves
from distcloth.scene.meshio import read_mesh                # noqa: E402
from distcloth.collision.colliders import MeshCollider      # noqa: E402
from distcloth.collision.mesh_query import MeshProximity    # noqa: E402
from distcloth.collision.tritri import self_intersecting_pairs  # noqa: E402
from distcloth.garment import load_pattern, mesh_pattern    # noqa: E402

DEFAULT_PATTERNS = [ROOT / "configs" / "garments" / f"{n}.yaml"
                    for n in ("skirt", "tshirt", "trousers", "dress")]
DEFAULT_BODY = ROOT / "configs" / "meshes" / "mean_all.obj"
SEGMENT_SAMPLES = 9        # interior points tested on each stitch pair's straight path


# ------------------------------------------------------------------ body queries

@njit(cache=True)
def _winding_kernel(points, a, b, c, out):
    """Generalized winding number of every point: sum over triangles of the
    signed solid angle / 4 pi, the solid angle by van Oosterom and Strackee
    (tan(omega / 2) = det / (|a||b||c| + (a.b)|c| + (b.c)|a| + (c.a)|b|))."""
    for i in range(points.shape[0]):
        px, py, pz = points[i, 0], points[i, 1], points[i, 2]
        total = 0.0
        for t in range(a.shape[0]):
            ax, ay, az = a[t, 0] - px, a[t, 1] - py, a[t, 2] - pz
            bx, by, bz = b[t, 0] - px, b[t, 1] - py, b[t, 2] - pz
            cx, cy, cz = c[t, 0] - px, c[t, 1] - py, c[t, 2] - pz
            la = math.sqrt(ax * ax + ay * ay + az * az)
            lb = math.sqrt(bx * bx + by * by + bz * bz)
            lc = math.sqrt(cx * cx + cy * cy + cz * cz)
            det = (ax * (by * cz - bz * cy) - ay * (bx * cz - bz * cx)
                   + az * (bx * cy - by * cx))
            den = (la * lb * lc + (ax * bx + ay * by + az * bz) * lc
                   + (bx * cx + by * cy + bz * cz) * la + (cx * ax + cy * ay + cz * az) * lb)
            total += math.atan2(det, den)
        out[i] = total / (2.0 * math.pi)


class Body:
    def __init__(self, path: Path):
        self.vertices, self.triangles = read_mesh(str(path))
        self.vertices = np.ascontiguousarray(self.vertices, dtype=np.float64)
        self.triangles = np.ascontiguousarray(self.triangles, dtype=np.int64)
        corners = self.vertices[self.triangles]
        self._a, self._b, self._c = (np.ascontiguousarray(corners[:, k]) for k in range(3))
        self.lo, self.hi = self.vertices.min(axis=0), self.vertices.max(axis=0)
        self.proximity = MeshProximity(MeshCollider.static(self.vertices, self.triangles))

    def inside(self, points: np.ndarray) -> np.ndarray:
        """True where the winding number rounds to +-1 (sign free of the mesh's
        orientation); points outside the bounding box are outside."""
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        result = np.zeros(points.shape[0], bool)
        box = np.all((points >= self.lo) & (points <= self.hi), axis=1)
        todo = np.ascontiguousarray(points[box])
        w = np.empty(todo.shape[0])
        _winding_kernel(todo, self._a, self._b, self._c, w)
        result[box] = np.abs(w) > 0.5
        return result

    def closest(self, points: np.ndarray):
        """(closest body point, distance) of every point."""
        face, w, dist = self.proximity.closest(points)
        return np.einsum("ij,ijk->ik", w, self.vertices[self.triangles[face]]), dist


# ------------------------------------------------------------------ garment checks

def merged_topology(mesh) -> dict:
    """Merge each stitch's paired vertices and check the merged triangle mesh."""
    n = mesh.positions.shape[0]
    pairs = np.concatenate([s.pairs for s in mesh.seams]) if mesh.seams else np.zeros((0, 2), int)
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    tri = label[mesh.triangles]
    collapsed = int(np.sum((tri[:, 0] == tri[:, 1]) | (tri[:, 1] == tri[:, 2])
                           | (tri[:, 2] == tri[:, 0])))
    directed = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    _, dcount = np.unique(directed, axis=0, return_counts=True)
    same_direction = int(np.sum(dcount > 1))          # an edge walked twice the same way
    undirected, ucount = np.unique(np.sort(directed, axis=1), axis=0, return_counts=True)
    over_used = int(np.sum(ucount > 2))
    # boundary: directed edges whose reverse is absent; loops by following them
    keys = directed[:, 0] * n + directed[:, 1]
    boundary = directed[~np.isin(directed[:, 1] * n + directed[:, 0], keys)]
    nxt, branching = {}, 0
    for u, v in boundary:
        branching += u in nxt
        nxt[u] = v
    loops, seen = 0, set()
    for start in nxt:
        if start in seen:
            continue
        loops += 1
        u = start
        while u not in seen:
            seen.add(u)
            u = nxt.get(u, start)
    v_used = np.unique(tri).size
    euler = v_used - undirected.shape[0] + tri.shape[0]
    ok = collapsed == 0 and same_direction == 0 and over_used == 0 and branching == 0
    return {"ok": ok, "collapsed": collapsed, "same_direction": same_direction,
            "over_used": over_used, "branching": branching, "loops": loops, "euler": euler,
            "genus": (2 - euler - loops) / 2, "merged_vertices": v_used}


def panel_crossings(mesh) -> int:
    """Intersecting triangle pairs that belong to different panels.  Paired
    vertices that already coincide (a seam closed in the file, as GarmentCode's
    centre front) are merged first, so panels sharing them only touch."""
    x, tri = mesh.positions, mesh.triangles
    n = x.shape[0]
    pairs = np.concatenate([s.pairs for s in mesh.seams]) if mesh.seams else np.zeros((0, 2), int)
    same = pairs[np.linalg.norm(x[pairs[:, 0]] - x[pairs[:, 1]], axis=1) < 1e-9]
    graph = coo_matrix((np.ones(len(same)), (same[:, 0], same[:, 1])), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    merged = np.empty((label.max() + 1, 3))
    merged[label] = x
    owner = np.concatenate([np.full(p.triangles.shape[0], k) for k, p in enumerate(mesh.panels)])
    hits = self_intersecting_pairs(merged, label[tri])
    return int(np.sum(owner[hits[:, 0]] != owner[hits[:, 1]])) if len(hits) else 0


def outward_share(mesh, body: Body) -> float:
    """Share of triangles whose outside normal points away from the nearest body point."""
    x, tri = mesh.positions, mesh.triangles
    p = x[tri]
    normal = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    centre = p.mean(axis=1)
    near, _ = body.closest(centre)
    return float(np.mean(np.einsum("ij,ij->i", normal, centre - near) > 0.0))


def check(path: Path, body: Body, edge: float, clearance: float) -> dict:
    t0 = time.perf_counter()
    pattern = load_pattern(str(path))
    mesh = mesh_pattern(pattern, edge)
    x, tri = mesh.positions, mesh.triangles
    inside = body.inside(x)
    _, dist = body.closest(x)
    back = MeshProximity(MeshCollider.static(x, tri)).closest(body.vertices)[2]
    stitches = []
    for s in mesh.seams:
        a, b = x[s.pairs[:, 0]], x[s.pairs[:, 1]]
        gap = np.linalg.norm(a - b, axis=1)
        t = np.arange(1, SEGMENT_SAMPLES + 1) / (SEGMENT_SAMPLES + 1)
        samples = a[:, None, :] + t[None, :, None] * (b - a)[:, None, :]
        through = body.inside(samples.reshape(-1, 3)).reshape(len(gap), -1).any(axis=1)
        stitches.append({"name": f"{_side(s.stitch.a)} ~ {_side(s.stitch.b)}",
                         "label": s.stitch.label or "", "pairs": len(gap),
                         "gap": (gap.min(), np.median(gap), gap.max()),
                         "through": int(through.sum())})
    return {"name": pattern.name or path.stem, "file": path.name, "vertices": x.shape[0],
            "triangles": tri.shape[0], "inside": int(inside.sum()),
            "clearance": float(min(dist.min(), back.min())),
            "near": int(np.sum(dist < clearance)), "crossings": panel_crossings(mesh),
            "outward": outward_share(mesh, body), "topology": merged_topology(mesh),
            "stitches": stitches, "seconds": time.perf_counter() - t0}


def _side(side) -> str:
    edges = f"{side.edges[0]}-{side.edges[-1]}" if len(side.edges) > 1 else f"{side.edges[0]}"
    return f"{side.panel}:{edges}"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("patterns", nargs="*", type=Path, default=DEFAULT_PATTERNS)
    parser.add_argument("--edge", type=float, default=0.03, help="target edge length, m")
    parser.add_argument("--body", type=Path, default=DEFAULT_BODY)
    parser.add_argument("--clearance", type=float, default=0.015,
                        help="vertices closer to the body than this (m) are counted")
    args = parser.parse_args(argv)
    body = Body(args.body)
    results = [check(p, body, args.edge, args.clearance) for p in args.patterns]
    cm = 100.0
    print(f"body {args.body.name}: {body.vertices.shape[0]} vertices, "
          f"{body.triangles.shape[0]} triangles; edge {args.edge * cm:g} cm\n")
    print(f"| garment | vertices | triangles | inside body | clearance (cm) | "
          f"< {args.clearance * cm:g} cm | panel crossings | outward | oriented manifold | "
          f"boundary loops | genus |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---|---:|---:|")
    for r in results:
        t = r["topology"]
        flaws = ", ".join(f"{k} {t[k]}" for k in ("collapsed", "same_direction", "over_used",
                                                   "branching") if t[k])
        print(f"| {r['file']} | {r['vertices']} | {r['triangles']} | {r['inside']} | "
              f"{r['clearance'] * cm:.2f} | {r['near']} | {r['crossings']} | "
              f"{100 * r['outward']:.1f} % | {'yes' if t['ok'] else 'NO: ' + flaws} | "
              f"{t['loops']} | {t['genus']:g} |")
    for r in results:
        print(f"\n{r['file']}: start distance of the paired vertices (cm); 'through' = "
              f"pairs whose straight path crosses the body ({r['seconds']:.1f} s)\n")
        print("| # | stitch | label | pairs | min | median | max | through |")
        print("|---:|---|---|---:|---:|---:|---:|---:|")
        for k, s in enumerate(r["stitches"]):
            lo, med, hi = (cm * g for g in s["gap"])
            print(f"| {k} | {s['name']} | {s['label']} | {s['pairs']} | {lo:.1f} | {med:.1f} | "
                  f"{hi:.1f} | {s['through']} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
