"""The stability suite (distcloth study stability, docs/stability.md) at CI
size, in process on both ranks of the test job, plus the classifier's own
tests.

* the reduced suite (every case, every integrator at the case's step, the
  explicit ones also at half their step limit, backward Euler also with
  Newton to convergence) ends no variant FAILED: each survives or stops
  naming the step and the cause (KNOWN_FAILED, empty since the energy guard);
  every verdict agrees with how its run ended (a survivor ran every step, a
  stop names its step, only explicit schemes at the case's step are refused);
* specific expectations: backward Euler survives every case with Newton
  converged, and every case but the two largest steps with one Newton step
  (where the energy guard stops it at these sizes; docs/stability.md);
  an explicit integrator at 0.1 s is refused at start-up, naming the step and
  its limit, and forced past the refusal it stops naming the step and cause;
* the classifier can fail: garbage the simulator does not see (its health
  check switched off, a NaN injected, a forced explicit blow-up) is FAILED,
  never survived; synthetic traces check each criterion alone;
* the command writes the Markdown table and the CSV (own mpiexec, rank 0).
"""
from __future__ import annotations

import csv
import math
import re

import numpy as np
import pytest

from conftest import run_cli
from distcloth.study import perturb
from distcloth.study.cases import CASES, get_case
from distcloth.study.classify import (FAILED, REFUSED, STOPPED, SURVIVED, Criteria, Trace,
                                      classify)
from distcloth.study.stability import (EXPLICIT, IMPLICIT, INTEGRATORS, SETTINGS, run_suite,
                                       run_variant)

# Silent garbage results of the reduced suite on 2 ranks that are allowed
# (analysis: docs/stability.md). Before the energy guard (distcloth/
# energy_guard.py) this held 20 variants: one linearised step at h >= 0.05 s,
# implicit midpoint and Newmark gaining energy without bound on the nonlinear
# membrane, the pinch gaining energy once its spheres stop, explicit schemes
# from strained starts. The guard now stops every one of them naming the
# step and the gain, and friction inside the solve (distcloth/physics/
# contact_friction.py) lets the pinch survive, so none is allowed: a variant
# that ends FAILED breaks test_no_unexpected_failure.
KNOWN_FAILED: set = set()


@pytest.fixture(scope="module")
def comm():
    from distcloth.linalg.petsc import init_petsc
    init_petsc([])
    from distcloth.parallel.comm import Comm
    return Comm()


@pytest.fixture(scope="module")
def suite(comm):
    """{(case, integrator, setting): Result} of the reduced suite (about 30 s on 2 ranks)."""
    results = run_suite(CASES, INTEGRATORS, [SETTINGS["case_step"], SETTINGS["explicit_stable"]],
                        comm, reduced=True)
    results += run_suite([c for c in CASES if c.name not in SETTINGS["newton"].skip_cases],
                         ["backward_euler"], [SETTINGS["newton"]], comm, reduced=True)
    return {(r.case, r.integrator, r.setting): r for r in results}


def test_every_variant_ran(suite):
    """Every variant has a verdict consistent with how its run ended (the
    classifier's contract, distcloth/study/classify.py), and only the
    explicit schemes at the case's step may be refused."""
    n = len(CASES)
    assert len(suite) == n * len(INTEGRATORS) + n * len(EXPLICIT) + (n - 1)
    for (case, integrator, setting), r in suite.items():
        key = (case, integrator, setting, r.status, r.step, r.reason)
        assert r.steps_planned > 0, key
        if r.status == SURVIVED:
            # ran to its end, nothing to report
            assert r.steps_run == r.steps_planned and r.step is None and r.reason == "", key
        elif r.status == STOPPED:
            # the simulator's error names the step and the cause, and the run ended early
            assert r.step is not None and r.reason.startswith(f"step {r.step}: "), key
            assert r.steps_run < r.steps_planned, key
        elif r.status == REFUSED:
            # refused before the first step, saying why: only an explicit scheme at
            # the case's step (above its limit); the stable setting halves the limit
            assert r.steps_run == 0 and r.reason, key
            assert integrator in EXPLICIT and setting == "case_step", key
        else:
            # FAILED (test_no_unexpected_failure says whether that is allowed): the
            # run went to its end and the verdict names the first bad step
            assert r.status == FAILED, key
            assert r.steps_run == r.steps_planned and r.step is not None and r.reason, key


def test_no_unexpected_failure(suite):
    failed = {k for k, r in suite.items() if r.status == FAILED}
    unexpected = {k: suite[k].reason for k in failed - KNOWN_FAILED}
    assert not unexpected, unexpected


