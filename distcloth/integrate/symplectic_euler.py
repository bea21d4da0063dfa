"""Symplectic (semi-implicit) Euler, the explicit baseline (seed 002 Eq. 3):
v1 = v0 + h M^-1 f(x0, v0),  x1 = x0 + h v1.  Constrained directions take the
prescribed velocity change: dv = S (h M^-1 f) + z."""
from __future__ import annotations

import numpy as np

from .base import Integrator, StepResult


class SymplecticEuler(Integrator):
    implicit = False

    def step(self, sim, h, cons):
        n = sim.n_owned
        f = sim.forces(sim.x, sim.v, want_jac=False)
        dv = h * f[:n] / sim.mass[:n, None]
        owned = cons.index < n
        idx = cons.index[owned]
        if idx.size:
            dv[idx] = np.einsum("nij,nj->ni", cons.S[owned], dv[idx]) + cons.z[owned]
        v1 = sim.v[:n] + dv
        return StepResult(x=sim.x[:n] + h * v1, v=v1)
