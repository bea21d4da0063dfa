"""The ``strain_limiting`` stage: keeps every membrane spring within its bound.

Runs once per step attempt, after the integrator (for implicit schemes after
the solve and its contact passes, for explicit ones after the step, as
Vassilev et al. 2001 §3.2 does after each iteration) and before the
collision response, so that contacts, the fail-safe and the triangle
pipeline still have the last word.  Pinned vertices and this attempt's
contact vertices never move (physics/strain_limits.py).

Distributed passes (Jacobi with averaging): each pass computes every local
spring's correction from positions and velocities whose ghost rows are
current, adds them into the owned rows, and refreshes the ghosts (one
neighbour exchange of x, or of x, v and the anchor flags); one global
reduction per pass decides whether another pass is needed.  A pass costs
the same on any number of ranks and gives the same result up to the order
of floating-point sums.

Velocities follow the positions through the integrator's position gain
(x1 depends on v1 by ``position_gain``): Provot's position change dx comes
with dv = dx / gain, and the velocity method's dv moves x1 by gain dv, as
if the modification had come between the velocity and the position update
of Vassilev et al.'s Eq. 3.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .model import SHEAR, STRUCTURAL
from .physics.strain_limits import (COS_PERPENDICULAR, provot_pass, spring_classes, spring_strain,
                                    velocity_pass)

# the velocity method stops once no spring over its bound separates faster
# than this fraction of the strain tolerance per step
VELOCITY_TOLERANCE_FRACTION = 0.01


@dataclass
class LimitReport:
    springs: float = 0.0       # membrane springs over their bound before limiting (global)
    passes: int = 0            # passes used
    strain: float = 0.0        # largest spring strain after limiting (global)
    excess: float = 0.0        # largest strain above the bound after limiting (global)
    converged: bool = True


class StrainLimiter:
    def __init__(self, spec, cfg, model, layout, mass, held, ghosts, comm):
        self.spec, self.ghosts, self.comm = spec, ghosts, comm
        self.n_owned, self.n_local = layout.n_owned, layout.n_local
        self.mass = mass
        ids = layout.local_spring_ids
        membrane = np.isin(model.spring_kind[ids], [STRUCTURAL, SHEAR])
        self.springs = layout.local_springs[membrane]
        ids = ids[membrane]
        self.rest = model.spring_rest_length[ids]
        # each piece's weft direction for its springs
        weft = np.zeros((ids.size, 3))
        first = model.spring_vertices[ids, 0]
        for spec_piece, piece in zip(cfg.cloth, model.pieces):
            mine = (first >= piece.vertex_start) & (first < piece.vertex_stop)
            weft[mine] = spec_piece.material.weft
        self.kind = spring_classes(model.rest_positions, model.spring_vertices[ids],
                                   model.spring_kind[ids] == SHEAR, weft)
        self.bound = np.array([spec.weft, spec.warp, spec.shear])[self.kind]
        self.limit = (1.0 + self.bound) * self.rest
        # a spring counts once over the ranks: each owned end carries half of it
        self.weight = 0.5 * (self.springs < self.n_owned).sum(axis=1)
        self.held = np.asarray(held, dtype=np.int64)
        self.gravity = np.asarray(cfg.gravity, dtype=np.float64)

    # ------------------------------------------------------------------ stage
    def apply(self, state, result, contacts, h) -> LimitReport:
        """Limits the attempt's proposed (x, v) (``result``, owned rows) in place."""
        n = self.n_owned
        x, v = state.x.copy(), state.v.copy()
        x[:n], v[:n] = result.x, result.v
        fixed = np.zeros((self.n_local, 4))          # anchor flag, body velocity
        fixed[self.held, 0] = 1.0
        if contacts is not None and contacts.index.size:
            own = contacts.index < n
            fixed[contacts.index[own], 0] = 1.0
            fixed[contacts.index[own], 1:] = contacts.velocity[own]
        self.ghosts.update(x, v, fixed)
        over = spring_strain(x, self.springs, self.rest) > self.bound
        report = LimitReport(springs=float(self.comm.sum(np.array([self.weight[over].sum()]))[0]))
        omega = self.spec.over_relaxation
        if self.spec.method == "velocity" and self.spec.rule == "directional":
            omega = 1.0      # catching up over-relaxed would overtake the front
        start = (x.copy(), v.copy())
        done = self._passes(x, v, fixed, h, result.position_gain, omega, report)
        if not done and omega > 1.0:
            # over-relaxed passes cut short leave springs bounced back past their
            # bound, which can add energy (a 0.25 J square gained 76 J with one
            # pass at 1.8); passes of plain Jacobi cut short only remove it
            x[:], v[:] = start
            self._passes(x, v, fixed, h, result.position_gain, 1.0, report)
        result.x, result.v = x[:n].copy(), v[:n].copy()
        excess = spring_strain(x, self.springs, self.rest) - self.bound
        strain = excess + self.bound
        report.strain, report.excess = (float(a) for a in self.comm.max(np.array(
            [strain.max(initial=0.0), excess.max(initial=-np.inf)])))
        report.converged = report.excess <= self.spec.tolerance
        return report

    def _passes(self, x, v, fixed, h, gain, omega, report) -> bool:
        """At most ``passes`` passes of the scene's method; True if they reached the bound."""
        if self.spec.method == "provot":
            return self._provot(x, v, fixed[:, 0] > 0, gain, omega, report)
        return self._velocity(x, v, fixed, h, gain, omega, report)

    def _provot(self, x, v, fixed, gain, omega, report) -> bool:
        n = self.n_owned
        inv_mass = np.where(fixed, 0.0, 1.0 / self.mass)
        x_start = x[:n].copy()
        done = False
        for p in range(self.spec.passes + 1):
            corr, count, _, worst = provot_pass(x, self.springs, self.rest, self.limit, inv_mass)
            done = self.comm.max(np.array([worst]))[0] <= self.spec.tolerance
            if done or p == self.spec.passes:
                break
            x[:n] += omega * corr[:n] / np.maximum(count[:n], 1.0)[:, None]
            self.ghosts.update(x)
            report.passes += 1
        v[:n] += (x[:n] - x_start) / gain
        return done

    def _velocity(self, x, v, fixed, h, gain, omega, report) -> bool:
        n = self.n_owned
        anchored = fixed[:, 0] > 0
        # Vassilev et al. 2001 Eq. 6: v_dir = v_grav + v_object, v_grav = g dt; the
        # object's velocity is that of the body a spring's ends touch (their mean)
        body = np.where(anchored[:, None], fixed[:, 1:], 0.0)
        i, j = self.springs[:, 0], self.springs[:, 1]
        ends = anchored[i].astype(float) + anchored[j].astype(float)
        v_object = (body[i] + body[j]) / np.maximum(ends, 1.0)[:, None]
        vdir = self.gravity * h + v_object
        tolerance = VELOCITY_TOLERANCE_FRACTION * self.spec.tolerance * self.rest / h
        perpendicular = COS_PERPENDICULAR if self.spec.rule == "directional" else np.inf
        for p in range(self.spec.passes + 1):
            dv, active = velocity_pass(x, v, self.springs, self.limit, self.mass, anchored,
                                       vdir, tolerance, perpendicular)
            if self.comm.sum(np.array([float(active)]))[0] == 0.0:
                return True
            if p == self.spec.passes:
                return False
            dv = omega * dv[:n]
            v[:n] += dv
            x[:n] += gain * dv
            self.ghosts.update(x, v)
            report.passes += 1
        return False

    def diagnostics(self, report: LimitReport | None) -> dict:
        report = report or LimitReport()
        return {"limited_springs": report.springs, "limiter_passes": float(report.passes),
                "limited_strain": report.strain}
