"""The held vertices of one rank at run time: where their grips' paths put
them, and the reaction force each pin group takes (docs/loads_and_grips.md).

Rows are local (owned or ghost), in the order the constraints stage lists
them (pins, then sliding pins); P = I - S projects on the held directions.
"""
from __future__ import annotations

import numpy as np


class HeldVertices:
    def __init__(self, model, layout, pinned_local, slide_local, slide_S, mass):
        self.rows = np.concatenate([pinned_local, slide_local]).astype(np.int64)
        S = np.concatenate([np.zeros((pinned_local.size, 3, 3)), slide_S])
        self.P = np.eye(3)[None] - S
        self.n_owned = layout.n_owned
        self.grips = list(model.grips)
        inputs = layout.local_input[self.rows]
        self.group = (model.pin_group[inputs] if model.pin_group is not None
                      else np.full(self.rows.size, -1, dtype=np.int64))
        self.inputs = inputs
        self.X = model.start_positions()[inputs]
        self.mass = mass[self.rows]
        # per grip, then per row (index -1, a row of no grip, takes the last entry: False)
        has_path = np.array([g.path is not None for g in self.grips] + [False], dtype=bool)
        self.moving = has_path[self.group]
        self.owned = self.rows < self.n_owned

    @property
    def names(self) -> list[str]:
        return [g.name for g in self.grips]

    def _along_path(self, t: float, what: str) -> np.ndarray:
        """(k, 3) positions or velocities of the moving rows at t, per grip."""
        out = np.zeros((int(self.moving.sum()), 3))
        group = self.group[self.moving]
        X = self.X[self.moving]
        inputs = self.inputs[self.moving]
        for g in np.unique(group):
            sel = group == g
            out[sel] = getattr(self.grips[g].path, what)(X[sel], t, inputs[sel])
        return out

    def targets(self, state, h: float, t_end: float, integrator) -> np.ndarray:
        """(rows, 3) velocities whose constrained part the constraints stage
        imposes: zero for pins at rest; for a moving grip the velocity whose
        change z puts the row on its path at t_end under the integrator's own
        position update (``Integrator.held_path``)."""
        target = np.zeros((self.rows.size, 3))
        if self.moving.any():
            rows = self.rows[self.moving]
            base, gain = integrator.held_path(state, h, rows)
            target[self.moving] = state.v[rows] + (self._along_path(t_end, "positions")
                                                  - base) / gain
        return target

    def hold(self, v_owned: np.ndarray, t_end: float) -> None:
        """The held directions of the moving owned rows of ``v_owned`` take their
        path's velocity at t_end: their position is on the path already, and a
        scheme whose end velocity is 2 (x1 - x0) / h - v0 (implicit midpoint)
        would otherwise make the grip's velocity alternate from step to step."""
        sel = self.moving & self.owned
        if not sel.any():
            return
        rows = self.rows[sel]
        P = self.P[sel]
        path_v = self._along_path(t_end, "velocities")[sel[self.moving]]
        v = v_owned[rows]
        v_owned[rows] = v - np.einsum("nij,nj->ni", P, v - path_v)

    def reactions(self, force: np.ndarray, acceleration: np.ndarray | None) -> np.ndarray:
        """(grips, 3) this rank's share of each pin group's reaction, the force
        its constraints exert on the cloth: P (m a - f) summed over the group's
        owned rows, f every force term at the committed state and a its
        acceleration over the step."""
        out = np.zeros((len(self.grips), 3))
        sel = self.owned & (self.group >= 0)
        if not sel.any():
            return out
        rows = self.rows[sel]
        inertia = (0.0 if acceleration is None
                   else self.mass[sel, None] * acceleration[rows])
        r = np.einsum("nij,nj->ni", self.P[sel], inertia - force[rows])
        np.add.at(out, self.group[sel], r)
        return out
