"""Draping: relaxation to the rest state (Volino and Magnenat-Thalmann 2007, seed 004).

Four methods, one iteration each per call of ``Relaxation.iterate``:

* ``dynamic``: plain dynamic simulation with the scene's integrator;
* ``stop_and_go`` (seed 004 §2.1): dynamic simulation with as little damping
  as the scene has; when the total potential energy (gravity + elastic)
  passes a minimum, or optionally the kinetic energy a maximum, the state
  goes back to that extremum and all velocities are set to zero;
* ``quasistatic`` (seed 004 Eq. 2): backward Euler with the velocities
  zeroed before and after each step, (M - h^2 K) dx = h^2 f;
* ``newton`` (seed 004 Eq. 3): dx = -K^-1 f, with K the (clamped, SPD-
  projected) stiffness plus a vanishing mass shift 1e-8 lambda_max M so CG
  stays defined where the cloth has no stiffness (a flat sheet's normal
  direction), safeguarded by a backtracking (Armijo) line search on the
  potential energy so a near-singular step cannot explode.

All stop when the residual, the largest force on a free vertex divided by
its weight m g (velocity-dependent forces excluded), drops below
``drape.tolerance``.  Collective: every rank calls ``iterate`` together.
"""
from __future__ import annotations

import math

import numpy as np

DRAPE_DIAGNOSTICS = ("potential_energy", "gravitational_energy", "elastic_energy",
                     "kinetic_energy", "residual", "stops", "ksp_iterations", "line_search_halvings")


class Relaxation:
    def __init__(self, sim, spec):
        self.sim, self.spec = sim, spec
        self.stops = 0
        self.iteration = 0
        g = float(np.linalg.norm(sim.cfg.gravity)) or 9.81
        self.weight = sim.mass[: sim.n_owned] * g
        self._prev = None            # (x, v, potential, kinetic) after the last iteration
        self._eps = None

    # ------------------------------------------------------------- measures
    def energies(self, x=None):
        """(gravitational, elastic) potential energy at x (local, ghosts valid); collective."""
        sim = self.sim
        x = sim.x if x is None else x
        grav = elastic = 0.0
        for t in sim.terms:
            if t.name == "force:gravity":
                grav += t.energy(x)
            elif t.has_jacobian and hasattr(t, "energy") and t.name != "force:damping":
                elastic += t.energy(x)
        return tuple(sim.comm.sum(np.array([grav, elastic])))

    def kinetic(self):
        sim, n = self.sim, self.sim.n_owned
        return float(sim.comm.sum(np.array([0.5 * np.sum(sim.mass[:n, None] * sim.v[:n] ** 2)]))[0])

    def residual(self):
        sim, n = self.sim, self.sim.n_owned
        f = sim.forces(sim.x, np.zeros_like(sim.v), want_jac=False)[:n]
        f = sim.project(sim._constraints(), f)      # only the free directions count
        r = np.sqrt(np.einsum("ij,ij->i", f, f)) / self.weight
        return float(sim.comm.max(np.array([np.max(r, initial=0.0)]))[0])

    # ------------------------------------------------------------ iteration
    def iterate(self) -> dict:
        method = self.spec.method
        its, halvings = 0, 0
        if method == "newton":
            its, halvings = self._newton_step()
        elif method == "quasistatic":
            self._zero_velocities()
            its = self.sim.step()["ksp_iterations"]
            self._zero_velocities()
        else:
            its = self.sim.step()["ksp_iterations"]
            if method == "stop_and_go":
                self._stop_if_extremum()
        self.iteration += 1
        grav, elastic = self.energies()
        return {"potential_energy": grav + elastic, "gravitational_energy": grav,
                "elastic_energy": elastic, "kinetic_energy": self.kinetic(),
                "residual": self.residual(), "stops": self.stops, "ksp_iterations": its,
                "line_search_halvings": halvings}

    def _zero_velocities(self):
        self.sim.v[:] = 0.0
        history = getattr(self.sim.integrator, "history", None)
        if history is not None:          # a multistep history no longer applies
            self.sim.integrator.history = None

    def _stop_if_extremum(self):
        """Seed 004 §2.1: back to the potential minimum (kinetic maximum) just passed, v = 0."""
        sim = self.sim
        grav, elastic = self.energies()
        potential, kinetic = grav + elastic, self.kinetic()
        prev = self._prev
        self._prev = (sim.x.copy(), sim.v.copy(), potential, kinetic)
        if prev is None:
            return
        passed = potential > prev[2] if self.spec.stop_on == "potential" else kinetic < prev[3]
        if passed:
            sim.x[:] = prev[0]
            self._zero_velocities()
            self.stops += 1
            self._prev = (sim.x.copy(), sim.v.copy(), prev[2], 0.0)

    def _newton_step(self):
        sim = self.sim
        n = sim.n_owned
        if self._eps is None:
            lam = sim.comm.max(np.array([sim._gershgorin_local()]))[0]
            self._eps = 1e-8 * lam
        self._zero_velocities()
        f = sim.forces(sim.x, sim.v, want_jac=True)
        data = sim.assemble(alpha=1.0, beta=0.0, gamma=self._eps)
        cons = sim._constraints()            # v = 0: the constrained directions stay put
        dx_owned, info = sim.solve(data, f[:n], cons)
        dx = sim.local_array(dx_owned)
        p0 = sum(self.energies())
        slope = -sim.comm.sum(np.array([float(np.sum(f[:n] * dx_owned))]))[0]   # dP/dt at t = 0
        t, halvings = 1.0, 0
        while halvings < 40:
            trial = sim.x + t * dx
            if sum(self.energies(trial)) <= p0 + 1e-4 * t * min(slope, 0.0):
                break
            t *= 0.5
            halvings += 1
        else:
            t = 0.0                      # no decrease found: stay (the residual test decides)
        sim.x += t * dx
        return info.iterations, halvings


def drape_converged(diag, spec) -> bool:
    return diag["residual"] <= spec.tolerance and math.isfinite(diag["residual"])
