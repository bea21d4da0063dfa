"""Explicit schemes: symplectic Euler (seed 002 Eq. 3), explicit midpoint, RK4.

Constrained directions follow their prescribed velocity change z spread
evenly over the step: every stage acceleration is S a + (I - S) z / h.
``stability_factor`` c gives the start-up check h < 0.9 c / sqrt(lambda_max):
2 for symplectic Euler and explicit midpoint (which, without damping, is
weakly unstable at any h: |amplification|^2 = 1 + (h w)^4 / 4), 2 sqrt(2)
for RK4 (its stability region reaches 2.83 i on the imaginary axis).
"""
from __future__ import annotations

import math

import numpy as np

from .base import Integrator, StepResult


def accelerations(sim, x, v, cons, h):
    """Filtered accelerations on every local row (ghosts exchanged)."""
    n = sim.n_owned
    a = sim.forces(x, v, want_jac=False)[:n] / sim.mass[:n, None]
    owned = cons.index < n
    idx = cons.index[owned]
    if idx.size:
        a[idx] = np.einsum("nij,nj->ni", cons.S[owned], a[idx]) + \
            np.einsum("nij,nj->ni", np.eye(3)[None] - cons.S[owned], cons.z[owned]) / h
    return sim.local_array(a)


class SymplecticEuler(Integrator):
    """v1 = v0 + h M^-1 f(x0, v0), x1 = x0 + h v1."""
    implicit = False
    stability_factor = 2.0

    def step(self, sim, h, cons):
        n = sim.n_owned
        a = accelerations(sim, sim.x, sim.v, cons, h)
        v1 = sim.v[:n] + h * a[:n]
        return StepResult(x=sim.x[:n] + h * v1, v=v1)


class ExplicitMidpoint(Integrator):
    """Second-order Runge-Kutta, midpoint rule."""
    implicit = False
    stability_factor = 2.0

    def step(self, sim, h, cons):
        n = sim.n_owned
        x0, v0 = sim.x, sim.v
        a0 = accelerations(sim, x0, v0, cons, h)
        vm = v0 + 0.5 * h * a0
        am = accelerations(sim, x0 + 0.5 * h * v0, vm, cons, h)
        return StepResult(x=x0[:n] + h * vm[:n], v=v0[:n] + h * am[:n])


class RK4(Integrator):
    """The classical fourth-order Runge-Kutta method on (x, v)."""
    implicit = False
    stability_factor = 2.0 * math.sqrt(2.0)

    def step(self, sim, h, cons):
        n = sim.n_owned
        x0, v0 = sim.x, sim.v
        a1 = accelerations(sim, x0, v0, cons, h)
        v2 = v0 + 0.5 * h * a1
        a2 = accelerations(sim, x0 + 0.5 * h * v0, v2, cons, h)
        v3 = v0 + 0.5 * h * a2
        a3 = accelerations(sim, x0 + 0.5 * h * v2, v3, cons, h)
        v4 = v0 + h * a3
        a4 = accelerations(sim, x0 + h * v3, v4, cons, h)
        x1 = x0 + h / 6.0 * (v0 + 2.0 * v2 + 2.0 * v3 + v4)
        v1 = v0 + h / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4)
        return StepResult(x=x1[:n], v=v1[:n])
