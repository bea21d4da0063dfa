#!/usr/bin/env python3
"""Each contact pass of each step of a scene with body contacts: the pass's
solver tolerance, CG iterations and wall time (forces, assembly and solve:
the integrator's step, rank 0), and after it how many contacts the
attempt has released as adhesive and made of missed vertices so far (the
revision, summed over ranks); then, over the traced steps, the mean cost of
a step's first pass and a least-squares fit of the later passes' time as
a fixed part plus a part per CG iteration (the later passes keep the
first's multigrid preconditioner).

    scripts/mpiexec.sh 2 .venv/bin/python scripts/trace_contact_passes.py configs/bench/s2_81.yaml --start 0.3 --end 0.35
    scripts/mpiexec.sh 2 .venv/bin/python scripts/trace_contact_passes.py configs/tablecloth_sphere.yaml \\
        --set 'cloth.0.mesh.grid.resolution=[317,317]' --set 'cloth.0.mesh.center=[0,0,0.505]' \\
        --set cloth.0.material.stretch=1000 --set time.step=0.01 --start 0.04 --end 0.1

With ``--profile`` the traced steps are profiled too (rank 0).  The second is the 100k-vertex scene of scripts/bench_scale.py (whose solver,
GAMG on AIJ at rtol 1e-5, is also the default a 100k cloth with contacts
gets on 2 ranks).
"""
from __future__ import annotations

import argparse
import cProfile
import pstats
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from distcloth.config.load import apply_overrides, read_scene_file  # noqa: E402
from distcloth.inprocess import build_simulation  # noqa: E402
from distcloth.parallel.comm import Comm  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("config", type=Path)
    ap.add_argument("--start", type=float, default=0.0, help="s: tracing starts here")
    ap.add_argument("--end", type=float, default=0.1)
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--profile", action="store_true",
                    help="also profile the traced steps (cProfile, rank 0: the 25 functions "
                         "with the most time of their own)")
    a = ap.parse_args()
    comm = Comm()
    raw = apply_overrides(read_scene_file(str(a.config)), a.set + [f"time.end={a.end}"])
    raw.pop("output", None)
    sim, _, err = build_simulation(raw, a.config.stem, comm, base_dir=str(a.config.parent))
    if err:
        sys.exit(err)
    if not sim.contact.has_bodies or sim.system is None:
        sys.exit("trace_contact_passes: the scene needs an implicit integrator and body contacts")
    passes = []
    step, revise = sim.integrator.step, sim.contact.revise

    def traced_step(ctx, state, h, cons, guess=None):
        t0 = time.perf_counter()
        result = step(ctx, state, h, cons, guess)
        passes.append({"rtol": sim.system.rtol, "its": result.ksp_iterations,
                       "s": time.perf_counter() - t0})
        return result

    def traced_revise(contacts, result, t_end, h, revision):
        out = revise(contacts, result, t_end, h, revision)
        n = sim.n_owned
        so_far = out if out is not None else revision     # unchanged: the attempt's so far
        counts = (np.zeros(2) if so_far is None else
                  np.array([so_far.released[:n].sum(), so_far.missed[:, :n].sum()], dtype=float))
        total = comm.sum(np.array([float(np.sum(contacts.index < n)), *counts]))
        passes[-1].update(contacts=int(total[0]), changed=out is not None,
                          released=int(total[1]), missed=int(total[2]))
        return out

    sim.integrator.step, sim.contact.revise = traced_step, traced_revise
    while sim.state.t < a.start - 1e-12:
        sim.step()
    first, later = [], []
    profile = cProfile.Profile() if a.profile else None
    if profile is not None:
        profile.enable()
    while sim.state.t < a.end - 1e-12:
        passes.clear()
        t0 = time.perf_counter()
        diag = sim.step()
        wall = time.perf_counter() - t0
        if comm.rank == 0:
            print(f"step {sim.state.step} (t = {sim.state.t:.4g} s): {wall:.3f} s, "
                  f"{len(passes)} passes, {diag['contacts']:.0f} contacts at the end", flush=True)
            for k, p in enumerate(passes):
                print(f"  pass {k}: rtol {p['rtol']:g}, {p['its']} CG its, {p['s']:.3f} s, "
                      f"{p.get('contacts', 0)} contacts; released {p.get('released', 0)}, "
                      f"missed {p.get('missed', 0)} so far"
                      + ("" if p.get("changed", True) else " (set unchanged)"), flush=True)
        first += passes[:1]
        later += passes[1:]
    if profile is not None:
        profile.disable()
        if comm.rank == 0:
            pstats.Stats(profile).sort_stats("tottime").print_stats(25)
    sim.destroy()
    if comm.rank == 0 and first:
        print(f"first passes: {np.mean([p['s'] for p in first]):.3f} s, "
              f"{np.mean([p['its'] for p in first]):.1f} CG its on average ({len(first)})")
        if len(later) >= 2:
            its = np.array([p["its"] for p in later], dtype=float)
            fit = np.linalg.lstsq(np.column_stack([np.ones_like(its), its]),
                                  np.array([p["s"] for p in later]), rcond=None)[0]
            print(f"later passes ({len(later)}): {fit[0]:.3f} s fixed + {fit[1] * 1e3:.1f} ms "
                  f"per CG iteration (least squares)")


if __name__ == "__main__":
    main()
