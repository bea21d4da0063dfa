"""``distcloth inspect RESULT.h5``: what a result file holds, read serially.

The scene, the ranks, the status (a 'running' file whose processes are gone
is reported as killed: io/liveness.py), steps and frames written, the
checkpoint to resume from, the time per stage summed over the steps
(/diagnostics/stage_time), and warnings: those the run recorded (attribute
warnings) and those the diagnostics show; ``--plots``
writes the preview pictures again.
"""
from __future__ import annotations

import os
import sys

import numpy as np

from .io.checkpoint import checkpoint_path, read_checkpoint
from .io.h5read import read_result
from .io.h5writer import FORMAT_NAME
from .io.liveness import judge


def describe(path: str) -> list[str]:
    """The report's lines; ValueError/OSError for a file that is not a result."""
    res = read_result(path, positions=False)
    a = res["attrs"]
    if a.get("format") != FORMAT_NAME:
        raise ValueError("not a distcloth result file")
    lines = [f"result:     {os.path.abspath(path)} ({a.get('format')} version "
             f"{a.get('format_version')})",
             f"scene:      {a.get('scene', '?')}" + (f" ({a['phase']} phase)" if "phase" in a else ""),
             f"ranks:      {a.get('ranks', '?')}; integrator "
             f"{a.get('integrator', '?')}, h = {a.get('time_step', '?')} s, solver "
             f"{a.get('solver', '?')}"]
    lines.append("status:     " + _status(a))
    steps, times = res["diagnostics"].get("step", np.zeros(0)), res["time"]
    planned = a.get("steps")
    span = f" (last step {int(steps[-1])}, t = {res['diagnostics']['time'][-1]:g} s)" if len(steps) else ""
    lines.append(f"steps:      {res['steps_written']} written" +
                 (f" of {planned}" if planned is not None else "") + span)
    lines.append(f"frames:     {res['frames_written']} written" +
                 (f", t = {times[0]:g} .. {times[-1]:g} s" if len(times) else ""))
    resumed = [int(s) for s in np.atleast_1d(a.get("resumed_at", []))]
    if resumed:
        lines.append(f"resumed:    at step {', '.join(map(str, resumed))}")
    lines.append("checkpoint: " + _checkpoint(path, a))
    lines += _stage_times(res["stage_time"], res["stage_calls"])
    warnings = _recorded_warnings(a) + _warnings(res["diagnostics"])
    lines.append("warnings:   " + ("none" if not warnings else warnings[0]))
    lines += [f"            {w}" for w in warnings[1:]]
    return lines


def _status(a) -> str:
    status = a.get("status", "?")
    if status == "no_rest_state":
        return f"no rest state at iteration {a.get('error_step')}: {a.get('error', '')}"
    if status == "failed":
        return f"failed at step {a.get('error_step')}: {a.get('error', '')}"
    if status == "interrupted":
        return f"interrupted by {a.get('interrupted_by', 'a signal')} after step " \
               f"{a.get('interrupted_step')}"
    if status == "running":
        return f"running: {judge(a)[1]}"
    if status == "completed_with_warnings":
        return "completed_with_warnings (the run reached its end; see warnings below)"
    return str(status)


def _checkpoint(path: str, a) -> str:
    name = a.get("checkpoint") or os.path.basename(checkpoint_path(path))
    ckpt = os.path.join(os.path.dirname(os.path.abspath(path)), str(name))
    if not os.path.isfile(ckpt):
        return "none"
    try:
        scalars, _, _ = read_checkpoint(ckpt)
    except (OSError, ValueError) as exc:
        return f"{ckpt} is unreadable ({exc})"
    return (f"{ckpt}: step {scalars.get('step')}, t = {float(scalars.get('time', 0.0)):g} s, "
            f"written on {scalars.get('ranks')} ranks (distcloth run SCENE --resume {path})")


def _stage_times(stage_time: dict, stage_calls: dict) -> list[str]:
    total = {k: float(np.nansum(v)) for k, v in stage_time.items()}
    calls = {k: int(np.sum(v)) for k, v in stage_calls.items()}
    run = {k: v for k, v in total.items() if calls.get(k, 0)}
    if not run:
        return ["stage time: none recorded"]
    whole = sum(run.values()) or 1.0
    lines = [f"stage time (rank 0, s, summed over the steps; {whole:.3f} s in all):"]
    for name, seconds in sorted(run.items(), key=lambda kv: -kv[1]):
        lines.append(f"  {name:<20}{seconds:>10.3f}{100 * seconds / whole:>7.1f}%"
                     f"{calls[name]:>9} calls")
    return lines


def _recorded_warnings(a) -> list[str]:
    """The warnings the run recorded (attribute warnings: the energy guard's,
    when it was off), each with its step."""
    return [str(w) for w in np.atleast_1d(a.get("warnings", []))]


def _warnings(diag: dict) -> list[str]:
    """What the diagnostics say went wrong but did not stop the run."""
    out = []

    def last(name):
        v = diag.get(name)
        return float(v[-1]) if v is not None and len(v) and np.isfinite(v[-1]) else 0.0

    if last("newton_unconverged"):
        out.append(f"{int(last('newton_unconverged'))} accepted steps whose Newton loop ran out "
                   f"(newton_unconverged)")
    if last("rejected_steps"):
        out.append(f"{int(last('rejected_steps'))} rejected attempts, retried at half the step "
                   f"(rejected_steps)")
    if "self_intersections" in diag and np.nanmax(diag["self_intersections"], initial=0) > 0:
        out.append(f"cloth crossing itself in {int(np.sum(diag['self_intersections'] > 0))} steps "
                   f"(self_intersections)")
    return out


def inspect(path: str, plots: bool = False) -> int:
    """The command: report on stdout; exit 2 with one line for a bad file."""
    try:
        lines = describe(path)
    except (OSError, ValueError, KeyError) as exc:
        reason = exc.args[0] if isinstance(exc, KeyError) and exc.args else exc
        print(f"{path}: not a readable distcloth result file ({reason})", file=sys.stderr)
        return 2
    print("\n".join(lines), flush=True)
    if plots:
        # matplotlib takes a second to import: only --plots pays for it
        from .io.preview import write_previews
        for p in write_previews(path):
            print(f"preview: {os.path.abspath(p)}")
    return 0
