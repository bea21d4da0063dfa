"""Body-collision query cost and accuracy: BVH closest point
(``MeshProximity``) against Vassilev et al. 2001's image-space maps (``ImageSpaceCollider``)
on the shipped torso.

Cloth-like points: N points sampled uniformly (by area) on the torso
surface and moved along the face normal by a uniform offset in
[-1 cm, +3 cm] (cloth hugging the body, a few points pushed in).  For each
variant the median wall time of several repetitions (after a warm-up call
that JIT-compiles) is reported; for the image-space collider the render
(all six maps; paid once for a static body, every step for a moving one;
independent of N, so measured once per map size) and the lookup
separately.  Accuracy, with the BVH result as reference: the fraction of
points whose contact verdict (phi < 5 mm) differs, split into contacts the
maps miss and contacts they add; "unresolved share" is the part of the
differing points whose pixel is not covered by the body (beside the
silhouette) or whose map normal is steeper than 60 degrees to the image
plane; the last column is the differing fraction among the other
("resolved") points.  The maps view the torso front/back (axis 1, as in
Vassilev et al. 2001).  Timings are wall clock on a shared machine: expect noise.

    .venv/bin/python scripts/bench_body_collision.py [--n 10000 40000]
        [--sizes 128 256 512 1024] [--reps 7] [--axis 1]
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from distcloth.collision.colliders import load_mesh_collider  # noqa: E402
from distcloth.collision.image_collider import ImageSpaceCollider  # noqa: E402
from distcloth.collision.mesh_query import MeshProximity  # noqa: E402

CONTACT = 0.005        # m: contact distance of the verdict
MAX_DISTANCE = 0.05    # m: query cut-off, beyond the point shell


def cloth_points(collider, n: int, seed: int = 0) -> np.ndarray:
    x, tri = collider.vertices(0.0), collider.triangles
    a, b, c = (x[tri[:, k]] for k in range(3))
    normal = np.cross(b - a, c - a)
    area = np.linalg.norm(normal, axis=1)
    normal /= area[:, None]
    rng = np.random.default_rng(seed)
    f = rng.choice(tri.shape[0], n, p=area / area.sum())
    r = rng.random((n, 2))
    flip = r.sum(axis=1) > 1
    r[flip] = 1 - r[flip]
    offset = rng.uniform(-0.01, 0.03, n)
    return (a[f] + r[:, :1] * (b - a)[f] + r[:, 1:] * (c - a)[f]
            + offset[:, None] * normal[f])


def median_time(fn, reps: int) -> float:
    fn()                                           # warm-up (JIT, caches)
    times = []
    for _ in range(reps):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, nargs="+", default=[10_000, 40_000])
    ap.add_argument("--sizes", type=int, nargs="+", default=[128, 256, 512, 1024])
    ap.add_argument("--reps", type=int, default=7)
    ap.add_argument("--axis", type=int, default=1)
    args = ap.parse_args(argv)

    collider = load_mesh_collider(ROOT / "configs" / "meshes" / "torso.obj")
    t0 = time.perf_counter()
    bvh = MeshProximity(collider)
    build = time.perf_counter() - t0
    print(f"torso: {collider.n_vertices} vertices, {collider.triangles.shape[0]} triangles; "
          f"MeshProximity build {1e3 * build:.1f} ms (incl. first-call JIT); contact distance "
          f"{1e3 * CONTACT:.0f} mm, max_distance {1e3 * MAX_DISTANCE:.0f} mm, view axis {args.axis}, "
          f"median of {args.reps}\n")
    print("| N | method | map | Δx–y Eq. 14 (mm) | render (ms) | lookup/query (ms) "
          "| render + lookup (ms) | verdict differs (%) | missed (%) | extra (%) | unresolved share "
          "| differs among resolved (%) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    # render cost does not depend on the query points: measured once per map size
    colliders, render_ms = {}, {}
    for size in args.sizes:
        isc = colliders[size] = ImageSpaceCollider(collider, size, axis=args.axis)

        def render():
            isc.resolution = size                  # drops the cached maps
            isc.maps(0.0)

        render_ms[size] = 1e3 * median_time(render, args.reps)
    for n in args.n:
        pts = cloth_points(collider, n)
        ref = bvh.query(pts, 0.0, MAX_DISTANCE)[0] < CONTACT
        q = median_time(lambda: bvh.query(pts, 0.0, MAX_DISTANCE), args.reps)
        print(f"| {n} | BVH closest point | – | exact | – | {1e3 * q:.1f} | {1e3 * q:.1f} "
              f"| (reference: {100 * ref.mean():.1f} % touching) | | | | |")
        for size in args.sizes:
            isc = colliders[size]
            q = 1e3 * median_time(lambda: isc.query(pts, 0.0, MAX_DISTANCE), args.reps)
            phi, normal, _ = isc.query(pts, 0.0, MAX_DISTANCE)
            touch = phi < CONTACT
            differs = touch != ref
            unresolved = ~np.isfinite(phi) | (np.abs(normal[:, args.axis]) < 0.5)
            share = (differs & unresolved).sum() / max(differs.sum(), 1)
            dx = 1e3 * float(np.max(isc.error_bound))
            r = render_ms[size]
            print(f"| {n} | image space | {size}² | {dx:.2f} | {r:.1f} | {q:.1f} | {r + q:.1f} "
                  f"| {100 * differs.mean():.2f} | {100 * (ref & ~touch).mean():.2f} "
                  f"| {100 * (touch & ~ref).mean():.2f} | {share:.2f} "
                  f"| {100 * differs[~unresolved].mean():.2f} |")

if __name__ == "__main__":
    main()
