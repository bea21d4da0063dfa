#!/usr/bin/env python3
"""Where GAMG on AIJ overtakes block-Jacobi SGS on BAIJ, and what ksp_rtol and
warm start cost or save, on the hanging square of the peer comparison (S1:
0.5 m, edge x = 0 pinned, 0.1 kg/m², FE membrane 1000 N/m, BDF-2 at 5 ms).

    .venv/bin/python scripts/bench_defaults.py --sizes 41 101 141 201 --ranks 1 2
    .venv/bin/python scripts/bench_defaults.py --accuracy --side 41
    .venv/bin/python scripts/bench_defaults.py --write-scene s1_41.yaml   # for -log_view

Each run: a scene built in process, ``--warmup`` steps untimed (JIT, first
set-up), then ``--steps`` timed; the step time is the slowest rank's.  The
choice it informs is distcloth/linalg/presets.py's ``by_size``.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]


def s1_scene(side: int, solver: dict | None, linear_system: dict | None, step=0.005) -> dict:
    raw = {
        "scene": "s1",
        "cloth": [{"name": "square",
                   "mesh": {"grid": {"size": [0.5, 0.5], "resolution": [side, side]},
                            "center": [0.25, 0.0, 0.0]},
                   "pins": [{"edge": "left"}],
                   "material": {"model": "fem", "density": 0.1, "stretch": 1000.0,
                                "bending": 1e-6}}],
        "effects": ["gravity", "membrane", "bending"],
        "time": {"end": 10.0, "step": step, "integrator": "bdf2"},
        "output": {"file": "unused.h5", "every": 10.0, "preview": False},
    }
    if solver is not None:
        raw["solver"] = solver
    if linear_system is not None:
        raw["linear_system"] = linear_system
    return raw


def worker(args):
    from distcloth.linalg.petsc import init_petsc
    init_petsc([])
    import numpy as np
    from distcloth.config.load import config_from_dict
    from distcloth.linalg.presets import PRECONDITIONERS
    from distcloth.parallel.comm import Comm
    from distcloth.scene import build_model
    from distcloth.simulation import Simulation
    comm = Comm()
    solver = linear_system = None
    if args.pc != "default":
        options, mat_type = PRECONDITIONERS[args.pc]
        # on the unpreconditioned residual, as the presets stop
        solver = {"ksp_type": "cg", **options, "ksp_rtol": args.rtol,
                  "ksp_norm_type": "unpreconditioned"}
        linear_system = {"mat_type": mat_type, "warm_start": args.warm}
    cfg = config_from_dict(s1_scene(args.side, solver, linear_system), str(ROOT), "bench")
    sim = Simulation(cfg, build_model(cfg), comm, quiet=True)
    sim.prepare()
    for _ in range(args.warmup):
        sim.step()
    comm.synchronize()
    its = []
    t0 = time.perf_counter()
    for _ in range(args.steps):
        its.append(sim.step()["ksp_iterations"])
    comm.synchronize()
    wall = float(comm.max(np.array([time.perf_counter() - t0]))[0]) / args.steps
    if comm.rank == 0:
        print("RESULT " + json.dumps({"side": args.side, "vertices": args.side ** 2,
                                      "ranks": comm.size, "pc": args.pc, "rtol": args.rtol,
                                      "warm": args.warm, "step_ms": 1e3 * wall,
                                      "ksp_its": float(np.mean(its)),
                                      "solver": sim.system.describe()}), flush=True)
    sim.destroy()


def launch(ranks, side, pc, rtol, warm, steps, warmup):
    cmd = [str(ROOT / "scripts" / "mpiexec.sh"), str(ranks), sys.executable, __file__, "--worker",
           "--side", str(side), "--pc", pc, "--rtol", str(rtol), "--steps", str(steps),
           "--warmup", str(warmup)] + (["--warm"] if warm else [])
    env = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_", "PMIX_"))}
    p = subprocess.run(cmd, capture_output=True, text=True, env=env)
    for line in p.stdout.splitlines():
        if line.startswith("RESULT "):
            return json.loads(line[7:])
    sys.stderr.write(p.stdout[-2000:] + p.stderr[-3000:])
    return None


def main():
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--side", type=int, default=41)
    ap.add_argument("--sizes", type=int, nargs="+", default=[41, 101, 141, 201])
    ap.add_argument("--ranks", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--pc", default="bjacobi_sgs", help="a name of presets.PRECONDITIONERS, or default")
    ap.add_argument("--pcs", nargs="+", default=["bjacobi_sgs", "gamg"])
    ap.add_argument("--rtol", type=float, default=1e-3)
    ap.add_argument("--warm", action="store_true")
    ap.add_argument("--steps", type=int, default=10)
    ap.add_argument("--warmup", type=int, default=4)
    ap.add_argument("--json", help="append the results to this file (one JSON per line)")
    ap.add_argument("--accuracy", action="store_true",
                    help="what ksp_rtol and warm start cost in accuracy (1 rank, in process)")
    ap.add_argument("--rtols", type=float, nargs="+", default=[1e-2, 1e-3, 1e-5])
    ap.add_argument("--step", type=float, default=0.005)
    ap.add_argument("--t-end", type=float, default=1.0)
    ap.add_argument("--write-scene", metavar="PATH",
                    help="write S1 at --side as a scene file (ksp_rtol --rtol; --pc default: "
                    "no solver: section) for the CLI and -log_view, then stop")
    args = ap.parse_args()
    if args.write_scene:
        solver = None if args.pc == "default" else {"ksp_rtol": args.rtol}
        raw = s1_scene(args.side, solver, None)
        raw["time"]["end"] = 0.5
        raw["output"] = {"file": "s1.h5", "every": 0.5, "preview": False}
        Path(args.write_scene).write_text(yaml.safe_dump(raw, sort_keys=False))
        return None
    if args.worker:
        return worker(args)
    if args.accuracy:
        return accuracy(args)
    print(f"| vertices | ranks | solver | step ms | KSP its |\n|---:|---:|---|---:|---:|", flush=True)
    for side in args.sizes:
        for ranks in args.ranks:
            for pc in args.pcs:
                r = launch(ranks, side, pc, args.rtol, args.warm, args.steps, args.warmup)
                if r is None:
                    continue
                print(f"| {r['vertices']} | {ranks} | {pc} | {r['step_ms']:.1f} | "
                      f"{r['ksp_its']:.1f} |", flush=True)
                if args.json:
                    with open(args.json, "a") as f:
                        f.write(json.dumps(r) + "\n")



def accuracy(args):
    """RMS vertex distance at t = 0.5 and 1 s between each (ksp_rtol, warm start)
    and ksp_rtol 1e-8 at the same step, beside the time-discretisation error's
    size (h against h/2, both at 1e-8), and the CG iterations each used."""
    from distcloth.linalg.petsc import init_petsc
    init_petsc([])
    import numpy as np
    from distcloth.config.load import config_from_dict
    from distcloth.parallel.comm import Comm
    from distcloth.scene import build_model
    from distcloth.simulation import Simulation, SimulationError
    comm = Comm()

    def run(rtol, warm, step):
        solver = {"ksp_type": "cg", "pc_type": "bjacobi", "sub_pc_type": "sor", "ksp_rtol": rtol,
                  "ksp_norm_type": "unpreconditioned"}
        cfg = config_from_dict(s1_scene(args.side, solver, {"mat_type": "baij", "warm_start": warm},
                                        step), str(ROOT), "bench")
        sim = Simulation(cfg, build_model(cfg), comm, quiet=True)
        sim.prepare()
        frames, its = [], 0
        per = int(round(0.5 / step))
        t0 = time.perf_counter()
        try:
            for k in range(1, int(round(args.t_end / step)) + 1):
                its += sim.step()["ksp_iterations"]
                if k % per == 0:
                    order = np.argsort(sim.layout.local_input[:sim.n_owned])
                    frames.append(sim.owned_positions()[order].copy())
        except SimulationError as exc:
            return None, f"stopped: {str(exc)[:60]}", 0.0
        wall = time.perf_counter() - t0
        sim.destroy()
        return np.array(frames), its, wall

    def rms(a, b):
        return [1e3 * float(np.sqrt(np.mean(np.sum((x - y) ** 2, axis=1)))) for x, y in zip(a, b)]

    h = args.step
    ref, its_ref, _ = run(1e-8, False, h)
    half, _, _ = run(1e-8, False, h / 2)
    print(f"S1-{args.side}, BDF-2 at {1e3 * h:g} ms, 1 rank; RMS distances in mm at t = 0.5, 1, ... s")
    print(f"time-discretisation size (h against h/2 at 1e-8): {rms(ref, half)}")
    print("| ksp_rtol | warm start | RMS vs 1e-8, mm | CG iterations | solve loop s |\n|---:|---|---|---:|---:|")
    for rtol in args.rtols:
        for warm in (False, True):
            x, its, wall = run(rtol, warm, h)
            d = "-" if x is None else ", ".join(f"{v:.3g}" for v in rms(x, ref))
            print(f"| {rtol:g} | {'yes' if warm else 'no'} | {d} | {its} | {wall:.2f} |", flush=True)


if __name__ == "__main__":
    main()
