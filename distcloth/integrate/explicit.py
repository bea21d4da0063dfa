"""Explicit schemes: symplectic Euler (Vassilev et al. 2001 Eq. 3), explicit
midpoint, RK4.

Constrained directions follow their prescribed velocity change z spread
evenly over the step: every stage acceleration is S a + (I - S) z / h.
``stability_factor`` c gives the start-up check h < 0.9 c / sqrt(lambda_max):
2 for symplectic Euler and explicit midpoint (which, without damping, is
weakly unstable at any h: |amplification|^2 = 1 + (h w)^4 / 4), 2 sqrt(2)
for RK4 (its stability region reaches 2.83 i on the imaginary axis).
A velocity change after the step moves positions by h times it.  A held
row ends at x0 + h v0 + g h z, g = 1 (symplectic Euler) or 1/2 (midpoint,
RK4): ``held_gain``.
"""
from __future__ import annotations

import math

import numpy as np

from .base import Integrator, StepResult


def accelerations(ctx, f, cons, h):
    """Filtered accelerations from the forces f on every local row (ghosts exchanged)."""
    n = ctx.n_owned
    a = f[:n] / ctx.mass[:n, None]
    owned = cons.index < n
    idx = cons.index[owned]
    if idx.size:
        a[idx] = np.einsum("nij,nj->ni", cons.S[owned], a[idx]) + \
            np.einsum("nij,nj->ni", np.eye(3)[None] - cons.S[owned], cons.z[owned]) / h
    return ctx.local_array(a)


def stage_accelerations(ctx, x, v, cons, h):
    return accelerations(ctx, ctx.forces(x, v, want_jac=False), cons, h)


class SymplecticEuler(Integrator):
    """v1 = v0 + h M^-1 f(x0, v0), x1 = x0 + h v1."""
    implicit = False
    stability_factor = 2.0

    def step(self, ctx, state, h, cons, guess=None):
        n = ctx.n_owned
        f0 = ctx.forces(state.x, state.v, want_jac=False)
        a = accelerations(ctx, f0, cons, h)
        v1 = state.v[:n] + h * a[:n]
        return StepResult(x=state.x[:n] + h * v1, v=v1, start_forces=f0, position_gain=h)


class ExplicitMidpoint(Integrator):
    """Second-order Runge-Kutta, midpoint rule."""
    implicit = False
    stability_factor = 2.0
    held_gain = 0.5                  # x1 = x0 + h (v0 + z / 2) on held rows

    def step(self, ctx, state, h, cons, guess=None):
        n = ctx.n_owned
        x0, v0 = state.x, state.v
        f0 = ctx.forces(x0, v0, want_jac=False)
        a0 = accelerations(ctx, f0, cons, h)
        vm = v0 + 0.5 * h * a0
        am = stage_accelerations(ctx, x0 + 0.5 * h * v0, vm, cons, h)
        return StepResult(x=x0[:n] + h * vm[:n], v=v0[:n] + h * am[:n], start_forces=f0,
                          position_gain=h)


class RK4(Integrator):
    """The classical fourth-order Runge-Kutta method on (x, v)."""
    implicit = False
    stability_factor = 2.0 * math.sqrt(2.0)
    held_gain = 0.5                  # x1 = x0 + h v0 + h (z + z + z) / 6 on held rows

    def step(self, ctx, state, h, cons, guess=None):
        n = ctx.n_owned
        x0, v0 = state.x, state.v
        f0 = ctx.forces(x0, v0, want_jac=False)
        a1 = accelerations(ctx, f0, cons, h)
        v2 = v0 + 0.5 * h * a1
        a2 = stage_accelerations(ctx, x0 + 0.5 * h * v0, v2, cons, h)
        v3 = v0 + 0.5 * h * a2
        a3 = stage_accelerations(ctx, x0 + 0.5 * h * v2, v3, cons, h)
        v4 = v0 + h * a3
        a4 = stage_accelerations(ctx, x0 + h * v3, v4, cons, h)
        x1 = x0 + h / 6.0 * (v0 + 2.0 * v2 + 2.0 * v3 + v4)
        v1 = v0 + h / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4)
        return StepResult(x=x1[:n], v=v1[:n], start_forces=f0, position_gain=h)
