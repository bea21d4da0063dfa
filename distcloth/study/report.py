"""The stability suite's outcome as Markdown (tables of cases x integrators,
one per setting, the criteria, a paragraph per case, the machine) and CSV."""
from __future__ import annotations

import csv
import dataclasses
import math
import os
import platform
import re

from .cases import FULL_RES, LONG_STEPS, LONG_STEPS_REDUCED, REDUCED_RES
from .classify import FAILED, REFUSED, STOPPED, SURVIVED, Criteria
from .outcome import MAX_EXPLICIT_STEPS, MAX_EXPLICIT_STEPS_REDUCED, Result


def _short(text: str, n: int = 70) -> str:
    text = text.replace("|", "/").replace("\n", " ")
    return text if len(text) <= n else text[: n - 1] + "…"


# (pattern of a stop's or failure's cause, its short form from the match)
_CAUSES = (
    (r"blow-up: a vertex moves at ([0-9.e+-]+) m/s", lambda m: f"blow-up ({float(m[1]):.2g} m/s)"),
    (r"NaN or Inf", lambda m: "NaN/Inf in the state"),
    (r"energy above E_ref \+ [0-9.e+-]+ S; largest excess ([0-9.e+-]+) S",
     lambda m: f"energy up to E_ref + {float(m[1]):.3g} S"),
    (r"energy gain: total energy ([0-9.e+-]+) S above", lambda m: f"energy gain {float(m[1]):.2g} S"),
    (r"Newton did not converge in (\d+) iterations", lambda m: f"Newton unconverged ({m[1]} its)"),
    (r"a vertex ([0-9.e+-]+) d inside a collider",
     lambda m: f"a vertex {float(m[1]):.2g} d inside a collider"),
)


def _cause(reason: str) -> str:
    """The short form of a stop's or failure's cause for a table cell."""
    why = re.sub(r"^step \d+: ", "", reason)
    for pattern, short in _CAUSES:
        m = re.match(pattern, why)
        if m:
            return short(m)
    return _short(why, 60)


def cell(r) -> str:
    """One table cell: the verdict and, for stops, refusals and failures, where and why
    (the full messages are in the CSV and, for failures, listed below the tables)."""
    if r.status == SURVIVED:
        return "survived"
    if r.status == REFUSED:
        m = re.search(r"unstable above ([0-9.eE+-]+) s", r.reason)
        return f"refused (limit {float(m.group(1)):.2g} s)" if m else "refused: " + _short(
            r.reason.replace("distcloth: config error: ", ""), 60)
    if r.status == STOPPED:
        extra = (f"; garbage from step {r.first_violation}"
                 if r.first_violation is not None and r.first_violation < r.step else "")
        return f"stopped at step {r.step}: {_cause(r.reason)}{extra}"
    return f"**FAILED** at step {r.step}: {_cause(r.reason)}"


def _table(results, cases, integrators, setting) -> list[str]:
    cols = [i for i in integrators if i in setting.integrators]
    by = {(r.case, r.integrator): r for r in results if r.setting == setting.name}
    lines = ["| case | " + " | ".join(cols) + " |", "|---" * (len(cols) + 1) + "|"]
    for c in cases:
        row = []
        for i in cols:
            r = by.get((c.name, i))
            row.append("—" if r is None else cell(r) + _step_note(r))
        lines.append(f"| {c.title} | " + " | ".join(row) + " |")
    return lines


def _step_note(r) -> str:
    """The step actually used when a setting changed it (explicit at its limit)."""
    if r.setting == "explicit_stable" and r.status != REFUSED and math.isfinite(r.h):
        return f" (h = {r.h:.2g} s, {r.steps_run} steps, {r.sim_time:.3g} s)"
    return ""


