#!/usr/bin/env python3
"""Work stealing in the collision traversal: load balance and phase time
(distcloth/parallel/steal.py, EG07 tutorial, Part 1 §5.8.2).

Scenes (frozen snapshots of the 0.5 m x 2 m ribbon of configs/ribbon.yaml,
41 x 101 = 4141 vertices, 8000 triangles, thickness 4 mm, self-collision):

* simulated: the last frame of a run of configs/ribbon.yaml, if
  ``--ribbon H5`` is given (made with the command below); self-collision
  only (the ramp meshes are left out: the snapshot is all that is frozen,
  the ramp files may have changed since the run).  How crowded it is
  depends on how far the ribbon got: lying on the ramps it is not;
* crowded, synthetic: the last 0.5 m of the ribbon folded in ten layers
  (accordion panels of 5 cm, 3 mm apart), the rest flat: all the contacts
  sit in the sub-mesh(es) holding that end;
* uniform: the whole ribbon pleated across its width (five 10 cm layers,
  3 mm apart, along its whole length): every sub-mesh has the same work.

For 2 ranks and 4 ranks (oversubscribed on the 2 cores) it runs the
detection phase (``DistributedCollisions.candidates``: refit, traversal,
narrow phase, all-gather) on each snapshot, with the static assignment and
with stealing (a = 2, b = 8, chunk = 256), and reports the median over the
repetitions of: max and mean per-rank busy time (thread CPU time inside the
traversal chunks) and their ratio (the traversal's load imbalance); the
max/mean of the triangle pairs found per rank (the load of the narrow phase,
which runs where the pairs were found); the traversal wall time (run_tasks,
max over ranks; with stealing the call is collective, so it also holds the
wait for the last rank to arrive and the termination detection); the whole
detection phase wall time (barrier -> end of ``candidates``, max over
ranks: the collision phase time); tasks created and stolen, refusals and
the mean steal latency.  A second table sweeps a, b and chunk on the
synthetic crowded scene.

    scripts/mpiexec.sh 2 .venv/bin/python -m distcloth run configs/ribbon.yaml \\
        --set time.end=3.0 --set output.preview=false --output /tmp/r.h5 --overwrite        # ~4 min
    .venv/bin/python scripts/bench_steal.py --ribbon /tmp/r.h5                  # ~2 min
    .venv/bin/python scripts/bench_steal.py --quick                             # no sweep

The driver launches itself under ``scripts/mpiexec.sh N`` (worker mode) and
prints Markdown tables.  The first detection of each configuration is a
warm-up (JIT) and is not timed.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
THICK = 0.004
DEFAULT = dict(a=2.0, b=8, chunk=256)
SWEEP_SCENE = "ribbon, end folded ×10"


# ------------------------------------------------------------------ scenes
def accordion(x, axis, start, panel, gap, seed=0, bump=3e-4):
    """Fold the coordinate ``axis`` beyond ``start`` (measured from its
    minimum) into panels of length ``panel`` stacked ``gap`` apart in z."""
    rng = np.random.default_rng(seed)
    x = np.asarray(x, dtype=np.float64).copy()
    lo = x[:, axis].min()
    s = x[:, axis] - lo
    u = np.maximum(s - start, 0.0)
    k = np.floor(u / panel)
    r = u - k * panel
    along = np.where(k % 2 == 0, r, panel - r)
    fold = s > start
    x[fold, axis] = lo + start + along[fold]
    x[fold, 2] += k[fold] * gap
    kk = rng.normal(size=(5, 2)) * 40.0
    ph = rng.uniform(0, 2 * np.pi, 5)
    x[:, 2] += bump * np.sin(x[:, :2] @ kk.T + ph).sum(axis=1) / 5
    return x


def ribbon_model():
    from distcloth.config.load import load_config
    from distcloth.scene import build_model
    return build_model(load_config(str(ROOT / "configs" / "ribbon.yaml")))


def scenes(ribbon_h5):
    """[(label, kind, cloth positions)]"""
    model = ribbon_model()
    rest = np.asarray(model.rest_positions, dtype=np.float64)
    out = []
    if ribbon_h5:
        import h5py
        with h5py.File(ribbon_h5, "r") as f:
            x = f["frames/positions"][-1].astype(np.float64)
            t = float(f["frames/time"][-1])
        out.append((f"ribbon run, t = {t:g} s", "simulated", x))
    out.append((SWEEP_SCENE, "crowded", accordion(rest, 1, 1.5, 0.05, 0.003)))
    out.append(("ribbon, pleated ×5", "uniform", accordion(rest, 0, 0.0, 0.1, 0.003)))
    return out


# ------------------------------------------------------------------ worker
def worker(args) -> None:
    from distcloth.parallel.collide import build_collisions
    from distcloth.parallel.comm import Comm, partition_on_root
    from distcloth.parallel.partition import build_layout
    from distcloth.parallel.steal import summarize
    comm = Comm()
    results = []
    model = ribbon_model()
    xadj, adjncy = model.matrix_graph()
    part = partition_on_root(comm, xadj, adjncy)
    layout = build_layout(xadj, adjncy, model.spring_vertices, part, comm.rank, comm.size)
    for label, kind, xx in scenes(args.ribbon):
        det = build_collisions(comm, model, layout, (), self_collision=True)
        configs = [("static", dict(stealing=False, **DEFAULT)),
                   ("stealing", dict(stealing=True, **DEFAULT))]
        if not args.quick and kind == "crowded" and label == args.sweep_scene_label:
            for b in (8, 16, 24, 32, 128, 1024, 10000):
                configs.append((f"sweep b={b}", dict(stealing=True, a=2.0, b=b, chunk=256)))
            for a in (0.0, 0.5, 1.0, 4.0, 8.0):
                configs.append((f"sweep a={a:g}", dict(stealing=True, a=a, b=8, chunk=256)))
            for chunk in (64, 1024, 4096):
                configs.append((f"sweep chunk={chunk}", dict(stealing=True, a=2.0, b=8,
                                                            chunk=chunk)))
        for name, opts in configs:
            det.stealing, det.a, det.b, det.chunk = (opts["stealing"], opts["a"], opts["b"],
                                                     opts["chunk"])
            rows = []
            for rep in range(args.reps + 1):
                comm.synchronize()
                t0 = time.perf_counter()
                det.candidates(xx, xx, THICK)
                phase = time.perf_counter() - t0
                s = summarize(comm, det.last_phase_stats)
                s["phase_max"] = float(comm.max(np.array([phase]))[0])
                if rep:
                    rows.append(s)
            med = {k: float(np.median([r[k] for r in rows])) for k in rows[0]}
            med.update(scene=label, kind=kind, config=name, ranks=comm.size, **opts)
            results.append(med)
    if comm.rank == 0:
        Path(args.json).write_text(json.dumps(results))


# ------------------------------------------------------------------ driver
def run_ranks(ranks, args):
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "res.json"
        cmd = [str(ROOT / "scripts" / "mpiexec.sh"), str(ranks), sys.executable, __file__,
               "--worker", "--json", str(out), "--reps", str(args.reps)]
        if args.ribbon:
            cmd += ["--ribbon", args.ribbon]
        if args.quick:
            cmd += ["--quick"]
        env = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_", "PMIX_"))}
        env["PYTHONPATH"] = str(ROOT)
        p = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=ROOT)
        if p.returncode != 0:
            sys.stderr.write(p.stderr[-4000:])
            raise SystemExit(f"worker on {ranks} ranks failed")
        return json.loads(out.read_text())


def ms(v):
    return f"{1e3 * v:.1f}"


def imb(r):
    """Triangle pairs found per rank, max over mean: the narrow phase's load."""
    return f"{r['rows_max'] / max(r['rows_mean'], 1e-12):.2f}"


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--ribbon", default=None, help="HDF5 output of a ribbon run (last frame)")
    ap.add_argument("--ranks", type=int, nargs="+", default=[2, 4])
    ap.add_argument("--reps", type=int, default=7)
    ap.add_argument("--quick", action="store_true", help="no a/b sweep")
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--json", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    args.sweep_scene_label = SWEEP_SCENE
    if args.worker:
        worker(args)
        return
    res = []
    for r in args.ranks:
        res += run_ranks(r, args)
    print(f"Detection phase on frozen ribbon snapshots (4141 vertices, 8000 triangles, "
          f"thickness {1e3 * THICK:g} mm), median of {args.reps}; times in ms; busy = thread "
          f"CPU time in traversal chunks per rank; a = 2, b = 8, chunk = 256.\n")
    print("| scene | ranks | mode | tests | busy max | busy mean | max/mean | pairs max/mean "
          "| traversal wall | detection wall | tasks created | stolen | refused "
          "| steal latency (µs) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in res:
        if r["config"] not in ("static", "stealing"):
            continue
        print(f"| {r['scene']} ({r['kind']}) | {r['ranks']} | {r['config']} | {int(r['tests'])} "
              f"| {ms(r['busy_max'])} | {ms(r['busy_mean'])} "
              f"| {r['busy_max'] / max(r['busy_mean'], 1e-12):.2f} | {imb(r)} "
              f"| {ms(r['wall_max'])} | {ms(r['phase_max'])} | {int(r['tasks_created'])} "
              f"| {int(r['tasks_stolen'])} | {int(r['steals_refused'])} "
              f"| {1e6 * r['steal_latency_mean']:.0f} |")
    sweep = [r for r in res if r["config"].startswith("sweep")]
    if sweep:
        print(f"\nSweep of a, b and chunk on \"{sweep[0]['scene']}\" (stealing; static for "
              f"reference), times in ms.\n")
        print("| ranks | a | b | chunk | busy max | busy mean | max/mean | pairs max/mean "
              "| traversal wall | detection wall | tasks created | stolen | refused |")
        print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
        for r in res:
            if r["scene"] != sweep[0]["scene"] or r["config"] not in ("static",) \
                    and not r["config"].startswith("sweep"):
                continue
            a = "–" if r["config"] == "static" else f"{r['a']:g}"
            b = "static" if r["config"] == "static" else f"{int(r['b'])}"
            print(f"| {r['ranks']} | {a} | {b} | {int(r['chunk'])} | {ms(r['busy_max'])} "
                  f"| {ms(r['busy_mean'])} | {r['busy_max'] / max(r['busy_mean'], 1e-12):.2f} "
                  f"| {imb(r)} | {ms(r['wall_max'])} | {ms(r['phase_max'])} "
                  f"| {int(r['tasks_created'])} | {int(r['tasks_stolen'])} "
                  f"| {int(r['steals_refused'])} |")


if __name__ == "__main__":
    main()