def test_backward_euler_survives(suite):
    for c in CASES:
        if c.name not in SETTINGS["newton"].skip_cases:
            r = suite[(c.name, "backward_euler", "newton")]
            assert r.status == SURVIVED, (c.name, r.reason)
        if c.name not in ("large_step_0.05", "large_step_0.1"):
            r = suite[(c.name, "backward_euler", "case_step")]
            assert r.status == SURVIVED, (c.name, r.reason)


def test_explicit_at_a_large_step_is_refused_naming_step_and_limit(suite):
    for i in EXPLICIT:
        r = suite[("large_step_0.1", i, "case_step")]
        assert r.status == REFUSED
        assert re.search(r"time\.step: 0\.1 .* unstable above [0-9.e-]+ s", r.reason), r.reason


def test_explicit_forced_at_a_large_step_stops_naming_step_and_cause(comm):
    for i in EXPLICIT:
        r = run_variant(get_case("large_step_0.1"), i, SETTINGS["explicit_forced"], comm,
                        reduced=True)
        assert r.status == STOPPED, (i, r.status, r.reason)
        assert r.reason.startswith(f"step {r.step}: ")
        assert re.search("blow-up|NaN|energy gain", r.reason)


def test_collision_cases_touch(suite):
    # the oracle ran, and the cloth did reach the colliders (a vertex within
    # half an offset of a surface) in the implicit runs
    for case in ("impact", "pinch"):
        for i in IMPLICIT:
            r = suite[(case, i, "case_step")]
            if r.status != STOPPED:
                assert r.penetration > -0.5, (case, i, r.penetration)


def test_case_builds():
    from distcloth.config.load import config_from_dict
    from distcloth.scene import build_model
    for reduced in (True, False):
        model = build_model(config_from_dict(get_case("stiff").scene(reduced), ".", "stiff"))
        raw = get_case("stiff").scene(reduced)["cloth"][0]["material"]
        ratio = raw["stretch"] * perturb.mean_edge_length(model) ** 2 / raw["bending"]
        assert ratio >= 1e6
    model = build_model(config_from_dict(get_case("inverted").scene(True), ".", "x"))
    assert perturb.invert(model) > 0
    model = build_model(config_from_dict(get_case("degenerate").scene(True), ".", "x"))
    assert perturb.degenerate(model) > 0
    model = build_model(config_from_dict(get_case("crumpled").scene(True), ".", "x"))
    perturb.crumple(model)
    span = np.ptp(model.initial_positions[:, 2])
    assert 0.1 * 0.5 < span < 0.4 * 0.5           # 15 % of the size each way


# ------------------------------------------------------------ the classifier

def test_nan_is_stopped_by_the_simulator(comm, monkeypatch):
    # the injected NaN (rank 0, after step 3) is caught by the health check
    monkeypatch.setenv("DISTCLOTH_INJECT_NAN", "0:3")
    r = run_variant(get_case("long_run"), "symplectic_euler", SETTINGS["explicit_stable"], comm,
                    reduced=True)
    assert r.status == STOPPED and r.step == 3 and "NaN" in r.reason, r


def test_nan_behind_a_disabled_check_is_failed(comm, monkeypatch):
    from distcloth.simulation import Simulation
    monkeypatch.setenv("DISTCLOTH_INJECT_NAN", "0:3")
    monkeypatch.setattr(Simulation, "_check_state", lambda self: (None, self.energies()))
    r = run_variant(get_case("long_run"), "symplectic_euler", SETTINGS["explicit_stable"], comm,
                    reduced=True)
    assert r.status == FAILED and r.step == 3 and "non-finite" in r.reason, r


def test_undetected_blow_up_is_failed(comm, monkeypatch):
    # symplectic Euler forced at 0.1 s explodes within 3 steps (later steps
    # overflow into errors the simulator does catch); with its health check
    # off nothing stops the 3 steps, and the classifier must say so
    import dataclasses
    from distcloth.simulation import Simulation
    base = get_case("large_step_0.1")

    def short(reduced):
        raw = base.scene(reduced)
        raw["time"]["end"] = 3 * raw["time"]["step"]
        return raw
    monkeypatch.setattr(Simulation, "_check_state", lambda self: (None, self.energies()))
    r = run_variant(dataclasses.replace(base, scene=short), "symplectic_euler",
                    SETTINGS["explicit_forced"], comm, reduced=True)
    assert r.steps_run == 3
    assert r.status == FAILED and r.step == 1 and "energy above" in r.reason, r
    assert r.energy_excess > 1e3


