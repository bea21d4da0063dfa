"""``distcloth study stability``: every (case, integrator, setting) variant
simulated in process with the project's Simulation, collectively on the
ranks the command runs on, and classified (distcloth/study/classify.py).

Every rank takes the same decisions: config errors are agreed through
``Comm.agree``, the simulator agrees its numerical failures, and the
verdict comes from reduced (identical) numbers.
"""
from __future__ import annotations

import copy
import math
import os
import shlex
import sys
import time
from dataclasses import dataclass, field
from typing import Callable

from ..config.load import config_from_dict
from ..energy_guard import gravity_scale
from ..inprocess import agreed, build_simulation
from ..scene import build_model
from ..simulation import Simulation, SimulationError
from .cases import CASE_NAMES, CASES, get_case, steps_of
from .classify import REFUSED, Trace, classify
from .measure import PenetrationOracle
from .outcome import MAX_EXPLICIT_STEPS, MAX_EXPLICIT_STEPS_REDUCED, Result
from .report import markdown, write_csv

IMPLICIT = ("backward_euler", "bdf2", "implicit_midpoint", "newmark")
EXPLICIT = ("explicit_midpoint", "rk4", "symplectic_euler")
INTEGRATORS = IMPLICIT + EXPLICIT


@dataclass(frozen=True)
class Setting:
    name: str
    title: str
    integrators: tuple[str, ...]           # which integrators it applies to
    time: dict = field(default_factory=dict)
    material: dict = field(default_factory=dict)
    explicit_fraction: float | None = None  # h = min(case h, fraction * explicit limit)
    skip_cases: tuple[str, ...] = ()        # cases it does not run (cost)
    skip_full: tuple[tuple[str, str], ...] = ()   # (case, integrator) run reduced only (cost)
    force: bool = False                     # run explicit steps above the limit (run --force)


SETTINGS = {
    "case_step": Setting("case_step", "the case's step, one linearised Newton step (the "
                         "energy-momentum schemes: Newton to convergence, halving the steps "
                         "it does not converge; their 10,000-step long run only in the "
                         "reduced suite)", INTEGRATORS,
                         # 10,000 converged and halved steps: over 25 minutes each
                         skip_full=(("long_run", "implicit_midpoint"), ("long_run", "newmark"))),
    "newton": Setting("newton", "the case's step, Newton to 1e-8 (at most 10 iterations; "
                      "not run on the long run)", IMPLICIT,
                      time={"newton_iterations": 10, "newton_tolerance": 1e-8},
                      # 10,000 converged steps per integrator would double the full run
                      skip_cases=("long_run",)),
    "explicit_stable": Setting("explicit_stable", "explicit at half its Gershgorin step limit",
                               EXPLICIT, explicit_fraction=0.5),
    "explicit_forced": Setting("explicit_forced", "explicit at the case's step, forced past the "
                               "start-up refusal (distcloth run --force)", EXPLICIT, force=True),
    "mass_spring": Setting("mass_spring", "mass-spring membrane (Vassilev et al. 2001) and "
                           "flexion-spring bending instead of FE and hinges, the case's step, one Newton step "
                           "(not run on the long run)", INTEGRATORS,
                           material={"model": "mass_spring"}, skip_cases=("long_run",)),
}
DEFAULT_SETTINGS = ("case_step", "explicit_stable")
def scene_for(case, integrator: str, setting: Setting, reduced: bool) -> dict:
    raw = copy.deepcopy(case.scene(reduced))
    raw["time"].update(setting.time, integrator=integrator)
    if setting.material:
        for piece in raw["cloth"]:
            mat = piece["material"]
            mat.update(setting.material)
            if mat.get("model") == "mass_spring":   # continuum-only keys
                mat.pop("strain", None)
                mat.pop("bending_model", None)
    return raw


def _config(raw, name):
    return config_from_dict(raw, ".", name)


def _build(raw, case, comm, force=False):
    """(sim, note, None) or (None, note, refusal message); collective."""
    return build_simulation(raw, case.name, comm, force=force, hook=case.hook)


def _explicit_step(case, raw, comm, fraction):
    """(min(case h, fraction * the explicit step limit), None) or (None, refusal);
    collective. The limit comes from a Simulation that is never prepared (so
    never refused at start-up); the case's hook does not change it (the
    Gershgorin bound is taken at the rest shape)."""
    cfg, err = agreed(comm, lambda: _config(raw, case.name))
    if err:
        return None, err
    sim, err = agreed(comm, lambda: Simulation(cfg, build_model(cfg), comm, quiet=True))
    if err:
        return None, err
    limit, _ = sim.explicit_step_limits()
    sim.destroy()
    return min(raw["time"]["step"], fraction * limit), None


