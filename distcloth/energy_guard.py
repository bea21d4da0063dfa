"""The energy guard: a passive cloth must not gain energy.

Without external work (pins are fixed; colliders do work only while they
move) the total energy E = kinetic + gravitational + elastic of a cloth can
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
otherwise the run stops naming the step and the energy.
"""
from __future__ import annotations

import numpy as np

# S is floored so that a cloth at rest without gravity (S = 0) is not stopped
# by round-off (J; the energies of a 1 g cloth moving at 1 mm/s are 5e-10 J)
SCALE_FLOOR = 1.0e-12


def gravity_scale(cfg, model) -> float:
    """M |g| L: the gravitational energy a cloth of mass M and size L can exchange."""
    if not cfg.has("gravity"):
        return 0.0
    return float(model.vertex_mass.sum() * np.linalg.norm(cfg.gravity) * model.size())


class EnergyGuard:
    """The guard's settings; its reference (E_ref, S) is part of the State,
    taken at the first committed state of the passive window."""

    def __init__(self, gain: float | None, drive_end: float, gravity_scale: float):
        self.gain = gain                   # None: off
        self.drive_end = float(drive_end)  # s: colliders move until here
        self.gravity_scale = float(gravity_scale)

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
        excess = (kinetic + gravitational + elastic - e_ref) / scale
        if excess > self.gain:
            return (f"energy gain: total energy {excess:.3g} S above the passive scene's "
                    f"{e_ref:.4g} J (S = {scale:.3g} J, limit time.max_energy_gain = "
                    f"{self.gain:g} S)")
        return None
