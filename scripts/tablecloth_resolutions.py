#!/usr/bin/env python3
"""Contact at 41², 81², 161²: the tablecloth on the sphere at three resolutions.

Runs configs/tablecloth_sphere.yaml at each resolution N (``--set
cloth.0.mesh.grid.resolution=[N,N]``) to ``--end`` seconds (2 s) with the
energy guard on (the scene's default), on ``--ranks`` ranks (2) through the
public command, one run at a time, and reports per resolution

* whether the run completed, or where and why it stopped (the result file's
  ``status``, ``error_step`` and ``error``);
* the largest rise of the total energy after the first contact, above its
  running minimum from there, as a fraction of the scene's energy scale
  S = KE + |U_elastic| + M |g| L (distcloth/energy_guard.py: M from the mesh
  and the density, L the rest bounding-box diagonal; KE and U_elastic from
  the first step's row, both ~0 for a flat cloth at rest), and the largest
  excess over the start energy (the guard's own measure, limit 0.1 S);
* the deepest vertex in any written frame, (d - phi) / d with phi computed
  here from the frames, independently of the simulator (sphere centre
  (0, 0, 0.25), radius 0.25; floor z = 0; d = the cloth thickness, the
  colliders having none): > 0 is inside the offset surface, > 1 inside the
  body; frames are written after the position fail-safe, so beside it the
  largest ``max_penetration`` diagnostic (what the solve left before the
  fail-safe), also in d;
* the total work of the contact constraints, of friction and of the
  position fail-safe over the run (diagnostics, J);
* solves per step (``stage_calls/solve``: 1 when the first contact set was
  right) and the run's wall time.

Prints a Markdown table (and writes it with ``--markdown``).  Result files go
to ``--out`` (out/tablecloth_resolutions/tc_N.h5), each with a JSON sidecar
holding the wall time; ``--reuse`` takes a finished run's file instead of
running it again, so the resolutions can be run separately:

    .venv/bin/python scripts/tablecloth_resolutions.py --resolutions 41 81
    .venv/bin/python scripts/tablecloth_resolutions.py --resolutions 41 81 161 --reuse
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import yaml

from distcloth.io.h5read import read_result

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "configs" / "tablecloth_sphere.yaml"
SPHERE_CENTER = np.array([0.0, 0.0, 0.25])
SPHERE_RADIUS = 0.25
FLOOR_Z = 0.0


def run_one(n: int, out: Path, end: float, ranks: int, extra: list[str]) -> dict:
    """Run the scene at N x N; returns {wall, returncode, stderr tail}."""
    path = out / f"tc_{n}.h5"
    cmd = [str(ROOT / "scripts" / "mpiexec.sh"), str(ranks), str(ROOT / ".venv" / "bin" / "distcloth"),
           "run", str(SCENE), "--set", f"cloth.0.mesh.grid.resolution=[{n},{n}]",
           "--set", f"time.end={end}", "--set", "output.preview=false",
           "--output", str(path), "--overwrite", "--quiet", *extra]
    t0 = time.perf_counter()
    p = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    info = {"n": n, "wall": wall, "returncode": p.returncode, "command": " ".join(cmd),
            "stderr_tail": p.stderr[-2000:], "stdout_tail": p.stdout[-2000:]}
    (out / f"tc_{n}.json").write_text(json.dumps(info, indent=1))
    return info


def signed_distances(x: np.ndarray) -> np.ndarray:
    """(frames, n) smallest signed distance to the sphere and the floor."""
    sphere = np.linalg.norm(x - SPHERE_CENTER, axis=-1) - SPHERE_RADIUS
    floor = x[..., 2] - FLOOR_Z
    return np.minimum(sphere, floor)


def measure(path: Path, info: dict) -> dict:
    res = read_result(path)
    cfg = yaml.safe_load(res["config"])
    piece = cfg["cloth"][0]
    d = float(piece.get("thickness", 0.001)) + max(
        [float(c.get("thickness", 0.0)) for c in cfg.get("colliders", [])] + [0.0])
    diag = res["diagnostics"]
    attrs = res["attrs"]
    # S as the energy guard takes it
    x0 = res["rest_positions"]
    tri = res["triangles"]
    area = 0.5 * np.linalg.norm(np.cross(x0[tri[:, 1]] - x0[tri[:, 0]],
                                         x0[tri[:, 2]] - x0[tri[:, 0]]), axis=1).sum()
    mass = float(piece["material"].get("density", 0.1)) * area
    g = float(np.linalg.norm(cfg.get("gravity", [0.0, 0.0, -9.81])))
    size = float(np.linalg.norm(x0.max(axis=0) - x0.min(axis=0)))
    scale = abs(diag["kinetic_energy"][0]) + abs(diag["elastic_energy"][0]) + mass * g * size
    E = diag["total_energy"]
    contacts = np.nan_to_num(diag["contacts"])
    touched = np.nonzero(contacts > 0)[0]
    first = int(touched[0]) if touched.size else None
    if first is not None:
        after = E[first:]
        rise = after - np.minimum.accumulate(after)
        k = int(np.argmax(rise))
        rise_max, rise_t = float(rise[k]), float(diag["time"][first + k])
    else:
        rise_max, rise_t = 0.0, float("nan")
    phi = signed_distances(res["positions"])
    depth = (d - phi) / d
    f, v = np.unravel_index(int(np.argmax(depth)), depth.shape)
    calls = res["stage_calls"]["solve"]
    return {
        "n": int(round(np.sqrt(x0.shape[0]))), "vertices": int(x0.shape[0]),
        "status": attrs.get("status"), "error": attrs.get("error", ""),
        "error_step": int(attrs.get("error_step", -1)), "steps": int(res["steps_written"]),
        "t_end": float(diag["time"][-1]) if len(diag["time"]) else 0.0,
        "first_contact_t": float(diag["time"][first]) if first is not None else None,
        "S": float(scale), "rise_over_S": rise_max / scale, "rise_t": rise_t,
        "excess_over_S": float((E.max() - E[0]) / scale),
        "deepest_over_d": float(depth[f, v]), "deepest_t": float(res["time"][f]),
        "solve_penetration_over_d": float(np.nanmax(diag["max_penetration"]) / d),
        "frames": int(res["frames_written"]),
        "contact_work": float(np.nansum(diag["contact_work"])),
        "friction_work": float(np.nansum(diag["friction_work"])),
        "failsafe_work": float(np.nansum(diag["failsafe_work"])),
        "solves_mean": float(np.mean(calls)), "solves_max": int(np.max(calls)),
        "max_strain": float(np.nanmax(diag["max_strain"])),
        "wall": float(info.get("wall", float("nan"))),
    }


def table(rows: list[dict]) -> str:
    head = ("| N × N | vertices | outcome | energy rise after first contact (S) | "
            "largest excess over start (S) | deepest vertex, any frame (d) | "
            "deepest before the fail-safe (d) | "
            "contact work (J) | friction work (J) | fail-safe work (J) | solves/step (mean, max) | "
            "largest strain | wall (s) |")
    lines = [head, "|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        if r["status"] == "completed":
            outcome = f"completed, {r['t_end']:.2f} s"
        else:
            outcome = (f"stopped at step {r['error_step']} (t = {r['t_end']:.3f} s): "
                       f"{r['error'].split(': ', 1)[-1] if r['error'] else r['status']}")
        rise = (f"{r['rise_over_S']:.3g} (t = {r['rise_t']:.2f} s)" if r["rise_over_S"] > 0
                else "0 (never rises)")
        lines.append(
            f"| {r['n']} | {r['vertices']} | {outcome} | {rise} "
            f"| {r['excess_over_S']:.3g} | {r['deepest_over_d']:.2g} "
            f"(t = {r['deepest_t']:.2f} s) | {r['solve_penetration_over_d']:.3f} | "
            f"{r['contact_work']:.4g} | {r['friction_work']:.4g} | "
            f"{r['failsafe_work']:.4g} | {r['solves_mean']:.2f}, {r['solves_max']} | "
            f"{r['max_strain']:.3f} | {r['wall']:.0f} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--resolutions", type=int, nargs="+", default=[41, 81, 161])
    ap.add_argument("--end", type=float, default=2.0, help="s: simulated time")
    ap.add_argument("--ranks", type=int, default=2)
    ap.add_argument("--out", type=Path, default=ROOT / "out" / "tablecloth_resolutions")
    ap.add_argument("--reuse", action="store_true",
                    help="use an existing result file (and its JSON sidecar) instead of running")
    ap.add_argument("--markdown", type=Path, help="also write the table here")
    ap.add_argument("extra", nargs="*", help="further arguments for distcloth run (after --)")
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    rows = []
    for n in args.resolutions:
        path, side = args.out / f"tc_{n}.h5", args.out / f"tc_{n}.json"
        if args.reuse and path.exists() and side.exists():
            info = json.loads(side.read_text())
        else:
            print(f"running {n} x {n} ...", file=sys.stderr, flush=True)
            info = run_one(n, args.out, args.end, args.ranks, args.extra)
            print(f"  {n} x {n}: exit {info['returncode']} in {info['wall']:.0f} s",
                  file=sys.stderr, flush=True)
        if not path.exists():
            print(f"{n} x {n}: no result file; stderr:\n{info['stderr_tail']}", file=sys.stderr)
            continue
        rows.append(measure(path, info))
    text = table(rows)
    print(text)
    if args.markdown:
        args.markdown.write_text(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
