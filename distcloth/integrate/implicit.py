"""Implicit one-step schemes as Newton on the velocity change dv = v1 - v0.

Each scheme fixes, for its step, the state where forces are evaluated as an
affine function of dv and a residual (seed 000 Part 2 §2.3 compares backward
Euler, BDF-2 and backward midpoint; Newmark 1959 for the beta/gamma family):

    x_e = x_pred + a_x dv,   v_e = v0 + a_v dv
    g(dv) = M (dv - d) - s f(x_e, v_e)
    dg/ddv = M - s a_v df/dv - s a_x df/dx       (the assembled system)

The first Newton iteration is linearised at the start state (x0, v0), as
Baraff and Witkin (1998) do for backward Euler:

    (M - s a_v D - s a_x K) dv = M d + s (f0 + K (x_pred - x0))

so ``time.newton_iterations: 1`` is the classic one-linear-solve step for
every scheme; more iterations continue Newton on g until |S g| <= tol |b0|.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..linalg.constraints import Constraints
from .base import Integrator, StepResult


@dataclass
class Affine:
    x_pred: np.ndarray     # (n_local, 3)
    a_x: float
    a_v: float
    d: np.ndarray          # (n_owned, 3) velocity offset of the residual
    s: float


class ImplicitScheme(Integrator):
    """A scheme defines ``affine`` (given f0 at the start state) and ``final``."""

    def affine(self, sim, h, f0, cons) -> Affine:
        raise NotImplementedError

    def final(self, sim, h, aff: Affine, dv):
        """(x1, v1) on the owned rows from the converged velocity change."""
        n = sim.n_owned
        return aff.x_pred[:n] + aff.a_x * dv[:n], sim.v[:n] + dv[:n]

    def step(self, sim, h, cons):
        n = sim.n_owned
        x0, v0 = sim.x, sim.v
        m = sim.mass[:n, None]
        f = sim.forces(x0, v0, want_jac=True)
        aff = self.affine(sim, h, f, cons)
        kx = sim.stiffness_product(aff.x_pred - x0)
        alpha, beta = aff.s * aff.a_x, aff.s * aff.a_v
        data = sim.assemble(alpha=alpha, beta=beta)
        b = m * aff.d + aff.s * (f[:n] + kx[:n])
        dv_owned, info = sim.solve(data, b, cons)
        ksp_its, ksp_res = info.iterations, info.residual
        dv = sim.local_array(dv_owned)
        newton_its, rel, converged = 1, 0.0, True
        max_its = self.cfg.time.newton_iterations
        if max_its > 1:
            converged = False
            b0 = max(sim.global_norm(b), 1e-300)
            relaxed = Constraints(cons.index, cons.S, np.zeros_like(cons.z))
            while newton_its < max_its:
                f = sim.forces(aff.x_pred + aff.a_x * dv, v0 + aff.a_v * dv, want_jac=True)
                g = m * (dv[:n] - aff.d) - aff.s * f[:n]
                rel = sim.global_norm(sim.project(relaxed, -g)) / b0
                if rel <= self.cfg.time.newton_tolerance:
                    converged = True
                    break
                data = sim.assemble(alpha=alpha, beta=beta)
                delta, info = sim.solve(data, -g, relaxed)
                ksp_its += info.iterations
                ksp_res = max(ksp_res, info.residual)
                dv[:n] += delta
                sim.ghosts.update(dv)
                newton_its += 1
        self.position_gain = aff.a_x      # dx1/dv1, for a post-solve velocity change
        x1, v1 = self.final(sim, h, aff, dv)
        return StepResult(x=x1, v=v1, newton_iterations=newton_its, ksp_iterations=ksp_its,
                          ksp_residual=ksp_res, newton_residual=rel, newton_converged=converged)


class BackwardEuler(ImplicitScheme):
    """x1 = x0 + h v1, M (v1 - v0) = h f(x1, v1): first order, dissipative."""

    def affine(self, sim, h, f0, cons):
        return Affine(sim.x + h * sim.v, h, 1.0, np.zeros((sim.n_owned, 3)), h)


class ImplicitMidpoint(ImplicitScheme):
    """x1 = x0 + h (v0 + v1)/2, M (v1 - v0) = h f((x0 + x1)/2, (v0 + v1)/2):
    second order, symplectic, no numerical damping."""

    def affine(self, sim, h, f0, cons):
        return Affine(sim.x + 0.5 * h * sim.v, 0.25 * h, 0.5, np.zeros((sim.n_owned, 3)), h)

    def final(self, sim, h, aff, dv):
        n = sim.n_owned
        v1 = sim.v[:n] + dv[:n]
        self.position_gain = 0.5 * h
        return sim.x[:n] + 0.5 * h * (sim.v[:n] + v1), v1


class Newmark(ImplicitScheme):
    """x1 = x0 + h v0 + h^2 ((1/2 - beta) a0 + beta a1), v1 = v0 + h ((1 - gamma) a0 + gamma a1),
    M a1 = f(x1, v1); a0 = M^-1 f(x0, v0) with constrained directions at rest.
    Second order for gamma = 1/2; beta = 1/4 is the average-acceleration rule."""

    def affine(self, sim, h, f0, cons):
        beta, gamma = self.cfg.time.newmark_beta, self.cfg.time.newmark_gamma
        a0 = sim.local_array(sim.project(cons, f0[: sim.n_owned] / sim.mass[: sim.n_owned, None]))
        x_pred = sim.x + h * sim.v + h * h * (0.5 - beta - beta * (1.0 - gamma) / gamma) * a0
        return Affine(x_pred, h * beta / gamma, 1.0, h * (1.0 - gamma) * a0[: sim.n_owned], h * gamma)


class BDF2(ImplicitScheme):
    """x1 = 4/3 x0 - 1/3 x_-1 + 2/3 h v1, v1 = 4/3 v0 - 1/3 v_-1 + 2/3 h M^-1 f(x1, v1):
    second order; the first step, and any step after a change of h, is backward Euler."""

    def __init__(self, cfg):
        super().__init__(cfg)
        self.history = None      # (x_-1, v_-1, h) of the last accepted step
        self._pending = None

    def affine(self, sim, h, f0, cons):
        self._pending = (sim.x.copy(), sim.v.copy(), h)
        if self.history is None or self.history[2] != h:
            return BackwardEuler.affine(self, sim, h, f0, cons)
        xm1, vm1, _ = self.history
        n = sim.n_owned
        x_pred = (4.0 * sim.x - xm1) / 3.0 + (2.0 / 3.0) * h * sim.v
        return Affine(x_pred, 2.0 * h / 3.0, 1.0, (sim.v[:n] - vm1[:n]) / 3.0, 2.0 * h / 3.0)

    def accepted(self):
        self.history = self._pending
