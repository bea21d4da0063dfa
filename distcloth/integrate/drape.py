"""Draping: relaxation to the rest state (Volino and Magnenat-Thalmann 2007).

Four methods, one iteration each per call of ``Relaxation.iterate``:

* ``dynamic``: plain dynamic simulation with the scene's integrator;
* ``stop_and_go`` (§2.1): dynamic simulation with as little damping
  as the scene has; when the total potential energy (gravity + elastic)
  passes a minimum, or optionally the kinetic energy a maximum, the state
  goes back to that extremum and all velocities are set to zero;
* ``quasistatic`` (Eq. 2): backward Euler with the velocities
  zeroed before and after each step, (M - h^2 K) dx = h^2 f;
* ``newton`` (Eq. 3): dx = -K^-1 f, with K the (clamped, SPD-
  projected) stiffness plus a vanishing mass shift 1e-8 lambda_max M so CG
  stays defined where the cloth has no stiffness (a flat sheet's normal
  direction), safeguarded by a backtracking (Armijo) line search on the
  potential energy so a near-singular step cannot explode.

All stop when the residual, the largest unbalanced force on a vertex
divided by its weight m g (velocity-dependent forces excluded; what pins
hold, bodies support and static friction carries is balanced), drops below
``drape.tolerance``; or, with ``criterion: motion``, when no vertex moved
more than ``motion_tolerance`` over the last ``window`` iterations (the
paper's "visible stability" of a garment: a coarse garment pressed on a
body keeps in-plane forces that its contacts and self-contacts hold, which
a force residual cannot tell from imbalance).  Collective: every rank
calls ``iterate`` together.
"""
from __future__ import annotations

import math

import numpy as np

DRAPE_DIAGNOSTICS = ("potential_energy", "gravitational_energy", "elastic_energy",
                     "kinetic_energy", "residual", "window_motion", "stops", "ksp_iterations",
                     "line_search_halvings")


class Relaxation:
    """Relaxation of a Simulation's state, through its public interface: its
    State, its step, its constraints, potential energies and stiffness bound,
    and the step context's forces, assembly and solve."""

    def __init__(self, sim, spec):
        self.sim, self.spec = sim, spec
        self.ctx = sim.ctx
        self.stops = 0
        self.iteration = 0
        g = float(np.linalg.norm(sim.cfg.gravity)) or 9.81
        self.weight = sim.mass[: sim.n_owned] * g
        self._prev = None            # (x, v, potential, kinetic) after the last iteration
        self._restarted = False      # the last iteration ended in a stop
        self._checkpoint = sim.state.x[: sim.n_owned].copy()   # at the start of the motion window
        self._eps = None

    # ------------------------------------------------------------- measures
    def kinetic(self):
        n, v = self.ctx.n_owned, self.sim.state.v
        return float(self.ctx.global_sum(0.5 * np.sum(self.ctx.mass[:n, None] * v[:n] ** 2))[0])

    def residual(self):
        sim, ctx = self.sim, self.ctx
        n, state = ctx.n_owned, sim.state
        f = ctx.forces(state.x, np.zeros_like(state.v), want_jac=False)[:n]
        f = ctx.project(sim.constraints(), f)     # pins hold: only their free directions count
        # a body holds what presses on it, and static friction what stays in
        # its friction cone: a garment at rest on a body has its weight and
        # its tension carried there
        r = sim.contact.unbalanced(state.x, state.t, f) / self.weight
        return float(ctx.global_max(np.max(r, initial=0.0))[0])

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
        motion = self._window_motion()
        grav, elastic = self.sim.potential_energies()
        return {"potential_energy": grav + elastic, "gravitational_energy": grav,
                "elastic_energy": elastic, "kinetic_energy": self.kinetic(),
                "residual": self.residual(), "window_motion": motion, "stops": self.stops,
                "ksp_iterations": its,
                "line_search_halvings": halvings}

    def _window_motion(self) -> float:
        """The largest displacement of a vertex over the last ``window``
        iterations, measured every window iterations (NaN in between)."""
        n, x = self.ctx.n_owned, self.sim.state.x
        if self.iteration % self.spec.window:
            return math.nan
        d = x[:n] - self._checkpoint
        self._checkpoint = x[:n].copy()
        return float(self.ctx.global_max(np.sqrt(np.max(np.einsum("ij,ij->i", d, d),
                                                         initial=0.0)))[0])

    def _zero_velocities(self):
        self.sim.state.v[:] = 0.0
        self.sim.state.clear_history()

    def _stop_if_extremum(self):
        """Volino and Magnenat-Thalmann 2007 §2.1: back to the potential minimum
        (kinetic maximum) just passed, v = 0."""
        state = self.sim.state
        grav, elastic = self.sim.potential_energies()
        potential, kinetic = grav + elastic, self.kinetic()
        prev = self._prev
        self._prev = (state.x.copy(), state.v.copy(), potential, kinetic)
        # the first step from a stop is always taken: from rest a step lowers
        # the potential unless contact pushes the cloth out (a tight garment
        # against a body), and going back to the same state would stop forever
        if prev is None or self._restarted:
            self._restarted = False
            return
        if self.spec.stop_on == "potential":
            passed = potential > prev[2]
        elif self.spec.stop_on == "kinetic":
            passed = kinetic < prev[3]
        else:
            # both: a rise of the potential while the motion still speeds up is
            # contact pushing cloth out of a body, not the bottom of a swing
            passed = potential > prev[2] and kinetic < prev[3]
        if passed:
            state.x[:] = prev[0]
            self._zero_velocities()
            self.stops += 1
            self._restarted = True
            self._prev = (state.x.copy(), state.v.copy(), prev[2], 0.0)

    def _newton_step(self):
        sim, ctx = self.sim, self.ctx
        n, state = ctx.n_owned, sim.state
        if self._eps is None:
            self._eps = 1e-8 * sim.stiffness_bound()
        self._zero_velocities()
        f = ctx.forces(state.x, state.v, want_jac=True)
        data = ctx.assemble(alpha=1.0, beta=0.0, gamma=self._eps)
        cons = sim.constraints(contacts=state.contacts)   # v = 0: the constrained directions stay put
        dx_owned, info = ctx.solve(data, f[:n], cons)
        dx = ctx.local_array(dx_owned)
        p0 = sum(sim.potential_energies())
        slope = -ctx.global_sum(float(np.sum(f[:n] * dx_owned)))[0]   # dP/dt at t = 0
        t, halvings = 1.0, 0
        while halvings < 40:
            trial = state.x + t * dx
            if sum(sim.potential_energies(trial)) <= p0 + 1e-4 * t * min(slope, 0.0):
                break
            t *= 0.5
            halvings += 1
        else:
            t = 0.0                      # no decrease found: stay (the residual test decides)
        state.x += t * dx
        return info.iterations, halvings


def drape_converged(diag, spec) -> bool:
    if spec.criterion == "motion":
        return diag["window_motion"] <= spec.motion_tolerance     # NaN between windows: False
    return diag["residual"] <= spec.tolerance and math.isfinite(diag["residual"])
