#!/usr/bin/env python3
"""What strain limiting costs, and that it does not depend on the ranks.

Runs configs/hanging_square.yaml (soft: 10 N/m, hanging from its top edge)
with the strain_limiting effect through the public command

    scripts/mpiexec.sh RANKS .venv/bin/python -m distcloth run configs/hanging_square.yaml \\
        --set effects=[gravity,membrane,bending,strain_limiting] \\
        --set strain_limiting.method=METHOD --set strain_limiting.weft=BOUND ...

for each method on 1, 2 and 3 ranks (3 oversubscribed on a 2-core machine),
and prints per run, from the result file's diagnostics: the mean time per
step of the whole step and of the ``strain_limiting`` stage (rank 0's
timer), the limiter's share, its passes per step (mean, max), the time per
pass, the largest strain after limiting, and the largest distance of the
final frame from the 1-rank run's (rank invariance: the passes are Jacobi
passes with averaging, so only the order of floating-point sums differs;
with an implicit integrator (``--integrator backward_euler --step 0.01``)
the solve's tolerance and its partition-dependent block-Jacobi
preconditioner add their own differences).

Each pass is one neighbour exchange (x, or x and v) and one global
reduction; on one rank neither communicates, so the time per pass on 2 and
3 ranks against 1 rank shows what the ghost updates cost.

    .venv/bin/python scripts/bench_strain_limiting.py        # 41 x 41, symplectic Euler, h = 0.5 ms
    .venv/bin/python scripts/bench_strain_limiting.py --integrator backward_euler --step 0.01
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import h5py
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "configs" / "hanging_square.yaml"


def run(ranks, method, args, out):
    sets = [f"cloth.0.mesh.grid.resolution=[{args.resolution}, {args.resolution}]",
            f"time.end={args.end}", f"time.step={args.step}",
            f"time.integrator={args.integrator}", "output.preview=false",
            f"output.every={args.end}",
            "effects=[gravity, membrane, bending, strain_limiting]",
            f"strain_limiting.method={method}", f"strain_limiting.weft={args.bound}",
            f"strain_limiting.warp={args.bound}"]
    cmd = [str(ROOT / "scripts" / "mpiexec.sh"), str(ranks), sys.executable, "-m", "distcloth",
           "run", str(SCENE), "--quiet", "--output", str(out), "--overwrite"]
    for s in sets:
        cmd += ["--set", s]
    env = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_", "PMIX_"))}
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True)
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed:\n{proc.stderr[-2000:]}")
    with h5py.File(out, "r") as f:
        d = f["diagnostics"]
        # stages a run does not have read as NaN
        step = np.nansum([d[f"stage_time/{k}"][:] for k in d["stage_time"] if k != "output"],
                         axis=0)
        lim = d["stage_time/strain_limiting"][:]
        passes = d["limiter_passes"][:]
        return {"step_ms": 1e3 * float(np.mean(step)), "limit_ms": 1e3 * float(np.mean(lim)),
                "passes_mean": float(np.mean(passes)), "passes_max": int(np.max(passes)),
                "strain": float(np.max(d["limited_strain"][:])),
                "final": f["frames/positions"][-1][:]}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolution", type=int, default=41)
    ap.add_argument("--end", type=float, default=0.3, help="s: simulated time")
    ap.add_argument("--step", type=float, default=0.0005)
    ap.add_argument("--integrator", default="symplectic_euler")
    ap.add_argument("--bound", type=float, default=0.02, help="weft and warp bound")
    ap.add_argument("--ranks", type=int, nargs="+", default=[1, 2, 3])
    args = ap.parse_args()
    print(f"hanging square {args.resolution} x {args.resolution}, {args.integrator}, "
          f"h = {args.step} s, {args.end} s, weft/warp bound {args.bound}")
    print("| method | ranks | step (ms) | strain_limiting (ms) | share | passes/step (mean, max) "
          "| ms per pass | largest spring strain after (any class) | max |x - x(1 rank)| (m) |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    with tempfile.TemporaryDirectory() as tmp:
        for method in ("provot", "velocity"):
            first = None
            for ranks in args.ranks:
                r = run(ranks, method, args, Path(tmp) / f"{method}_{ranks}.h5")
                first = r["final"] if first is None else first
                per_pass = r["limit_ms"] / r["passes_mean"] if r["passes_mean"] else float("nan")
                print(f"| {method} | {ranks} | {r['step_ms']:.2f} | {r['limit_ms']:.2f} | "
                      f"{100 * r['limit_ms'] / r['step_ms']:.0f} % | {r['passes_mean']:.1f}, "
                      f"{r['passes_max']} | {per_pass:.3f} | {r['strain']:.4f} | "
                      f"{np.abs(r['final'] - first).max():.2g} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
