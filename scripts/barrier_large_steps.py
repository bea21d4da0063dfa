#!/usr/bin/env python3
"""Large steps onto a body with contact as a barrier, against contact as
constraints: the peer benchmark's tablecloth on the sphere S2-81
(configs/bench/s2_81.yaml: 81², FE membrane with Newton's Lamé moduli
1000 N/m, friction 0.5, 2 s) at 5 to 33 ms with backward Euler and BDF-2,
the energy guard on and no halving, each run a whole `distcloth run` under
mpiexec.

For each setting it prints whether the run reached its end (or where the
guard stopped it), the wall time per simulated second (the whole process,
and the stepping loop: the stage timers' sum less output), Newton and CG
iterations per step, the error against distcloth's converged reference
(BDF-2 at 1 ms, ksp_rtol 1e-8: RMS vertex distance over t = 0.5, 1, 1.5,
2 s, as docs/peers.md), with constraints and with the barrier (Newton to
1 mm/s), each model's own, the closest any vertex came to
the sphere, the largest strain and the lowest point at 2 s.  Runs are
cached under out/barrier/ by setting (delete a file to run it again; the
reference too).

    .venv/bin/python scripts/barrier_large_steps.py [--ranks 2] [--settings KEY ...]
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "out" / "barrier"
SCENE = ROOT / "configs" / "bench" / "s2_81.yaml"
TIMES = (0.5, 1.0, 1.5, 2.0)
CENTER, RADIUS = np.array([0.0, 0.0, 0.25]), 0.25
H33 = 1.0 / 30.0

# key: (contact model, integrator, step, Newton's velocity tolerance or None)
SETTINGS = {
    "reference": ("constraints", "bdf2", 0.001, None),
    "reference_barrier": ("barrier", "bdf2", 0.001, 1e-3),
    **{f"constraints_{integ}_{1e3 * h:.3g}ms": ("constraints", integ, h, None)
       for integ in ("backward_euler", "bdf2")
       for h in (0.005, 0.01, 0.02, H33)},
    **{f"barrier_{integ}_{1e3 * h:.3g}ms_tol{tol:g}": ("barrier", integ, h, tol)
       for integ in ("backward_euler", "bdf2")
       for h in (0.005, 0.01, 0.02, H33) for tol in (0.003, 0.01, 0.03, 0.1, 0.3)},
}


def command(key: str, ranks: int) -> list[str]:
    model, integ, h, tol = SETTINGS[key]
    sets = {"contact.model": model, "time.integrator": integ, "time.step": repr(h),
            "output.every": "0.1"}
    if tol is not None:
        sets["contact.velocity_tolerance"] = repr(tol)
    if key.startswith("reference"):
        sets["solver.ksp_rtol"] = "1e-8"
    args = [str(ROOT / "scripts" / "mpiexec.sh"), str(ranks), str(ROOT / ".venv/bin/python"),
            "-m", "distcloth", "run", str(SCENE), "--output", str(OUT / f"{key}.h5"),
            "--overwrite", "--quiet"]
    for k, v in sets.items():
        args += ["--set", f"{k}={v}"]
    return args


def run(key: str, ranks: int) -> dict:
    """Run a setting (or read its cached record)."""
    record = OUT / f"{key}.json"
    if record.exists():
        rec = json.loads(record.read_text())
        rec.update(summary(OUT / f"{key}.h5"))      # what is read from the result, read again
        return rec
    OUT.mkdir(parents=True, exist_ok=True)
    cmd = command(key, ranks)
    load = os.getloadavg()[0]
    start = time.perf_counter()
    p = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.perf_counter() - start
    rec = {"key": key, "command": " ".join(cmd[1:]), "wall": wall, "load": load,
           "returncode": p.returncode, "ranks": ranks}
    rec.update(summary(OUT / f"{key}.h5"))
    record.write_text(json.dumps(rec, indent=1))
    return rec


def summary(path: Path) -> dict:
    with h5py.File(path, "r") as f:
        d = f["diagnostics"]
        out = {"status": str(f.attrs["status"]), "error": str(f.attrs["error"]),
               "steps": int(d["step"].shape[0]),
               "newton": float(np.sum(d["newton_iterations"][:])),
               "ksp": float(np.sum(d["ksp_iterations"][:])),
               "max_strain": float(np.max(d["max_strain"][:], initial=0.0))}
        stages = d["stage_time"]
        out["loop"] = sum(float(np.nansum(stages[name][:])) for name in stages
                          if name != "output")
        t = f["frames/time"][:]
        x = f["frames/positions"]
        frames = {}
        for want in TIMES:
            i = int(np.argmin(np.abs(t - want)))
            if abs(t[i] - want) < 1e-6:
                frames[str(want)] = x[i].tolist()
        out["frames"] = frames
        closest = np.inf
        for i in range(x.shape[0]):
            p = x[i]
            closest = min(closest, float(np.min(np.linalg.norm(p - CENTER, axis=1))) - RADIUS)
        out["closest_to_sphere_mm"] = 1e3 * closest
        out["min_z_end"] = float(np.min(x[-1][:, 2]))
        out["t_end"] = float(t[-1])
    return out


def error_mm(rec: dict, ref: dict) -> tuple[float, list[float]]:
    per = []
    for want in TIMES:
        a, b = rec["frames"].get(str(want)), ref["frames"].get(str(want))
        if a is None or b is None:
            return float("nan"), []
        per.append(1e3 * float(np.sqrt(np.mean(np.sum((np.array(a) - np.array(b)) ** 2, axis=1)))))
    return float(np.sqrt(np.mean(np.square(per)))), per


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--ranks", type=int, default=2)
    ap.add_argument("--settings", nargs="*", default=None, help=f"of {', '.join(SETTINGS)}")
    args = ap.parse_args()
    keys = args.settings or list(SETTINGS)
    refs = {"constraints": run("reference", args.ranks),
            "barrier": run("reference_barrier", args.ranks)}
    print("| contact | integrator | step ms | outcome | wall s per sim-s (process / loop) "
          "| Newton its per step | CG its per step | error mm RMS (0.5 / 1 / 1.5 / 2 s) "
          "against the constraints' reference | against the barrier's "
          "| closest to the sphere mm | max strain % | min z at end m | load before |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for key in keys:
        rec = run(key, args.ranks)
        model, integ, h, tol = SETTINGS[key]
        if tol is not None:
            model = f"{model}, tolerance {tol:g} m/s"
        done = rec["status"].startswith("completed")
        # "step 11: energy gain: total energy 0.162 S above ..." -> its first two parts
        outcome = "completed" if done else "stopped at " + ": ".join(
            rec["error"].split(": ")[:2]) + f" ({rec['error'].split(': ')[2].split(' above')[0]})"
        errors = []
        for ref in refs.values():
            err, per = error_mm(rec, ref)
            per_s = " / ".join(f"{e:.1f}" for e in per)
            errors.append("" if np.isnan(err) else f"{err:.1f} ({per_s})")
        speed = (f"{rec['wall'] / rec['t_end']:.1f} / {rec['loop'] / rec['t_end']:.1f}" if done
                 else "–")
        print(f"| {model} | {integ} | {1e3 * h:.3g} | {outcome} | {speed} | "
              f"{rec['newton'] / rec['steps']:.2f} | "
              f"{rec['ksp'] / rec['steps']:.0f} | {errors[0]} | {errors[1]} | "
              f"{rec['closest_to_sphere_mm']:.2f} | {100 * rec['max_strain']:.2f} | "
              f"{rec['min_z_end']:.4f} | {rec['load']:.2f} |", flush=True)
    print(f"\nmachine: {os.cpu_count()} cores; ranks {args.ranks}; scene {SCENE.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
