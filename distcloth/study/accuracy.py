"""``distcloth study accuracy SCENE.yaml --vary key=v1,v2 ...``: which settings
buy how much accuracy for how much time.

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

from ..config.load import apply_overrides, read_scene_file
from ..io.h5read import read_result
from ..linalg.petsc import init_petsc
from ..parallel.comm import Comm
from . import accuracy_report as rep
from . import sweep
from .metrics import compare, nanmax, reference_drape, support_disc_area


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("scene", help="scene YAML file")
    p.add_argument("--vary", action="append", default=[], metavar="KEY=V1,V2",
                   help="an axis of the sweep: a scene key (time.step=0.02,0.01) or a shorthand: "
                        "resolution=9,17 (every grid piece), pc=jacobi,bjacobi_sgs,sgs32,gamg,hypre, "
                        "limiter=off,provot,velocity (the strain_limiting effect), "
                        "combo='k1=v1;k2=v2' (one variant setting several keys)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override the base scene for every run (reference included)")
    p.add_argument("--reference-set", action="append", default=[], metavar="KEY=VALUE",
                   help="override the reference only (after its defaults: step/4, bdf2, "
                        "Newton 1e-10, ksp_rtol 1e-10 unpreconditioned, finest resolution)")
    p.add_argument("--one-at-a-time", action="store_true",
                   help="vary each axis alone around the base scene instead of the full product")
    p.add_argument("--alone", action="append", default=[], metavar="KEY=V1,V2",
                   help="an axis varied by itself around the base scene, beside the --vary product "
                        "(e.g. pc=gamg,hypre); compared with the variant that is the base scene")
    p.add_argument("--every", type=float, default=None,
                   help="seconds between compared frames (default: the scene's output.every)")
    p.add_argument("--dir", default=None,
                   help="study directory: results, CSV, report, plots (default out/accuracy/SCENE)")
    p.add_argument("--chaotic", action="store_true",
                   help="rank by centre-of-mass error, energies and drape measures, not positions "
                        "(chosen automatically when the noise floor diverges within the run)")
    p.add_argument("--divergence", type=float, default=0.01, metavar="METRES",
                   help="RMS error that counts as diverged (default 0.01 m)")
    p.add_argument("--no-noise-floor", action="store_true", help="skip the perturbed reference rerun")


def say_on(comm):
    def say(msg):
        if comm.rank == 0:
            print(f"[accuracy] {msg}", file=sys.stderr, flush=True)
    return say


def load_scene(path: str) -> dict:
    return read_scene_file(path)


def stage_seconds(result: dict) -> dict:
    return {k: float(np.nansum(v)) for k, v in result["stage_time"].items()}


def _run_row(o) -> dict:
    """What a variant's outcome says before any comparison."""
    return {"name": o.variant.name, "role": o.variant.role, "status": o.status,
            "label": o.variant.label(), "settings": dict(o.variant.settings), "wall": o.wall,
            "stages": {}, "message": o.message, "perturb": o.variant.perturb,
            "base": o.variant.base, "alone": o.variant.alone}


def _solver_counts(row: dict, res: dict) -> None:
    """Stage seconds, mean KSP iterations, steps whose Newton loop ran out of iterations."""
    row["stages"] = stage_seconds(res)
    diag = res["diagnostics"]
    ksp = diag.get("ksp_iterations")
    row["ksp_iterations_mean"] = float(np.nanmean(ksp)) if ksp is not None and len(ksp) else math.nan
    row["steps"] = int(len(diag.get("step", ())))
    unconverged = nanmax(res, "newton_unconverged")           # a running count
    row["newton_unconverged"] = 0 if math.isnan(unconverged) else int(unconverged)
    row["newton_residual_max"] = nanmax(res, "newton_residual")


