#!/usr/bin/env python3
"""Time per implicit step and its split, for square cloths of ~10k, 100k, 400k vertices.

The material of Volino and Magnenat-Thalmann 2007, Fig. 4 (0.1 kg/m^2,
10 N/m) on a 0.5 m square pinned along one edge, backward Euler with 20 ms
steps.  Every solver is compared at the same
true relative residual (ksp_rtol 1e-5 with -ksp_norm_type unpreconditioned).

    .venv/bin/python scripts/bench_step.py                  # the full table (slow: ~20 min)
    .venv/bin/python scripts/bench_step.py --sizes 10000    # one size

The driver launches itself under ``scripts/mpiexec.sh N`` for 1 and 2 ranks
and prints a Markdown table; parallel efficiency is T(1) / (2 T(2)) from
runs of the same invocation.  JIT compilation and set-up are excluded: the
first steps are warm-up, only the following ones are timed.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path

from distcloth.config.schema import BENDING_MODELS
from distcloth.linalg.presets import PRECONDITIONERS

ROOT = Path(__file__).resolve().parents[1]
FE_BENDING_MODELS = [m for m in BENDING_MODELS if m != "flexion"]   # flexion: mass-spring only

def _cg(name, **linear_system):
    """CG with one of distcloth's named preconditioners (distcloth/linalg/presets.py,
    where the AMG settings tuned on the 100k case live): the scene's solver: and
    linear_system: sections."""
    options, mat_type = PRECONDITIONERS[name]
    return {"ksp_type": "cg", **options}, {"mat_type": mat_type, **linear_system}


SOLVERS = {"bjacobi+sgs": _cg("bjacobi_sgs"), "gamg": _cg("gamg"), "hypre": _cg("hypre")}
# not in the default sweep: GAMG rebuilt only every 5th solve and reused in between
EXTRA_SOLVERS = {
    "gamg-rebuild5": _cg("gamg", pc_rebuild_every=5),
    # GAMG dropping the couplings weaker than 0.02 from its aggregation graph:
    # the preset until contact at 317² showed its dense coarse levels
    # (docs/benchmarks.md, "GAMG's aggregation threshold on the stiff membrane")
    "gamg-threshold0.02": ({**_cg("gamg")[0], "pc_gamg_threshold": 0.02}, _cg("gamg")[1]),
    # EG07 tutorial, Part 1 §5.7: the reference preconditioner with a float32 matrix
    # (numba, Python PC)
    "sgs32": _cg("sgs32"),
}


def worker(args):
    from distcloth.linalg.petsc import init_petsc
    init_petsc([])
    from distcloth.config.load import config_from_dict
    from distcloth.parallel.comm import Comm
    from distcloth.scene import build_model
    from distcloth.simulation import Simulation
    comm = Comm()
    side = int(round(math.sqrt(args.size)))
    opts, linear_system = {**SOLVERS, **EXTRA_SOLVERS}[args.solver]
    solver = dict(opts, ksp_rtol=1e-5, ksp_norm_type="unpreconditioned", ksp_max_it=5000)
    material = {"density": 0.1, "stretch": 10.0, "shear": 1.0, "bending": 1e-6}
    if args.bending is not None:     # the FE membrane with the chosen bending model
        material = {"model": "fem", "density": 0.1, "stretch": 10.0, "bending": 1e-6,
                    "bending_model": args.bending}
    raw = {
        "scene": "bench",
        "cloth": [{"name": "square", "mesh": {"grid": {"size": [0.5, 0.5], "resolution": [side, side]},
                                               "center": [0, 0, 1]},
                   "pins": [{"edge": "top"}],
                   "material": material}],
        "effects": ["gravity", "membrane", "bending"],
        "time": {"end": 10.0, "step": 0.02},
        "solver": solver,
        "linear_system": dict(linear_system, warm_start=args.warm),
        "output": {"file": "unused.h5", "every": 10.0, "preview": False},
    }
    cfg = config_from_dict(raw, str(ROOT), "bench")
    t0 = time.perf_counter()
    model = build_model(cfg)
    sim = Simulation(cfg, model, comm, quiet=True)
    sim.prepare()
    setup = time.perf_counter() - t0
    for _ in range(args.warmup):
        sim.step()
    sim.pipeline.take_step_counters()
    comm.synchronize()
    its, res = [], []
    split = {"forces": 0.0, "assembly": 0.0, "solve": 0.0, "rest": 0.0}
    t0 = time.perf_counter()
    for _ in range(args.steps):
        s0 = time.perf_counter()
        d = sim.step()
        wall = time.perf_counter() - s0
        times, _ = sim.pipeline.take_step_counters()
        f = sum(v for k, v in times.items() if k.startswith("force:"))
        split["forces"] += f
        split["assembly"] += times["assembly"]
        split["solve"] += times["solve"]
        split["rest"] += wall - f - times["assembly"] - times["solve"]
        its.append(d["ksp_iterations"])
        res.append(d["ksp_residual"])
    comm.synchronize()
    total = time.perf_counter() - t0
    # the slowest rank sets the pace: report each split's max over ranks
    import numpy as np
    keys = sorted(split)
    mx = comm.max(np.array([split[k] / args.steps for k in keys]))
    out = {"size": model.num_vertices, "ranks": comm.size, "solver": args.solver, "warm": args.warm,
           "step_time": total / args.steps, "setup_time": setup,
           **{k: float(v) for k, v in zip(keys, mx)},
           "ksp_iterations": float(np.mean(its)), "true_residual": float(max(res)),
           "imbalance": sim.layout.imbalance}
    if comm.rank == 0:
        print("RESULT " + json.dumps(out), flush=True)
    sim.destroy()


def launch(ranks, size, solver, warm, steps, warmup, bending=None):
    cmd = [str(ROOT / "scripts" / "mpiexec.sh"), str(ranks), sys.executable, __file__, "--worker",
           "--size", str(size), "--solver", solver, "--steps", str(steps), "--warmup", str(warmup)]
    if bending is not None:
        cmd += ["--bending", bending]
    if warm:
        cmd.append("--warm")
    env = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_", "PMIX_"))}
    env["PYTHONPATH"] = str(ROOT)
    p = subprocess.run(cmd, capture_output=True, text=True, env=env)
    for line in p.stdout.splitlines():
        if line.startswith("RESULT "):
            return json.loads(line[7:])
    sys.stderr.write(p.stdout[-2000:] + p.stderr[-4000:])
    return None


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--size", type=int, default=10000)
    ap.add_argument("--sizes", type=int, nargs="+", default=[10000, 100000, 400000])
    every = sorted({**SOLVERS, **EXTRA_SOLVERS})
    ap.add_argument("--solver", default="bjacobi+sgs", choices=every)
    ap.add_argument("--solvers", nargs="+", default=list(SOLVERS), choices=every)
    ap.add_argument("--ranks", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--warm", action="store_true")
    ap.add_argument("--steps", type=int, default=5)
    ap.add_argument("--warmup", type=int, default=2)
    ap.add_argument("--json", help="also write all results to this JSON file")
    ap.add_argument("--bending", choices=FE_BENDING_MODELS,
                    help="worker: FE membrane with this bending model (default: mass-spring)")
    ap.add_argument("--bending-models", nargs="+",
                    choices=FE_BENDING_MODELS,
                    help="compare the FE bending models instead of the solvers: one row per "
                         "model and rank count with the first of --solvers, no warm start")
    args = ap.parse_args()
    if args.worker:
        return worker(args)
    if args.bending_models:
        return compare_bending(args)
    rows = []
    print("| vertices | ranks | solver | warm start | step s | forces s | assembly s | solve s | "
          "rest s | KSP its | true rel. residual |")
    print("|---:|---:|---|---|---:|---:|---:|---:|---:|---:|---:|")
    for size in args.sizes:
        for solver in args.solvers:
            # warm starts only below 200k vertices: the reference preconditioner
            # needs minutes per configuration at 400k on this machine
            for warm in ((False, True) if size < 200000 else (False,)):
                for ranks in args.ranks:
                    # the slow reference preconditioner at 400k: fewer steps
                    steps = args.steps if size < 200000 else max(1, args.steps // 2)
                    r = launch(ranks, size, solver, warm, steps, args.warmup)
                    if r is None:
                        print(f"| {size} | {ranks} | {solver} | {warm} | failed |")
                        continue
                    rows.append(r)
                    print(f"| {r['size']} | {ranks} | {solver} | {'yes' if warm else 'no'} | "
                          f"{r['step_time']:.3f} | {r['forces']:.3f} | {r['assembly']:.3f} | "
                          f"{r['solve']:.3f} | {r['rest']:.3f} | {r['ksp_iterations']:.0f} | "
                          f"{r['true_residual']:.1e} |", flush=True)
    print("\nparallel efficiency T(1) / (2 T(2)) and iteration growth from 1 to 2 ranks:")
    for r1 in rows:
        if r1["ranks"] != 1:
            continue
        for r2 in rows:
            if r2["ranks"] == 2 and all(r2[k] == r1[k] for k in ("size", "solver", "warm")):
                eff = r1["step_time"] / (2 * r2["step_time"])
                growth = r2["ksp_iterations"] / max(r1["ksp_iterations"], 1)
                print(f"  {r1['size']:>7} {r1['solver']:<12} warm={'yes' if r1['warm'] else 'no '}: "
                      f"efficiency {100 * eff:.0f} %, iterations x{growth:.2f}")
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))


def compare_bending(args):
    """Cost per step of the FE bending models (the shell models' curvature-jump
    penalty widens the matrix stencil to the neighbours' neighbours)."""
    solver = args.solvers[0]
    print(f"FE membrane, solver {solver}, {args.steps} timed steps after {args.warmup} warm-up\n")
    print("| vertices | ranks | bending | step s | forces s | assembly s | solve s | KSP its | "
          "step / dihedral step |")
    print("|---:|---:|---|---:|---:|---:|---:|---:|---:|")
    for size in args.sizes:
        for ranks in args.ranks:
            base = None
            for bending in args.bending_models:
                r = launch(ranks, size, solver, False, args.steps, args.warmup, bending)
                if r is None:
                    print(f"| {size} | {ranks} | {bending} | failed |")
                    continue
                base = r["step_time"] if bending == "dihedral" else base
                ratio = f"{r['step_time'] / base:.2f}" if base else ""
                print(f"| {r['size']} | {ranks} | {bending} | {r['step_time']:.3f} | "
                      f"{r['forces']:.3f} | {r['assembly']:.3f} | {r['solve']:.3f} | "
                      f"{r['ksp_iterations']:.0f} | {ratio} |", flush=True)


if __name__ == "__main__":
    main()
