#!/usr/bin/env python3
"""Collision detection and response (CD&R) against the rest of the step:
the columns of Vassilev et al. 2001, Table 1, for the bundled collision scenes at
several resolutions, and BVH against image-space on the same body.

Each case runs a scene through the public command

    scripts/mpiexec.sh RANKS .venv/bin/python -m distcloth run SCENE --set ...

for a fixed number of steps (the first WARMUP steps, which include numba
compilation and the cloth's fall before contact, are excluded by taking the
stage times of the last steps from the HDF5 diagnostics) and reports per
step: the whole step, CD&R (stages collision:bodies and collision:response:
contact detection, friction, CCD impulses, impact zones, fail-safe) and CS
(everything else: forces, assembly, the solve with the contact constraints
in it), in ms and as shares, the mean contact count, the largest penetration
and, with self-collision, the largest self-intersection count.

    .venv/bin/python scripts/bench_collisions.py              # the table (~15 min)
    .venv/bin/python scripts/bench_collisions.py --quick      # one small case per scene
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

# (label, scene, resolution key, resolutions, end time (s), extra --set)
CASES = [
    ("tablecloth on sphere", "tablecloth_sphere.yaml", "cloth.0.mesh.grid.resolution",
     [[21, 21], [41, 41], [81, 81]], 0.8, []),
    ("ribbon, ramps + self", "ribbon.yaml", "cloth.0.mesh.grid.resolution",
     [[21, 51], [41, 101]], 0.8, []),
    ("cloth on body (BVH)", "cloth_on_body.yaml", "cloth.0.mesh.grid.resolution",
     [[33, 33], [65, 65]], 0.5, ["effects=[gravity, membrane, bending, damping, collisions]"]),
    ("cloth on body (image 512²)", "cloth_on_body.yaml", "cloth.0.mesh.grid.resolution",
     [[33, 33], [65, 65]], 0.5, ["effects=[gravity, membrane, bending, damping, collisions]",
                                 "colliders.0.method=image", "colliders.0.resolution=[512, 512]",
                                 "colliders.0.axis=y"]),
]
CDR = ("collision:bodies", "collision:response")


def run_case(scene, res_key, res, end, extra, ranks, warmup_fraction):
    import h5py
    import numpy as np
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "bench.h5"
        sets = [f"{res_key}={res}", f"time.end={end}", "output.preview=false",
                f"output.every={end}"] + extra
        cmd = [str(ROOT / "scripts" / "mpiexec.sh"), str(ranks), sys.executable, "-m", "distcloth",
               "run", str(ROOT / "configs" / scene), "--quiet", "--output", str(out)]
        for s in sets:
            cmd += ["--set", s]
        env = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_", "PMIX_"))}
        env["PYTHONPATH"] = str(ROOT)
        p = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=ROOT)
        if p.returncode != 0:
            sys.stderr.write(p.stderr[-3000:])
            return None
        with h5py.File(out, "r") as f:
            d = f["diagnostics"]
            st = d["stage_time"]
            n = d["step"].shape[0]
            k0 = int(warmup_fraction * n)
            per = {name: st[name][k0:] for name in st}
            total = sum(per.values())
            cdr = sum(per[s] for s in CDR if s in per)
            nv = f["mesh/rest_positions"].shape[0] if "mesh/rest_positions" in f else None
            si = d["self_intersections"][k0:] if "self_intersections" in d else None
            return {
                "vertices": nv, "steps": n - k0,
                "step_ms": 1e3 * float(np.mean(total)), "cdr_ms": 1e3 * float(np.mean(cdr)),
                "contacts": float(np.nanmean(d["contacts"][k0:])),
                "penetration": float(np.nanmax(d["max_penetration"][k0:])),
                "self_intersections": (float(np.nanmax(si)) if si is not None and
                                       np.isfinite(si).any() else None),
            }


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--ranks", type=int, default=2)
    ap.add_argument("--quick", action="store_true", help="the smallest resolution of each scene")
    ap.add_argument("--warmup-fraction", type=float, default=0.25,
                    help="leading share of the steps left out (compilation, free fall)")
    args = ap.parse_args()
    print(f"{args.ranks} ranks; stage times summed over the ranks' rank-0 view, last "
          f"{100 * (1 - args.warmup_fraction):.0f} % of the steps\n")
    print("| scene | vertices | step (ms) | CD&R (ms) | CS (ms) | CD&R % | CS % | contacts | "
          "max penetration (mm) | self-intersections |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for label, scene, key, resolutions, end, extra in CASES:
        for res in (resolutions[:1] if args.quick else resolutions):
            r = run_case(scene, key, res, end, extra, args.ranks, args.warmup_fraction)
            if r is None:
                print(f"| {label} | {res} | failed |")
                continue
            cs = r["step_ms"] - r["cdr_ms"]
            nv = r["vertices"] or res[0] * res[1]
            si = "" if r["self_intersections"] is None else f"{r['self_intersections']:.0f}"
            print(f"| {label} | {nv} | {r['step_ms']:.1f} | {r['cdr_ms']:.1f} | {cs:.1f} | "
                  f"{100 * r['cdr_ms'] / r['step_ms']:.1f} | {100 * cs / r['step_ms']:.1f} | "
                  f"{r['contacts']:.0f} | {1e3 * r['penetration']:.3f} | {si} |", flush=True)


if __name__ == "__main__":
    main()
