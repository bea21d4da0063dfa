#!/usr/bin/env python3
"""What the contact passes cost: a scene with body contacts (no sewing
phase) stepped with its passes solved loosely until the contact set settles
(the default, ``ContactModel.pass_rtol``) and with every pass solved to the
scene's tolerance, alternately in one job (A, B, A, B, ...).  Prints per
step: linear solves, CG iterations, the solve stage's and the whole step's
wall time (the slowest rank's); and how far apart the end states are (RMS
and largest vertex distance), next to how far the tight mode lands from
itself with the solver's tolerance tightened tenfold: the scale the contact
set's sensitivity to the solver already allows.

    scripts/mpiexec.sh 2 .venv/bin/python scripts/bench_contact_passes.py configs/bench/s2_81.yaml --end 0.8 --repeats 2
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from distcloth.config.load import apply_overrides, read_scene_file  # noqa: E402
from distcloth.inprocess import build_simulation  # noqa: E402
from distcloth.parallel.comm import Comm  # noqa: E402


def positions(sim) -> np.ndarray:
    """Global positions in input order, on every rank."""
    out = np.zeros((sim.model.num_vertices, 3))
    out[sim.layout.owned_input] = sim.owned_positions()
    return sim.comm.sum(out)


def run(path: Path, overrides, comm, loose: bool, start: float, end: float,
        rtol_scale: float = 1.0) -> dict:
    raw = apply_overrides(read_scene_file(str(path)), list(overrides) + [f"time.end={end}"])
    raw.pop("output", None)
    sim, _, err = build_simulation(raw, path.stem, comm, base_dir=str(path.parent))
    if err:
        sys.exit(err)
    if not loose:
        sim.contact.pass_rtol = None
    if rtol_scale != 1.0:
        sim.system.ksp.setTolerances(rtol=sim.system.rtol * rtol_scale)
    while sim.state.t < start - 1e-12:
        sim.step()
    sim.pipeline.take_step_counters()
    solves0, its, steps, step_wall, solve_wall = sim.system.solves, 0, 0, 0.0, 0.0
    while sim.state.t < end - 1e-12:
        t0 = time.perf_counter()
        diag = sim.step()
        step_wall += time.perf_counter() - t0
        solve_wall += sim.pipeline.take_step_counters()[0].get("solve", 0.0)
        its += int(diag["ksp_iterations"])
        steps += 1
    walls = comm.max(np.array([step_wall, solve_wall]))
    out = dict(steps=steps, solves=(sim.system.solves - solves0) / steps, its=its / steps,
               step=walls[0] / steps, solve=walls[1] / steps, x=positions(sim))
    sim.destroy()
    return out


def apart(a, b) -> str:
    d = np.linalg.norm(a - b, axis=1)
    return f"RMS {1e3 * np.sqrt(np.mean(d * d)):.3f} mm, largest {1e3 * d.max():.3f} mm"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("config", type=Path)
    ap.add_argument("--start", type=float, default=0.0, help="s: timing starts here")
    ap.add_argument("--end", type=float, default=1.0)
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    args = ap.parse_args()
    comm = Comm()
    rows = {True: [], False: []}
    for _ in range(args.repeats):
        for loose in (True, False):
            rows[loose].append(run(args.config, args.set, comm, loose, args.start, args.end))
    ref = run(args.config, args.set, comm, False, args.start, args.end, rtol_scale=0.1)
    if comm.rank != 0:
        return
    print(f"{args.config}, t = {args.start:g}..{args.end:g} s, {comm.size} rank(s), "
          f"{args.repeats} run(s) each, per step (median over runs):")
    print("| passes | steps | solves | CG its | solve s | step s |")
    print("|---|---:|---:|---:|---:|---:|")
    for loose, name in ((True, "loose until settled"), (False, "all at the scene's rtol")):
        r = rows[loose]
        med = {k: float(np.median([x[k] for x in r])) for k in ("solves", "its", "solve", "step")}
        print(f"| {name} | {r[0]['steps']} | {med['solves']:.2f} | {med['its']:.1f} | "
              f"{med['solve']:.4f} | {med['step']:.4f} |")
    step_ratio = np.median([x["step"] for x in rows[True]]) / \
        np.median([x["step"] for x in rows[False]])
    print(f"step time, loose / tight: {step_ratio:.2f}")
    print(f"end states, loose vs tight: {apart(rows[True][0]['x'], rows[False][0]['x'])}")
    print(f"end states, tight vs tight at rtol / 10: {apart(rows[False][0]['x'], ref['x'])}")


if __name__ == "__main__":
    main()
