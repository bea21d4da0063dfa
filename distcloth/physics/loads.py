"""Point and line loads (docs/loads_and_grips.md): constant external forces
on vertices, each ramped linearly from zero over its ramp time.  A constant
load is conservative with the potential -F . x, which the energy guard
counts with gravity's; while a ramp runs the load does work on the cloth
and the scene is driven (energy_guard.py)."""
from __future__ import annotations

import numpy as np

from .base import ForceTerm


class LoadTerm(ForceTerm):
    name = "force:loads"
    has_jacobian = False

    def __init__(self, rows, forces, ramps, n_local, n_owned):
        # loads on one vertex are summed; ghost rows get theirs too (like gravity)
        self.rows = np.asarray(rows, dtype=np.int64)
        self.full = np.asarray(forces, dtype=np.float64)
        self.ramps = np.asarray(ramps, dtype=np.float64)
        self.weight = (self.rows < n_owned).astype(np.float64)   # energy: owned rows once
        self.n_local = n_local
        self.force = np.zeros((n_local, 3))
        self.at_time(0.0)

    def at_time(self, t: float) -> None:
        """The loads at time t: full after their ramp, t / ramp of it before."""
        ramps = np.where(self.ramps > 0, self.ramps, 1.0)
        scale = np.where(self.ramps > 0, np.minimum(1.0, max(t, 0.0) / ramps), 1.0)
        self.force = np.zeros((self.n_local, 3))
        np.add.at(self.force, self.rows, scale[:, None] * self.full)
        self._scaled = scale[:, None] * self.full

    def evaluate(self, x, v, force, want_jac):
        force += self.force

    def energy(self, x):
        return -float(np.sum(self.weight * np.einsum("ij,ij->i", self._scaled, x[self.rows])))


def build_loads(cfg, model, layout) -> ForceTerm | None:
    loads = model.loads
    if loads is None or loads.vertices.size == 0:
        return None
    local = layout.input_to_local()[loads.vertices]
    mine = local >= 0
    return LoadTerm(local[mine], loads.forces[mine], loads.ramps[mine], layout.n_local,
                    layout.n_owned)
