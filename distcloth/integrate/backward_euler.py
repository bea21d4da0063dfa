"""Backward Euler, linearised as Baraff and Witkin (1998, Eq. 16-17):

    (M - h df/dv - h^2 df/dx) dv = h (f0 + h df/dx v0)

evaluated at (x0, v0).  That is one Newton step; with ``time.newton_iterations``
> 1 Newton continues on the backward Euler residual

    g(dv) = M dv - h f(x0 + h (v0 + dv), v0 + dv)

with the Jacobian re-evaluated at each iterate, until |S g| <= tol |b0|
(S the constraint filter: constrained rows are exact after the first solve).
"""
from __future__ import annotations

import numpy as np

from ..linalg.constraints import Constraints
from .base import Integrator, StepResult


class BackwardEuler(Integrator):
    def step(self, sim, h, cons):
        n = sim.n_owned
        x0, v0 = sim.x, sim.v
        f = sim.forces(x0, v0, want_jac=True)
        kv = sim.stiffness_product(v0)
        data = sim.assemble(alpha=h * h, beta=h)
        b = h * (f[:n] + h * kv[:n])
        dv_owned, info = sim.solve(data, b, cons)
        ksp_its, ksp_res = info.iterations, info.residual
        newton_its, rel = 1, 0.0
        max_its = self.cfg.time.newton_iterations
        if max_its > 1:
            b0 = max(sim.global_norm(b), 1e-300)
            relaxed = Constraints(cons.index, cons.S, np.zeros_like(cons.z))
            dv = sim.local_array(dv_owned)
            while newton_its < max_its:
                v1 = v0 + dv
                f = sim.forces(x0 + h * v1, v1, want_jac=True)
                g = sim.mass[:n, None] * dv[:n] - h * f[:n]
                rel = sim.global_norm(sim.project(relaxed, -g)) / b0
                if rel <= self.cfg.time.newton_tolerance:
                    break
                data = sim.assemble(alpha=h * h, beta=h)
                delta, info = sim.solve(data, -g, relaxed)
                ksp_its += info.iterations
                ksp_res = max(ksp_res, info.residual)
                dv[:n] += delta
                sim.ghosts.update(dv)
                newton_its += 1
            dv_owned = dv[:n]
        v1 = v0[:n] + dv_owned
        return StepResult(x=x0[:n] + h * v1, v=v1, newton_iterations=newton_its,
                          ksp_iterations=ksp_its, ksp_residual=ksp_res, newton_residual=rel)