def cpu_model() -> str:
    """The processor's name (/proc/cpuinfo's first "model name"; '' where
    there is none): machines of one kind can differ in it, and a V-cycle of
    the same size took 2.3 times as long on one as on another."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return ""


def machine() -> str:
    pretty = platform.platform()
    try:
        with open("/etc/os-release", encoding="utf-8") as f:
            for line in f:
                if line.startswith("PRETTY_NAME="):
                    pretty = line.split("=", 1)[1].strip().strip('"')
    except OSError:
        pass
    cpu = cpu_model()
    return (f"{os.cpu_count()}-core {pretty} ({platform.machine()}{', ' + cpu if cpu else ''}), "
            f"Python {platform.python_version()}")


def _sizes(reduced: bool) -> str:
    res = REDUCED_RES if reduced else FULL_RES
    pinch = 13 if reduced else 25
    long = LONG_STEPS_REDUCED if reduced else LONG_STEPS
    cap = MAX_EXPLICIT_STEPS_REDUCED if reduced else MAX_EXPLICIT_STEPS
    return (f"{'REDUCED (CI)' if reduced else 'full'} sizes: sheets of {res} x {res} vertices "
            f"(pinch {pinch} x {pinch}), the long run {long:,} steps; explicit schemes at half "
            f"their step limit run the case's duration capped at {cap:,} steps (the long run "
            f"all its {long:,})")


def _margins(results) -> str:
    """The measured gap the energy bound sits in: largest excess that survived,
    smallest that FAILED on energy."""
    ok = [r.energy_excess for r in results
          if r.status == SURVIVED and math.isfinite(r.energy_excess)]
    bad = [r.energy_excess for r in results
           if r.status == FAILED and r.reason.startswith("energy above")]
    parts = []
    if ok:
        parts.append(f"the largest excess of a run that survived is {max(ok):.2g} S")
    if bad:
        parts.append(f"the smallest largest-excess of a run FAILED on energy is {min(bad):.2g} S")
    return ("In this run " + " and ".join(parts) + ".") if parts else ""


def _summary(results, integrators, settings) -> list[str]:
    lines = ["| setting | integrator | survived | stopped | refused | FAILED |",
             "|---|---|---:|---:|---:|---:|"]
    for s in settings:
        for i in integrators:
            rs = [r for r in results if r.setting == s.name and r.integrator == i]
            if rs:
                n = [sum(r.status == st for r in rs) for st in (SURVIVED, STOPPED, REFUSED, FAILED)]
                lines.append(f"| {s.name} | {i} | " + " | ".join(map(str, n)) + " |")
    return lines


def markdown(results, cases, integrators, settings, *, reduced, ranks, wall, command=None) -> str:
    crit = Criteria()
    counts = {s: sum(r.status == s for r in results) for s in (SURVIVED, STOPPED, REFUSED, FAILED)}
    cmd = command or ("scripts/mpiexec.sh 2 .venv/bin/python -m distcloth study stability "
                      + ("--reduced " if reduced else "") + "--output docs/stability.md")
    out = [
        "# Stability suite",
        "",
        "Generated by `distcloth study stability`: every case below, simulated "
        "with every integrator under each setting, in process with the project's "
        "`Simulation`, and classified. Do not edit by hand; rerun the command "
        "(`scripts/stability_suite.py` runs the full suite and lists what FAILED):",
        "",
        f"    {cmd}",
        "",
        f"Machine: {machine()}; {ranks} MPI ranks. {_sizes(reduced)}. {len(results)} variants "
        f"in {wall / 60:.1f} min: {counts[SURVIVED]} survived, {counts[STOPPED]} stopped, "
        f"{counts[REFUSED]} refused, {counts[FAILED]} FAILED. Per-variant figures (steps, "
        "largest energy excess, slope, penetration, wall time): the CSV beside this file. "
        "The CI runs the reduced suite (`tests/test_stability.py`).",
        "",
        "## Verdicts",
        "",
        "- **survived**: the run reached its end and every step passed the criteria below;",
        "- **stopped**: the simulator raised an error naming the step and the cause (NaN, "
        "blow-up above 1000 m/s, failed solve, or its energy guard: a passive scene's "
        "energy above E_ref + 0.1 S, the same bound as criterion 2, "
        "distcloth/energy_guard.py): a clear stop, the result file says so; "
        "\"garbage from step k\" when earlier steps already broke a criterion;",
        "- **refused**: the scene was refused before the first step (explicit schemes above "
        "their Gershgorin step limit; `distcloth run --force` overrides it);",
        "- **FAILED**: the run went to its end but some step broke a criterion and nothing "
        "said so: a silent garbage result;",
        "- —: the setting does not run this case (cost).",
        "",
        "Criteria (distcloth/study/classify.py). E = kinetic + gravitational + elastic energy "
        "of every force term, computed from the state after each step; S = KE + elastic "
        "energy at the reference + M |g| L (M the cloth's mass, L its bounding-box "
        "diagonal), the energy the run can exchange between its forms:",
        "",
        "1. E finite at every step;",
        f"2. E <= E_ref + {crit.energy_tolerance:g} S at every step, E_ref the start energy "
        "(pinch: the energy when the colliders stop, since moving colliders do work). Nothing "
        "else does work on the cloth, so E may only fall (backward Euler, BDF-2) or oscillate "
        "(implicit midpoint, Newmark, symplectic Euler, RK4 at small steps). "
        + _margins(results),
        f"3. long run: over the last {crit.slope_fraction:.0%} of the steps, the least-squares "
        f"line through E(t) rises by at most max(3 sigma, {crit.slope_floor:g} S), sigma the "
        "scatter about the line (a bounded oscillation fits a smaller rise, a drift does not);",
        f"4. collision cases: no free vertex ends a step deeper than "
        f"{crit.penetration_tolerance:g} d inside a collider's offset (d = contact offset; "
        "independent signed distance of the end-of-step positions, not the simulator's own "
        "diagnostic).",
        "",
        "Material for every case unless it says otherwise: a 0.5 m square sheet (alternating "
        "triangles), linear FE membrane (St. Venant–Kirchhoff, Y = 100 N/m, nu = 0.3), "
        "dihedral hinge bending B = 1e-5 N·m, 0.1 kg/m², no damping or drag, hanging from its "
        "two top corners; the default solver (CG + block Jacobi/SGS, rtol 1e-5).",
        "",
        "## Summary",
        "",
        *_summary(results, integrators, settings),
        "",
    ]
    for s in settings:
        out += [f"## Setting `{s.name}`: {s.title}", ""]
        out += _table(results, cases, integrators, s) + [""]
    failed = [r for r in results if r.status == FAILED]
    if failed:
        out += ["## FAILED variants", ""]
        out += [f"- {r.case} / {r.integrator} / {r.setting}: step {r.step}: {r.reason}"
                for r in failed] + [""]
    out += ["## Cases", ""]
    for c in cases:
        notes = sorted({r.note for r in results if r.case == c.name and r.note})
        steps = sorted({r.steps_planned for r in results
                        if r.case == c.name and r.setting != "explicit_stable"})
        hs = sorted({r.h for r in results if r.case == c.name and r.setting != "explicit_stable"})
        head = f"**{c.title}** (`{c.name}`"
        if hs and steps:
            head += f", h = {hs[0]:g} s, {steps[0]:,} steps"
        head += ")"
        out += [f"{head}. {c.about}" + (f" Built: {'; '.join(notes)}." if notes else ""), ""]
    return "\n".join(out)


def csv_fields() -> list[str]:
    return [f.name for f in dataclasses.fields(Result) if f.name != "trace"]


def write_csv(results, path: str) -> None:
    fields = csv_fields()
    with open(path, "w", newline="", encoding="utf-8") as f:
        w = csv.DictWriter(f, fieldnames=fields)
        w.writeheader()
        for r in results:
            row = {k: getattr(r, k) for k in fields}
            for k, v in row.items():
                if isinstance(v, float):
                    row[k] = f"{v:.6g}"
            w.writerow(row)
