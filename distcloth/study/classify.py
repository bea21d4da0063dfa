"""The verdict on one stability run, from what was recorded at every step.

A run ends one of four ways:

* ``refused``: the scene was refused before the first step (a config error,
  e.g. an explicit step above its stability bound); the message is kept;
* ``stopped``: the simulator raised SimulationError, naming the step and the
  cause (NaN, blow-up, failed solve...): a clear stop, not a silent result;
* ``survived``: every recorded step passed the criteria below;
* ``FAILED``: the run went on to its end but some step broke a criterion:
  garbage nobody was told about.

Criteria on the recorded steps (``Criteria``):

1. finite: the total energy (kinetic + gravitational + elastic, computed from
   the positions and velocities, so a NaN anywhere in them makes it NaN) is
   finite at every step;
2. bounded energy: E_k <= E_ref + energy_tolerance * S at every step k from
   ``window_start`` on, where E_ref is the energy at the window's start (the
   start state unless colliders still move: they do work on the cloth, so the
   bound starts when they come to rest), and the scale
   S = KE_ref + U_elastic_ref + M |g| L (M the cloth's mass, L its size) is the
   energy the run can move between kinetic, elastic and gravitational form.
   Without external work, dissipative schemes (backward Euler, BDF-2) must
   lose energy and conservative ones (implicit midpoint, Newmark 1/4, 1/2,
   symplectic Euler) keep it up to their O(h) or O(h^2) oscillation;
3. no slow growth (long runs, ``slope_check``): over the last
   ``slope_fraction`` of the run, the least-squares line through E(t) may rise
   by at most max(3 sigma, slope_floor * S) across that window, sigma the
   standard deviation of E about the line: a bounded oscillation has a fitted
   rise below 3 sigma, a drift does not;
4. no penetration: no vertex ends a step deeper than ``penetration_tolerance``
   times the contact offset d inside a collider (independent signed distance
   of the end-of-step positions, not the simulator's own diagnostic).

A run that stopped is ``stopped`` even if some steps before the stop already
broke a criterion (the result carries an error; the first such step is
reported beside it).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

SURVIVED, STOPPED, REFUSED, FAILED = "survived", "stopped", "refused", "FAILED"


@dataclass(frozen=True)
class Criteria:
    energy_tolerance: float = 0.1
    window_start: float = 0.0          # s: the energy bound holds from here on
    slope_check: bool = False
    slope_fraction: float = 0.5
    slope_floor: float = 1e-3
    penetration_tolerance: float = 0.1


@dataclass
class Trace:
    """Per-step records (index k = after step k + 1) plus the start state."""
    time: list = field(default_factory=list)
    energy: list = field(default_factory=list)            # total: kinetic + gravitational + elastic
    kinetic: list = field(default_factory=list)
    elastic: list = field(default_factory=list)
    penetration: list = field(default_factory=list)       # worst (d - phi) / d; NaN: no colliders
    start_energy: float = 0.0
    start_kinetic: float = 0.0
    start_elastic: float = 0.0
    gravity_scale: float = 0.0                            # M |g| L

    def record(self, t, kinetic, gravitational, elastic, penetration=math.nan):
        self.time.append(float(t))
        self.kinetic.append(float(kinetic))
        self.elastic.append(float(elastic))
        self.energy.append(float(kinetic + gravitational + elastic))
        self.penetration.append(float(penetration))


@dataclass
class Verdict:
    status: str
    step: int | None = None           # the stop's step, or the first failing step
    reason: str = ""
    energy_excess: float = math.nan   # max (E_k - E_ref) / S over the window
    slope_rise: float = math.nan      # fitted rise over the slope window / S
    penetration: float = math.nan     # worst (d - phi) / d over the run
    first_violation: int | None = None


def reference(trace: Trace, crit: Criteria):
    """(index of the reference record or -1 for the start state, E_ref, S)."""
    t = np.asarray(trace.time)
    ref = -1
    if crit.window_start > 0 and t.size:
        before = np.nonzero(t <= crit.window_start + 1e-12)[0]
        ref = int(before[-1]) if before.size else -1
    if ref < 0:
        e, ke, el = trace.start_energy, trace.start_kinetic, trace.start_elastic
    else:
        e, ke, el = trace.energy[ref], trace.kinetic[ref], trace.elastic[ref]
    scale = abs(ke) + abs(el) + trace.gravity_scale
    return ref, e, (scale if scale > 0 else 1.0)


def _violations(trace: Trace, crit: Criteria):
    """[(first step (1-based), reason)] of each broken criterion, and the metrics."""
    e = np.asarray(trace.energy, dtype=np.float64)
    t = np.asarray(trace.time, dtype=np.float64)
    pen = np.asarray(trace.penetration, dtype=np.float64)
    out, metrics = [], {}
    bad = ~np.isfinite(e)
    if bad.any():
        k = int(np.argmax(bad))
        out.append((k + 1, "non-finite energy (NaN or Inf in the state) not stopped"))
    ref, e_ref, scale = reference(trace, crit)
    window = (np.arange(e.size) > ref) & ~bad       # non-finite steps are criterion 1's
    if window.any():
        excess = (e - e_ref) / scale
        metrics["energy_excess"] = float(np.max(excess[window]))
        over = window & (excess > crit.energy_tolerance)
        if over.any():
            k = int(np.argmax(over))
            top = int(np.argmax(np.where(window, excess, -np.inf)))
            out.append((k + 1, f"energy above E_ref + {crit.energy_tolerance:g} S; largest "
                               f"excess {excess[top]:.3g} S at step {top + 1}"))
    if crit.slope_check and e.size >= 8 and not bad.any():
        lo = int(math.floor((1.0 - crit.slope_fraction) * e.size))
        tw, ew = t[lo:], e[lo:]
        a, b = np.polyfit(tw, ew, 1)
        sigma = float(np.std(ew - (a * tw + b)))
        rise = a * (tw[-1] - tw[0])
        metrics["slope_rise"] = float(rise / scale)
        if rise > max(3.0 * sigma, crit.slope_floor * scale):
            out.append((lo + 1, f"energy drifts up: +{rise / scale:.3g} S over the last "
                                f"{crit.slope_fraction:.0%} of the run "
                                f"(noise {sigma / scale:.2g} S)"))
    if np.isfinite(pen).any():
        metrics["penetration"] = float(np.nanmax(pen))
        deep = pen > crit.penetration_tolerance
        if deep.any():
            k = int(np.argmax(deep))
            out.append((k + 1, f"a vertex {pen[k]:.3g} d inside a collider "
                               f"(tolerance {crit.penetration_tolerance:g} d)"))
    return out, metrics


def classify(trace: Trace, crit: Criteria, stop: tuple[int, str] | None = None) -> Verdict:
    """The verdict on a run that started; ``stop`` = (step, message) of a
    SimulationError. Deterministic: equal traces give equal verdicts on every rank."""
    found, metrics = _violations(trace, crit)
    first = min((k for k, _ in found), default=None)
    if stop is not None:
        return Verdict(STOPPED, stop[0], stop[1], first_violation=first, **metrics)
    if found:
        k, why = min(found)
        return Verdict(FAILED, k, why, first_violation=k, **metrics)
    return Verdict(SURVIVED, None, "", **metrics)