def analyse(outcomes, *, divergence=0.01, support_area=0.0):
    """Rows (variants, then the reference and noise rerun) with their metrics
    against the reference; rank 0 only (reads the files serially).  The
    reference's row carries its own drape measures over time (``times``, ``drape``)."""
    ref_o = next(o for o in outcomes if o.variant.role == "reference")
    if ref_o.status != "completed":
        raise RuntimeError(f"the reference did not complete ({ref_o.status}: {ref_o.message})")
    reference = read_result(ref_o.path)
    ref_drape = reference_drape(reference, support_area)
    rows, noise = [], None
    for o in outcomes:
        row = _run_row(o)
        if o.status in ("completed", "failed") and os.path.exists(o.path):
            res = read_result(o.path)
            _solver_counts(row, res)
            if o.status == "failed":       # the file's cause: the same whether run now or resumed
                row["message"] = str(res["attrs"].get("error", "") or row["message"])
            if o.variant.role == "reference":
                row.update(times=np.asarray(reference["time"]), drape=ref_drape)
            else:
                try:
                    row.update(compare(res, reference, divergence_threshold=divergence,
                                       support_area=support_area, ref_drape=ref_drape))
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
        init_petsc([])
        comm = Comm()
    say = say_on(comm)
    try:
        raw = load_scene(args.scene)
        axes = sweep.parse_vary(args.vary)
        alone = sweep.parse_vary(args.alone)
        variants = sweep.plan(raw, axes, args.overrides, one_at_a_time=args.one_at_a_time,
                              reference_overrides=args.reference_set,
                              noise_floor=not args.no_noise_floor, alone=alone)
        error = None
    except Exception as exc:               # deterministic on every rank: all return together
        error = str(exc)
    if error is not None:
        say(f"error: {error}")
        return 2
    base_dir = os.path.dirname(os.path.abspath(args.scene))
    refused = sweep.refusals(variants, raw, base_dir, args.scene, comm, every=args.every)
    # no comparison is possible without the reference or any variant: stop before
    # the reference's long run rather than after it
    roles = {v.role for v in variants if v.name not in refused}
    if refused and ("reference" not in roles or "variant" not in roles):
        for var in variants:
            if var.name in refused:
                say(f"{var.role} {var.label()}: refused: {refused[var.name]}")
        say("error: " + ("the reference is refused" if "reference" not in roles
                         else "every variant is refused") + ": nothing to compare")
        return 2
    scene = os.path.splitext(os.path.basename(args.scene))[0]
    directory = args.dir or os.path.join("out", "accuracy", scene)
    n_var = sum(v.role == "variant" for v in variants)
    say(f"{n_var} variants + reference{'' if args.no_noise_floor else ' + noise floor'} "
        f"on {comm.size} rank(s) into {os.path.abspath(directory)}")
    outcomes = sweep.run_sweep(variants, raw, base_dir, args.scene, comm, directory,
                               every=args.every, say=say)
    code = 0
    if comm.rank == 0:
        code = write_outputs(outcomes, {**axes, **alone}, directory, scene, args, comm.size, say,
                             support_area=support_disc_area(_base_scene(raw, args.overrides)))
    return int(comm.broadcast(code))


def _base_scene(raw: dict, overrides) -> dict:
    return apply_overrides(sweep.normalise_scene(raw), tuple(overrides))


def _command(args, ranks: int) -> str:
    """The command as typed (from sys.argv), for the report's first line."""
    if len(sys.argv) > 3 and sys.argv[1:3] == ["study", "accuracy"]:
        return (f"scripts/mpiexec.sh {ranks} .venv/bin/python -m distcloth study accuracy "
                + " ".join(shlex.quote(a) for a in sys.argv[3:]))
    return f"distcloth study accuracy {args.scene}"


def write_outputs(outcomes, axes, directory, scene, args, ranks, say, *, support_area=0.0) -> int:
    try:
        rows, noise = analyse(outcomes, divergence=args.divergence, support_area=support_area)
    except RuntimeError as exc:
        say(f"error: {exc}")
        return 1
    chaos = rep.chaos(noise, args.divergence, forced=args.chaotic)
    if chaos["auto"]:
        say(f"the noise floor diverges at t = {chaos['horizon']:.3g} s: treated as chaotic")
    error = rep.ranking_metric(chaos["chaotic"])
    # a variant that stopped early is compared over its frames only: not ranked
    var = [r for r in rows if r["role"] == "variant" and r["status"] == "completed"]
    for i in rep.pareto(var, error=error):
        var[i]["pareto"] = True
    stages = sorted({s for r in rows for s, v in r["stages"].items() if v > 0})
    csv_path = os.path.join(directory, "accuracy.csv")
    rep.write_csv(csv_path, rows, list(axes), stages)
    plots = rep.plot(os.path.join(directory, ""), rows, noise, stages, error=error, chaos=chaos)
    ref = next(o.variant for o in outcomes if o.variant.role == "reference")
    md = os.path.join(directory, "accuracy.md")
    rep.write_markdown(md, rows, axes, noise, scene=scene, command=_command(args, ranks),
                       reference_label=", ".join(o for o in ref.overrides if o not in args.overrides),
                       plots=plots, error=error, chaos=chaos, divergence=args.divergence,
                       support_area=support_area, alone=list(sweep.parse_vary(args.alone)))
    say(f"wrote {md}, {csv_path} and {len(plots)} plots")
    failed = [r["label"] for r in rows if r["status"] != "completed"]
    if failed:
        say(f"not completed: {'; '.join(failed)}")
    return 0
