"""Frames per wall second of garments on the walking body, next to the
walking-avatar paper's 3-4 frames/s (Vassilev et al. 2001, Tables 1-2, 2001
hardware): each bundled walking scene run as a whole ``distcloth run``
process under mpiexec, one after the other.  A frame is 1/30 s of simulated
time.  Prints, over the walking steps (after the body's settle and
blend-in): simulated time, the steps' wall time (the sum of their stage
timers, every rank's slowest), frames per wall second, and where the time
goes (collision stages, solve, forces, the rest); and the whole process's
wall time.

    .venv/bin/python scripts/bench_walking.py [--ranks 2] [--scenes skirt_walking dress_walking ...]
    .venv/bin/python scripts/bench_walking.py --results out/dress_walking.h5 ...   # existing runs
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
SCENES = ("skirt_walking", "dress_walking", "dress_sleeves_walking", "tshirt_walking",
          "trousers_walking")
FRAME = 1.0 / 30.0
GROUPS = {"collisions": ("collision:bodies", "collision:response"),
          "solve": ("solve", "assembly"),
          "forces": None}          # every force:* stage


def run(scene: str, ranks: int, out: Path) -> float:
    cmd = [str(ROOT / "scripts" / "mpiexec.sh"), str(ranks), sys.executable, "-m", "distcloth",
           "run", str(ROOT / "configs" / f"{scene}.yaml"), "--output", str(out), "--overwrite",
           "--quiet"]
    env = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_", "PMIX_"))}
    t0 = time.perf_counter()
    p = subprocess.run(cmd, env=env, capture_output=True, text=True, cwd=ROOT)
    wall = time.perf_counter() - t0
    if p.returncode != 0:
        sys.exit(f"{scene}: run failed ({p.returncode}):\n{p.stderr[-2000:]}")
    return wall


def walk_start(config_text: str) -> float:
    """Scene time from which the body walks: its settle plus blend-in."""
    cfg = yaml.safe_load(config_text)
    anim = next(c["animation"] for c in cfg["colliders"] if c.get("animation"))
    return float(anim.get("settle", 0.0)) + float(anim.get("blend_in", 0.5))


def walking_figures(path: Path) -> dict:
    with h5py.File(path, "r") as f:
        n = int(f.attrs["steps_written"])
        t = f["diagnostics/time"][:n]
        h = f["diagnostics/step_size"][:n]
        walking = t > walk_start(f["config"][()].decode() if isinstance(f["config"][()], bytes)
                                 else str(f["config"][()]))
        # a stage switched off times NaN
        stages = {k: np.nan_to_num(f["diagnostics/stage_time"][k][:n][walking])
                  for k in f["diagnostics/stage_time"]}
        vertices = f["mesh/rest_positions"].shape[0]
        scene = f.attrs.get("scene", path.stem)
    total = sum(v.sum() for v in stages.values())
    split = {}
    for name, members in GROUPS.items():
        keys = [k for k in stages if k.startswith("force:")] if members is None else members
        split[name] = sum(stages[k].sum() for k in keys if k in stages)
    split["rest"] = total - sum(split.values())
    simulated = float(h[walking].sum())
    return {"scene": scene, "vertices": vertices, "steps": int(walking.sum()),
            "simulated": simulated, "wall": float(total),
            "frames_per_s": simulated / FRAME / total if total > 0 else float("nan"),
            "split": {k: v / total for k, v in split.items()}}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ranks", type=int, default=2)
    ap.add_argument("--scenes", nargs="+", default=list(SCENES))
    ap.add_argument("--results", nargs="+", type=Path, help="analyse these result files, run nothing")
    ap.add_argument("--out", type=Path, default=ROOT / "out" / "bench_walking")
    args = ap.parse_args(argv)
    rows = []
    if args.results:
        rows = [(walking_figures(p), float("nan")) for p in args.results]
    else:
        args.out.mkdir(parents=True, exist_ok=True)
        for scene in args.scenes:
            out = args.out / f"{scene}.h5"
            wall = run(scene, args.ranks, out)
            rows.append((walking_figures(out), wall))
            print(f"{scene}: {wall:.0f} s whole process", flush=True)
    load = os.getloadavg()[0]
    print(f"\n{args.ranks} ranks, 1-minute load average at the end {load:.2f} "
          f"({os.cpu_count()} cores)")
    print("| scene | vertices | walking steps | simulated s | wall s (steps) | frames/s (1/30 s) "
          "| collisions | solve | forces | rest | whole process s |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for r, wall in rows:
        s = r["split"]
        print(f"| {r['scene']} | {r['vertices']} | {r['steps']} | {r['simulated']:.2f} | "
              f"{r['wall']:.0f} | {r['frames_per_s']:.2f} | {100 * s['collisions']:.0f} % | "
              f"{100 * s['solve']:.0f} % | {100 * s['forces']:.0f} % | {100 * s['rest']:.0f} % | "
              f"{wall:.0f} |")
    print("\nVassilev et al. 2001 (walking avatars, 2001 hardware): 3-4 frames/s.")
    return 0


if __name__ == "__main__":
    sys.exit(main())