def run_variant(case, integrator: str, setting: Setting, comm, reduced: bool = False) -> Result:
    """Simulate one variant and classify it; collective on ``comm``."""
    t0 = time.perf_counter()
    raw = scene_for(case, integrator, setting, reduced)
    res = Result(case.name, integrator, setting.name, REFUSED, h=raw["time"]["step"])
    if setting.explicit_fraction is not None:
        h, err = _explicit_step(case, raw, comm, setting.explicit_fraction)
        if err:
            res.reason, res.wall = err, time.perf_counter() - t0
            return res
        cap = MAX_EXPLICIT_STEPS_REDUCED if reduced else MAX_EXPLICIT_STEPS
        # a long run keeps its step count; other cases their duration, capped
        n = steps_of(raw) if case.fixed_steps else min(int(math.ceil(raw["time"]["end"] / h)), cap)
        raw["time"]["step"], raw["time"]["end"] = h, n * h
        raw["output"]["every"] = n * h
        res.h = h
    res.steps_planned = steps_of(raw)
    sim, res.note, err = _build(raw, case, comm, force=setting.force)
    if err:
        res.reason, res.wall = err, time.perf_counter() - t0
        return res
    oracle = PenetrationOracle(sim.cfg)
    trace = Trace(gravity_scale=gravity_scale(sim.cfg, sim.model))
    ke, ge, el = sim.energies()
    trace.start_energy, trace.start_kinetic, trace.start_elastic = ke + ge + el, ke, el
    stop = None
    try:
        for _ in range(res.steps_planned):
            sim.step()
            trace.record(sim.state.t, *sim.energies(), oracle.worst(sim))
    except SimulationError as exc:
        stop = (exc.step, str(exc))
    finally:
        sim.destroy()
    verdict = classify(trace, case.criteria, stop)
    res.status, res.step, res.reason = verdict.status, verdict.step, verdict.reason
    res.energy_excess, res.slope_rise = verdict.energy_excess, verdict.slope_rise
    res.penetration, res.first_violation = verdict.penetration, verdict.first_violation
    res.trace = trace
    res.steps_run = len(trace.time)
    res.sim_time = trace.time[-1] if trace.time else 0.0
    res.wall = time.perf_counter() - t0
    return res


def variants(cases, integrators, settings, reduced=False):
    """(case, integrator, setting) in table order, only where the setting applies."""
    for s in settings:
        for c in cases:
            for i in integrators:
                if (i in s.integrators and c.name not in s.skip_cases
                        and (reduced or (c.name, i) not in s.skip_full)):
                    yield c, i, s


def run_suite(cases, integrators, settings, comm, reduced=False,
              progress: Callable[[str], None] | None = None) -> list[Result]:
    todo = list(variants(cases, integrators, settings, reduced))
    out = []
    for k, (c, i, s) in enumerate(todo, 1):
        r = run_variant(c, i, s, comm, reduced)
        out.append(r)
        if progress is not None:
            what = r.status + (f" at step {r.step}" if r.step is not None else "")
            progress(f"[{k}/{len(todo)}] {c.name} / {i} / {s.name}: {what} "
                     f"({r.steps_run} steps, {r.wall:.1f} s)")
    return out


# ------------------------------------------------------------------ command

def add_arguments(p) -> None:
    p.add_argument("--reduced", action="store_true",
                   help="the CI size: coarse meshes, few steps (300 for the long run)")
    p.add_argument("--cases", nargs="+", default=None, metavar="CASE", choices=CASE_NAMES,
                   help="cases to run (default: all): " + " ".join(CASE_NAMES))
    p.add_argument("--integrators", nargs="+", default=None, metavar="NAME",
                   choices=list(INTEGRATORS), help="integrators (default: all seven)")
    p.add_argument("--settings", nargs="+", default=list(DEFAULT_SETTINGS), metavar="NAME",
                   choices=list(SETTINGS),
                   help="settings (default: %(default)s): " + " ".join(SETTINGS))
    p.add_argument("--output", default=None, metavar="FILE.md",
                   help="write the Markdown report here and a CSV beside it "
                        "(default: print the tables)")


def main(args, comm) -> int:
    cases = [get_case(n) for n in args.cases] if args.cases else list(CASES)
    integrators = args.integrators or list(INTEGRATORS)
    settings = [SETTINGS[n] for n in args.settings]

    def say(msg):
        if comm.rank == 0:
            print(f"[stability] {msg}", file=sys.stderr, flush=True)
    if args.output is not None and not args.output.endswith(".md"):
        say(f"--output {args.output}: a file name ending in .md")
        return 2
    t0 = time.perf_counter()
    results = run_suite(cases, integrators, settings, comm, args.reduced, say)
    wall = time.perf_counter() - t0
    if comm.rank == 0:
        command = (f"scripts/mpiexec.sh {comm.size} .venv/bin/python -m distcloth "
                   + " ".join(shlex.quote(a) for a in sys.argv[1:]))
        text = markdown(results, cases, integrators, settings, reduced=args.reduced,
                        ranks=comm.size, wall=wall, command=command)
        if args.output:
            os.makedirs(os.path.dirname(os.path.abspath(args.output)), exist_ok=True)
            with open(args.output, "w", encoding="utf-8") as f:
                f.write(text)
            csv_path = args.output[:-3] + ".csv"
            write_csv(results, csv_path)
            say(f"wrote {args.output} and {csv_path} ({wall:.0f} s)")
        else:
            print(text)
    failed = sum(r.status == "FAILED" for r in results)
    say(f"{len(results)} variants, {failed} FAILED, {wall:.0f} s")
    return 0      # the verdicts are the result; FAILED variants are findings, not an error