def _trace(energy, t=None, pen=None, e0=1.0, scale=1.0):
    tr = Trace(start_energy=e0, gravity_scale=scale)
    t = np.arange(1, len(energy) + 1) * 0.01 if t is None else t
    for k, e in enumerate(energy):
        tr.record(t[k], 0.0, e, 0.0, math.nan if pen is None else pen[k])
    return tr


def test_classify_energy_bound():
    crit = Criteria()
    ok = 1.0 + 0.05 * np.sin(np.arange(100))              # oscillation within 0.1 S
    assert classify(_trace(ok), crit).status == SURVIVED
    bad = ok.copy()
    bad[40] = 1.0 + 0.11                                  # one step above the bound
    v = classify(_trace(bad), crit)
    assert v.status == FAILED and v.step == 41 and "largest excess 0.11 S at step 41" in v.reason
    # a stop keeps its own step and message, and reports the earlier violation
    v = classify(_trace(bad), crit, stop=(60, "step 60: blow-up"))
    assert v.status == STOPPED and v.step == 60 and v.first_violation == 41
    # the window: a rise before window_start (moving colliders) is not judged
    t = np.arange(1, 101) * 0.01
    rise = np.where(t <= 0.3, 1.0 + 3 * t, 1.9 + 0.01 * np.cos(t))
    assert classify(_trace(rise, t), Criteria(window_start=0.3)).status == SURVIVED
    assert classify(_trace(rise, t), crit).status == FAILED


def test_classify_nan_and_penetration():
    e = np.ones(20)
    e[7] = np.nan
    v = classify(_trace(e), Criteria())
    assert v.status == FAILED and v.step == 8
    pen = np.full(20, -1.0)
    pen[12] = 0.15                                        # 0.15 d inside > 0.1 d
    v = classify(_trace(np.ones(20), pen=pen), Criteria())
    assert v.status == FAILED and v.step == 13 and "inside a collider" in v.reason
    pen[12] = 0.09
    assert classify(_trace(np.ones(20), pen=pen), Criteria()).status == SURVIVED


def test_classify_slow_drift():
    crit = Criteria(slope_check=True)
    k = np.arange(2000)
    wobble = 0.01 * np.sin(0.3 * k)                      # bounded: sigma 0.007
    assert classify(_trace(1.0 + wobble), crit).status == SURVIVED
    # a drift of 0.06 S over the run stays inside the 0.1 S bound, but over
    # the last half it rises 0.03 S > 3 sigma = 0.021 S of the wobble
    drift = 1.0 + wobble + 0.06 * k / k[-1]
    v = classify(_trace(drift), crit)
    assert v.status == FAILED and "drifts up" in v.reason
    assert classify(_trace(drift), Criteria()).status == SURVIVED   # bound alone misses it


# ------------------------------------------------------------ the command

@pytest.mark.rank0_only
def test_command_writes_table_and_csv(tmp_path):
    out = tmp_path / "stab.md"
    p = run_cli(["study", "stability", "--reduced", "--cases", "large_step_0.1", "impact",
                 "--integrators", "backward_euler", "rk4", "--output", str(out)], ranks=2)
    assert p.returncode == 0, p.stderr
    assert "[stability] [4/" in p.stderr or "[stability] [6/" in p.stderr
    text = out.read_text()
    assert "| case | backward_euler | rk4 |" in text
    assert re.search(r"\| 20 m/s impact \| survived \| ", text)
    # one linearised step at 0.1 s overstretches the sheet: the energy guard
    # stopped it until the steps that gain energy were solved again with
    # Newton (time.energy_retry_newton; tests/test_step_health.py)
    assert re.search(r"\| large step h = 0\.1 s \| survived ", text)
    with open(tmp_path / "stab.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    # case_step: 2 cases x 2 integrators; explicit_stable: rk4 on 2 cases
    assert len(rows) == 6
    status = {(r["case"], r["integrator"], r["setting"]): r["status"] for r in rows}
    assert {("impact", "rk4", "explicit_stable"),
            ("large_step_0.1", "rk4", "case_step")} <= set(status)
    # the CSV agrees with the table above and with the in-process suite
    assert status[("impact", "backward_euler", "case_step")] == SURVIVED
    assert status[("large_step_0.1", "backward_euler", "case_step")] == SURVIVED
    assert status[("large_step_0.1", "rk4", "case_step")] == REFUSED
    assert FAILED not in status.values(), status
