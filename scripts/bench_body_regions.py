"""What restricting a moving body's contact to the parts a garment can
reach saves (EG07 tutorial, Part 2 §2.3): the walking skirt
(configs/skirt_walking.yaml) run with the whole body in its contact and with
``colliders.0.animation.reach`` set, one run after the other, each a whole
``distcloth run`` process under mpiexec.  Prints the body triangles in
contact, the whole-process wall time, and the per-step time of the
collision stages and of the whole step over the walking steps (after the
body's settle and blend-in), and the ratios restricted / whole.

    .venv/bin/python scripts/bench_body_regions.py [--ranks 2] [--end 2.4] [--reach 0.1]
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import h5py
import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "configs" / "skirt_walking.yaml"
STAGES = ("collision:bodies", "collision:response")


def run(out: Path, ranks: int, end: float, reach) -> tuple[float, str]:
    cmd = [str(ROOT / "scripts" / "mpiexec.sh"), str(ranks), sys.executable, "-m", "distcloth",
           "run", str(SCENE), "--output", str(out), "--overwrite", "--set", f"time.end={end}",
           "--set", f"colliders.0.animation.reach={'null' if reach is None else reach}"]
    env = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_", "PMIX_"))}
    t0 = time.perf_counter()
    p = subprocess.run(cmd, env=env, capture_output=True, text=True, cwd=ROOT)
    wall = time.perf_counter() - t0
    if p.returncode != 0:
        sys.exit(f"run failed ({p.returncode}):\n{p.stderr[-2000:]}")
    region = next((ln.split("in contact: ")[1] for ln in p.stdout.splitlines() + p.stderr.splitlines()
                   if "in contact: " in ln), "whole body")
    return wall, region


def walking_stage_times(path: Path, walk_from: float) -> dict[str, float]:
    with h5py.File(path, "r") as f:
        n = int(f.attrs["steps_written"])
        g = f["diagnostics/stage_time"]
        walking = f["diagnostics/time"][:n] > walk_from
        times = {name: float(np.mean(g[name][:n][walking])) for name in STAGES}
        times["step"] = float(np.mean(sum(np.nan_to_num(g[k][:n]) for k in g)[walking]))
    return times


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ranks", type=int, default=2)
    parser.add_argument("--end", type=float, default=2.4, help="scene time to run to (s)")
    parser.add_argument("--reach", type=float, default=0.1)
    args = parser.parse_args()
    anim = yaml.safe_load(SCENE.read_text())["colliders"][0]["animation"]
    walk_from = anim["settle"] + anim["blend_in"]
    work = Path(tempfile.mkdtemp(prefix="regions-"))
    rows = {}
    for label, reach in (("whole body", None), (f"reach {args.reach:g} m", args.reach)):
        out = work / f"{'whole' if reach is None else 'reach'}.h5"
        wall, region = run(out, args.ranks, args.end, reach)
        rows[label] = (wall, region, walking_stage_times(out, walk_from))
    print(f"walking skirt, {args.ranks} ranks, to t = {args.end:g} s "
          f"(walking steps: t > {walk_from:g} s)")
    for label, (wall, region, st) in rows.items():
        print(f"  {label:12s} process {wall:6.1f} s; per walking step: "
              + ", ".join(f"{k} {1e3 * v:.1f} ms" for k, v in st.items()) + f"; contact: {region}")
    (w0, _, s0), (w1, _, s1) = rows.values()
    print("  ratio restricted/whole: process {:.2f}, ".format(w1 / w0)
          + ", ".join(f"{k} {s1[k] / s0[k]:.2f}" for k in s0))


if __name__ == "__main__":
    main()
