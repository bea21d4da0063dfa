"""The rigged body: skeleton fitted to a body mesh, bone-heat weights, the
candy-wrapper comparison of linear blend and dual-quaternion skinning (a
wrist twisted about the forearm, EG07 tutorial Part 2 §2.2.2), and the cost
of skinning one frame.

    .venv/bin/python scripts/body_rig.py [--mesh configs/meshes/mean_all.obj] [--angle 90]
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from distcloth.body.skeleton_fit import fit_skeleton
from distcloth.body.skinning import candy_wrapper, dual_quaternion, linear_blend
from distcloth.body.skinning_weights import skinning_weights
from distcloth.scene.meshio import read_mesh


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mesh", default="configs/meshes/mean_all.obj")
    parser.add_argument("--angle", type=float, default=90.0)
    args = parser.parse_args()
    x, tri = read_mesh(args.mesh)
    t0 = time.perf_counter()
    skel = fit_skeleton(x, tri)
    t1 = time.perf_counter()
    idx, w = skinning_weights(x, tri, skel)
    t2 = time.perf_counter()
    print(f"body: {x.shape[0]} vertices, {tri.shape[0]} triangles")
    print(f"skeleton fit {t1 - t0:.2f} s, bone-heat weights {t2 - t1:.2f} s")
    for name, p in zip(skel.names, skel.rest):
        print(f"  {name:11s} {p[0]:+.3f} {p[1]:+.3f} {p[2]:+.3f}")
    J = len(skel.names)
    R, t = np.repeat(np.eye(3)[None], J, axis=0), np.zeros((J, 3))
    for f, fn in (("lbs", linear_blend), ("dqs", dual_quaternion)):
        fn(x, idx, w, R, t)
        t3 = time.perf_counter()
        for _ in range(10):
            fn(x, idx, w, R, t)
        print(f"{f}: {(time.perf_counter() - t3) / 10 * 1e3:.1f} ms per frame")
    print(f"candy wrapper, wrist twisted {args.angle:g} degrees (relative to rest):")
    for side in ("l", "r"):
        c = candy_wrapper(x, tri, skel, idx, w, args.angle, side=side)
        print(f"  {side}: forearm-to-palm volume LBS {c['lbs_volume_ratio']:.4f} "
              f"DQS {c['dqs_volume_ratio']:.4f}; wrist section area LBS "
              f"{c['lbs_wrist_area_ratio']:.3f} DQS {c['dqs_wrist_area_ratio']:.3f}; "
              f"whole body LBS {c['lbs_body_volume'] / c['rest_body_volume']:.5f} "
              f"DQS {c['dqs_body_volume'] / c['rest_body_volume']:.5f}")


if __name__ == "__main__":
    main()
