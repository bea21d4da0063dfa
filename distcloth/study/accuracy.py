"""``distcloth study accuracy SCENE.yaml --vary key=v1,v2 ...``: which settings
buy how much accuracy for how much time (issue 6, item 1).

Variants run collectively (distcloth/study/sweep.py), their errors against a
finer reference are measured on rank 0 (distcloth/study/metrics.py), and the
CSV, Markdown report and plots are written by rank 0
(distcloth/study/accuracy_report.py) into the study directory.

Study-module interface (distcloth/study/__init__.py): ``add_arguments(parser)``
and ``main(args, comm)``; ``main`` also accepts an argv list.
"""
from __future__ import annotations

import argparse
import math
import os
import shlex
import sys

import numpy as np

from . import sweep
from .metrics import compare

HELP = ("the accuracy study (issue 6): sweep settings, errors against a finer reference, "
        "wall time and stage split, CSV + Markdown + plots")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("scene", help="scene YAML file")
    p.add_argument("--vary", action="append", default=[], metavar="KEY=V1,V2",
                   help="an axis of the sweep: a scene key (time.step=0.02,0.01) or a shorthand: "
                        "resolution=9,17 (every grid piece), pc=jacobi,bjacobi_sgs,sgs32,gamg,hypre")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override the base scene for every run (reference included)")
    p.add_argument("--reference-set", action="append", default=[], metavar="KEY=VALUE",
                   help="override the reference only (after its defaults: step/4, bdf2, "
                        "Newton 1e-10, ksp_rtol 1e-10 unpreconditioned, finest resolution)")
    p.add_argument("--one-at-a-time", action="store_true",
                   help="vary each axis alone around the base scene instead of the full product")
    p.add_argument("--every", type=float, default=None,
                   help="seconds between compared frames (default: the scene's output.every)")
    p.add_argument("--dir", default=None,
                   help="study directory: results, CSV, report, plots (default out/accuracy/SCENE)")
    p.add_argument("--chaotic", action="store_true",
                   help="rank by centre-of-mass error and time to divergence, not positions")
    p.add_argument("--divergence", type=float, default=0.01, metavar="METRES",
                   help="RMS error that counts as diverged (default 0.01 m)")
    p.add_argument("--no-noise-floor", action="store_true", help="skip the perturbed reference rerun")


def say_on(comm):
    def say(msg):
        if comm.rank == 0:
            print(f"[accuracy] {msg}", file=sys.stderr, flush=True)
    return say


def load_scene(path: str) -> dict:
    from ..config.load import read_scene_file
    return read_scene_file(path)


def stage_seconds(result: dict) -> dict:
    return {k: float(np.nansum(v)) for k, v in result["stage_time"].items()}


def analyse(outcomes, *, divergence=0.01):
    """Rows (variants, then the reference and noise rerun) with their metrics
    against the reference; rank 0 only (reads the files serially)."""
    from ..io.h5read import read_result
    ref_o = next(o for o in outcomes if o.variant.role == "reference")
    if ref_o.status != "completed":
        raise RuntimeError(f"the reference did not complete ({ref_o.status}: {ref_o.message})")
    reference = read_result(ref_o.path)
    rows, noise = [], None
    for o in outcomes:
        row = {"name": o.variant.name, "role": o.variant.role, "status": o.status,
               "label": o.variant.label(), "settings": dict(o.variant.settings), "wall": o.wall,
               "stages": {}, "message": o.message, "perturb": o.variant.perturb}
        if o.status in ("completed", "failed") and os.path.exists(o.path):
            res = read_result(o.path)
            row["stages"] = stage_seconds(res)
            ksp = res["diagnostics"].get("ksp_iterations")
            row["ksp_iterations_mean"] = float(np.nanmean(ksp)) if ksp is not None and len(ksp) else math.nan
            if o.variant.role != "reference":
                try:
                    row.update(compare(res, reference, divergence_threshold=divergence))
                except ValueError as exc:
                    row["message"] = (row["message"] + "; " if row["message"] else "") + str(exc)
        if o.variant.role == "noise":
            noise = row
        rows.append(row)
    return rows, noise


def main(args, comm=None) -> int:
    if isinstance(args, (list, tuple)):            # main(argv, comm)
        p = argparse.ArgumentParser(prog="distcloth study accuracy", allow_abbrev=False)
        add_arguments(p)
        args = p.parse_args(list(args))
    if comm is None:
        from ..linalg.petsc import init_petsc
        init_petsc([])
        from ..parallel.comm import Comm
        comm = Comm()
    say = say_on(comm)
    try:
        raw = load_scene(args.scene)
        axes = sweep.parse_vary(args.vary)
        variants = sweep.plan(raw, axes, args.overrides, one_at_a_time=args.one_at_a_time,
                              reference_overrides=args.reference_set,
                              noise_floor=not args.no_noise_floor)
        error = None
    except Exception as exc:               # deterministic on every rank: all return together
        error = str(exc)
    if error is not None:
        say(f"error: {error}")
        return 2
    scene = os.path.splitext(os.path.basename(args.scene))[0]
    directory = args.dir or os.path.join("out", "accuracy", scene)
    n_var = sum(v.role == "variant" for v in variants)
    say(f"{n_var} variants + reference{'' if args.no_noise_floor else ' + noise floor'} "
        f"on {comm.size} rank(s) into {os.path.abspath(directory)}")
    outcomes = sweep.run_sweep(variants, raw, os.path.dirname(os.path.abspath(args.scene)),
                               args.scene, comm, directory, every=args.every, say=say)
    code = 0
    if comm.rank == 0:
        code = write_outputs(outcomes, axes, directory, scene, args, comm.size, say)
    return int(comm.bcast(code))


def write_outputs(outcomes, axes, directory, scene, args, ranks, say) -> int:
    from . import accuracy_report as rep
    try:
        rows, noise = analyse(outcomes, divergence=args.divergence)
    except RuntimeError as exc:
        say(f"error: {exc}")
        return 1
    error = "com_max_error" if args.chaotic else "rms_mean"
    var = [r for r in rows if r["role"] == "variant"]
    for i in rep.pareto(var, error=error):
        var[i]["pareto"] = True
    stages = sorted({s for r in rows for s, v in r["stages"].items() if v > 0})
    csv_path = os.path.join(directory, "accuracy.csv")
    rep.write_csv(csv_path, rows, list(axes), stages)
    plots = rep.plot(os.path.join(directory, ""), rows, noise, stages, error=error)
    ref = next(o.variant for o in outcomes if o.variant.role == "reference")
    command = (f"scripts/mpiexec.sh {ranks} .venv/bin/python -m distcloth study accuracy "
               + " ".join(shlex.quote(a) for a in sys.argv[3:]) if len(sys.argv) > 3 else
               f"distcloth study accuracy {args.scene}")
    md = os.path.join(directory, "accuracy.md")
    rep.write_markdown(md, rows, axes, noise, scene=scene, command=command,
                       reference_label=", ".join(o for o in ref.overrides if o not in args.overrides),
                       plots=plots, error=error, chaotic=args.chaotic)
    say(f"wrote {md}, {csv_path} and {len(plots)} plots")
    failed = [r["label"] for r in rows if r["status"] != "completed"]
    if failed:
        say(f"not completed: {'; '.join(failed)}")
    return 0
