#!/usr/bin/env python3
"""A garment on a moving body, frame by frame: how close to and how deep
into the body its vertices get, whether its triangles cross, how far it
stretches.  Checks independent of the simulator's contact code (the same
as scripts/garment_at_rest.py, on every k-th frame instead of the last):
signed distance to the body as it was at that frame (generalized winding
number), vertices inside and deeper than 10 % of the contact offset d,
crossing triangle pairs (exact oracle), largest principal strain against
the panels' rest shapes (max and 99th percentile).

    .venv/bin/python scripts/garment_in_motion.py OUT.h5 [--every 5]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import h5py
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from garment_at_rest import (DEEP_FRACTION, _closed_mesh, _config, _contact_offsets,  # noqa: E402
                             main_and_sewing, principal_strain, self_intersections,
                             welded_rest_triangles)
from distcloth.io.h5read import read_result  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("file", metavar="OUT.h5")
    ap.add_argument("--every", type=int, default=5, help="every k-th frame")
    args = ap.parse_args(argv)
    r = read_result(args.file)
    cfg = _config(r["config"] or "")
    offsets = _contact_offsets(cfg)
    tri = r["triangles"].astype(np.int64)
    sew = read_result(main_and_sewing(args.file)[1], positions=False)
    with h5py.File(args.file, "r") as f:
        pv = f["garment/pattern_vertex"][...].astype(np.int64)
    rest, _ = welded_rest_triangles(sew["triangles"].astype(np.int64), sew["rest_positions"],
                                    pv, tri)
    (name, body), = [(k, c) for k, c in r["colliders"].items() if c["shape"] == "mesh"]
    d = offsets.get(name, offsets[None])
    print(f"{args.file}: {r['positions'].shape[1]} vertices, contact offset d = {1e3 * d:.1f} mm")
    print(f"{'t (s)':>7} {'min sd (mm)':>12} {'inside':>7} {'deep':>5} {'crossings':>10} "
          f"{'strain max %':>13} {'p99 %':>6}")
    worst = {"sd": np.inf, "inside": 0, "deep": 0, "cross": 0, "strain": 0.0}
    frames = list(range(0, r["positions"].shape[0], args.every))
    if frames[-1] != r["positions"].shape[0] - 1:
        frames.append(r["positions"].shape[0] - 1)
    for k in frames:
        x = r["positions"][k]
        bx = body["positions"][min(k, body["positions"].shape[0] - 1)]
        sd = _closed_mesh(bx, body["triangles"]).signed_distance(x)
        cross = int(self_intersections(x, tri).shape[0])
        s = principal_strain(rest, x[tri])
        s = s[np.isfinite(s)]
        inside, deep = int((sd < 0).sum()), int((sd < -DEEP_FRACTION * d).sum())
        print(f"{r['time'][k]:7.3f} {1e3 * sd.min():12.2f} {inside:7d} {deep:5d} {cross:10d} "
              f"{100 * s.max():13.1f} {100 * np.percentile(s, 99):6.1f}")
        worst = {"sd": min(worst["sd"], sd.min()), "inside": max(worst["inside"], inside),
                 "deep": max(worst["deep"], deep), "cross": max(worst["cross"], cross),
                 "strain": max(worst["strain"], s.max())}
    print(f"worst over {len(frames)} frames: closest {1e3 * worst['sd']:.2f} mm, up to "
          f"{worst['inside']} inside ({worst['deep']} deeper than {DEEP_FRACTION:g} d), up to "
          f"{worst['cross']} crossing pairs, strain up to {100 * worst['strain']:.1f} %")
    return 0


if __name__ == "__main__":
    sys.exit(main())
