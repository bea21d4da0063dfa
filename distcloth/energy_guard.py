"""The energy guard: a passive cloth must not gain energy.

Without external work (pins are fixed or their grips have stopped; colliders
do work only while they move; a load only while its ramp runs, and a constant
load's potential -F . x is counted with gravity's) the total energy E = kinetic + gravitational + elastic of a cloth can
only fall: damping, drag, friction and inelastic contact remove it, and the
conservative integrators (implicit midpoint, Newmark 1/4-1/2, symplectic
Euler) keep it up to a bounded oscillation.  A step that leaves E well above
the energy of the state where the scene became passive is therefore a
numerical blow-up in progress, even while every vertex is still slower than
the speed limit: the stability suite (docs/stability.md) found implicit
midpoint and Newmark runs gaining 15 to 10^4 times the scene's energy scale
that ran to their end unnoticed before this guard.

The bound is E <= E_ref + gain * S, with E_ref the total energy at the start
of the passive window (t = 0, or the end of the last collider keyframe) and
S = KE_ref + |U_elastic_ref| + M |g| L, the energy the scene can move between
kinetic, elastic and gravitational form (M the cloth's mass, L its rest
bounding-box diagonal).  The same definition is criterion 2 of the stability
classifier (distcloth/study/classify.py), so a run the guard lets through is
not one the suite calls garbage for its energy.  The check is a rejection
like NaN or a blow-up: with ``time.adaptive`` the step is retried at h/2,
otherwise the run stops naming the step and the energy.  With
``time.energy_guard: false`` the step is accepted, but the first one above
the bound is a warning of the run (its step, time and the energy gained),
which then ends 'completed_with_warnings', never plainly 'completed'.
"""
from __future__ import annotations

import numpy as np

# S is floored so that a cloth at rest without gravity (S = 0) is not stopped
# by round-off (J; the energies of a 1 g cloth moving at 1 mm/s are 5e-10 J)
SCALE_FLOOR = 1.0e-12
ENERGY_GAIN = "energy gain"     # how a rejection by the guard begins


def gravity_scale(cfg, model) -> float:
    """M |g| L + sum |F| L: the potential energy of gravity and the loads a cloth
    of mass M and size L can exchange."""
    scale = 0.0
    if cfg.has("gravity"):
        scale += float(model.vertex_mass.sum() * np.linalg.norm(cfg.gravity) * model.size())
    if cfg.has("loads") and model.loads is not None:
        scale += model.loads.total() * model.size()
    return scale


def drive_end(cfg, model) -> float:
    """When the grips and load ramps stop doing work on the cloth (0: never
    started; inf: a grip that never stops)."""
    end = max((g.path.end for g in model.grips if g.path is not None), default=0.0)
    if cfg.has("loads") and model.loads is not None:
        end = max(end, model.loads.end)
    return end


class EnergyGuard:
    """The guard's settings; its reference (E_ref, S) is part of the State,
    taken at the first committed state of the passive window."""

    def __init__(self, gain: float | None, drive_end: float, gravity_scale: float,
                 enforce: bool = True):
        self.gain = gain                   # None: off
        self.drive_end = float(drive_end)  # s: colliders, grips and ramps act until here
        self.gravity_scale = float(gravity_scale)
        self.enforce = enforce             # False: a gain is a warning, not a rejection

    def wants_reference(self, t: float, reference) -> bool:
        """True at the first committed state of the passive window."""
        return self.gain is not None and reference is None and t >= self.drive_end - 1e-12

    def reference(self, kinetic: float, gravitational: float, elastic: float) -> tuple[float, float]:
        """(E_ref, S) of the state where the scene became passive."""
        scale = abs(kinetic) + abs(elastic) + self.gravity_scale
        return kinetic + gravitational + elastic, max(scale, SCALE_FLOOR)

    def check(self, reference, kinetic: float, gravitational: float, elastic: float) -> str | None:
        """The rejection reason of a tentative state, or None (same on every rank:
        the energies are global sums)."""
        if self.gain is None or reference is None:
            return None
        e_ref, scale = reference
        gained = kinetic + gravitational + elastic - e_ref
        excess = gained / scale
        if excess > self.gain:
            return (f"{ENERGY_GAIN}: total energy {excess:.3g} S above the passive scene's "
                    f"{e_ref:.4g} J (S = {scale:.3g} J, limit time.max_energy_gain = "
                    f"{self.gain:g} S): {gained:.4g} J gained")
        return None
