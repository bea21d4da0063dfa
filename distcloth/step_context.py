"""What an integrator (or a relaxation) may do with the cloth during a step.

A narrow interface over the force terms, the assembled system, the linear
solver, the ghost exchange and global reductions, each operation charged to
its stage of the pipeline.  It holds no state of the step: positions and
velocities come in as arguments (from the State), results go out as arrays.
"""
from __future__ import annotations

import math

import numpy as np

from .stages import FORCE_STAGES


class StepContext:
    def __init__(self, n_owned: int, mass: np.ndarray, terms, pipeline, ghosts, comm,
                 barrier=None, contact_constraints=False):
        self.n_owned = n_owned
        self.barrier = barrier           # body contact as a barrier term, or None
        # collisions are constraints of the step's solves (contact passes)
        self.contact_constraints = contact_constraints
        self.n_local = mass.shape[0]
        self.mass = mass                 # (n_local,) lumped vertex masses
        self.terms = terms
        self.pipeline = pipeline
        self.ghosts = ghosts
        self.comm = comm
        self._min_mass = None

    def min_mass(self) -> float:
        """The smallest vertex mass over the ranks (collective on first use)."""
        if self._min_mass is None:
            local = float(np.min(self.mass[: self.n_owned], initial=math.inf))
            self._min_mass = -float(self.global_max(-local)[0])
        return self._min_mass

    def forces(self, x, v, want_jac: bool, start=None, dissipation_at=None) -> np.ndarray:
        """Sum of the enabled force terms on every local row (each term is a stage);
        with ``want_jac`` the terms keep what the system and products need.
        With ``start``: the force of a step from start to x, each term's
        discrete gradient (``ForceTerm.evaluate_between``), v the midpoint's.
        With ``dissipation_at``: the dissipative terms' forces (damping, drag)
        with these positions instead of x, lagged as in ``potential``."""
        f = np.zeros((self.n_local, 3))
        lagged = () if dissipation_at is None else {t.name for t in self.terms if t.dissipative}
        for name in FORCE_STAGES:
            self.pipeline.run(name, dissipation_at if name in lagged else x, v, f, want_jac,
                              start)
        return f

    def begin_step(self, x0) -> None:
        """Tell the terms that follow something from step to step (the
        dihedral angles' branch) where the step starts (local rows)."""
        for t in self.terms:
            if hasattr(t, "at_step_start"):
                t.at_step_start(x0)

    def potential(self, x, v, position_weight: float, velocity_weight: float,
                  dissipation_at=None) -> float:
        """Over the ranks: position_weight times the terms' potential energy at
        x plus velocity_weight times their dissipation potentials at v (the
        parts of a step's incremental potential the forces are gradients of),
        the dissipation potentials taken with the positions ``dissipation_at``
        if given (lagged, as friction's normal forces are) instead of x."""
        at = x if dissipation_at is None else dissipation_at
        local = 0.0
        for t in self.terms:
            if self.pipeline.enabled(t.name):
                local += position_weight * t.energy(x) + velocity_weight * t.dissipation(at, v)
        return float(self.global_sum(local)[0])

    def contact_step_bound(self, x, dx) -> float:
        """The largest fraction <= 1 of the move dx (owned rows) that keeps every
        vertex outside its contact distance, over the ranks (1 without a barrier)."""
        return self.contact_step_fractions(x, dx)[1]

    def contact_step_fractions(self, x, dx) -> tuple[np.ndarray, float]:
        """Each owned vertex's largest fraction <= 1 of its move dx that keeps it
        outside its contact distance, and the least of them over the ranks."""
        if self.barrier is None:
            return np.ones(self.n_owned), 1.0
        own = self.barrier.step_bound(x, dx)
        return own, -float(self.global_max(-float(np.min(own, initial=1.0)))[0])

    def stiffness_product(self, w) -> np.ndarray:
        """(df/dx) w at the last evaluation, on every local row."""
        out = np.zeros((self.n_local, 3))
        for t in self.terms:
            if t.has_jacobian and self.pipeline.enabled(t.name):
                t.stiffness_product(w, out)
        return out

    def assemble(self, alpha: float, beta: float, gamma: float = 1.0) -> np.ndarray:
        """Block values of A = gamma M - beta df/dv - alpha df/dx (owned rows)."""
        return self.pipeline.run("assembly", alpha, beta, gamma)

    def solve(self, data, rhs, cons, guess=None, rtol=None, keep_preconditioner=False,
              correction=False, target=None):
        """(dv on the owned rows, solve info) of A dv = rhs under the constraints,
        the iteration started from ``guess`` (owned rows) if given; ``rtol``:
        a looser relative tolerance for this solve (an inexact Newton step);
        ``keep_preconditioner``: a multigrid preconditioner is the last solve's
        (a later Newton iteration of the same step); ``correction``: a Newton
        correction, started from zero, which leaves the warm start as it was;
        ``target``: the absolute residual |b - A dv| to stop at instead of the
        relative tolerance (within the bounds of LinearSystem.aimed)."""
        return self.pipeline.run("solve", data, rhs, cons, guess, rtol, keep_preconditioner,
                                 correction, target)

    def local_array(self, owned_rows: np.ndarray) -> np.ndarray:
        """(n_local, k): the owned rows with their ghost copies filled in."""
        a = np.zeros((self.n_local, owned_rows.shape[1]))
        a[: self.n_owned] = owned_rows
        self.ghosts.update(a)
        return a

    def update_ghosts(self, *arrays: np.ndarray) -> None:
        self.ghosts.update(*arrays)

    def project(self, cons, rows):
        """S applied to the constrained owned rows of an (n_owned, 3) array."""
        out = rows.copy()
        owned = cons.index < self.n_owned
        idx = cons.index[owned]
        out[idx] = np.einsum("nij,nj->ni", cons.S[owned], rows[idx])
        return out

    def global_norm(self, rows) -> float:
        """The 2-norm over the ranks of the owned rows ``rows``."""
        return math.sqrt(self.comm.sum(np.array([float(np.sum(rows * rows))]))[0])

    def global_sum(self, *values: float) -> np.ndarray:
        """Each value summed over the ranks."""
        return self.comm.sum(np.array(values, dtype=np.float64))

    def global_max(self, *values: float) -> np.ndarray:
        """Each value's maximum over the ranks."""
        return self.comm.max(np.array(values, dtype=np.float64))
