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
  projected) stiffness plus a mass shift gamma M (Levenberg-Marquardt:
  from 1/h^2, a quasistatic step, down to 1e-8 lambda_max, where CG stays
  defined where the cloth has no stiffness: a flat sheet's normal
  direction), safeguarded by a backtracking (Armijo) line search on the
  potential energy so a near-singular step cannot explode; with colliders
  the contacts are an active set of the Coulomb cone (``_newton_step``).

All stop when the residual, the largest unbalanced force on a vertex
divided by its weight m g (velocity-dependent forces excluded; what pins
hold, bodies support and static friction carries is balanced: the residual
of the Coulomb contact conditions, Wriggers 2006 ch. 5, in
``collision/response.unbalanced_force``), drops below ``drape.tolerance``;
or, with ``criterion: motion``, when no vertex moved more than
``motion_tolerance`` over the last ``window`` iterations (the paper's
"visible stability" of a garment: a coarse garment pressed on a body keeps
in-plane forces that its contacts and self-contacts hold, which a force
residual cannot tell from imbalance).

Static friction in the dynamic methods (``criterion: force``; the motion
criterion's garment drapes keep a simulation's contacts): the contacts that the last
residual found inside their friction cone (within the tolerance) and at
rest are held whole in the next step (Baraff and Witkin 1998 §5: a stuck
contact is a constraint) instead of creeping under the regularised
friction force of a simulation (``physics/contact_friction.py``, up to
V_STICK): that creep lowered the potential steadily, so stop-and-go's
potential minimum never came, and it moved held vertices by a residual of
1e-2 weights.  A contact may pull by at most a tenth of the tolerance
before it is released (``ContactModel.adhesion_tolerance``): a pull counts
whole in the residual.

A drape that can never come to rest stops with the cause
(``no_rest_state``): nothing pins the cloth and it touches no collider
(it slid off every one, or there is none).  Collective: every rank calls
``iterate`` together.
"""
from __future__ import annotations

import math
import time

import numpy as np

from ..collision.response import coulomb_active_set, unbalanced_force
from ..physics.contact_friction import V_STICK
from ..simulation import SimulationError

DRAPE_DIAGNOSTICS = ("potential_energy", "gravitational_energy", "elastic_energy",
                     "kinetic_energy", "residual", "window_motion", "stops", "ksp_iterations",
                     "line_search_halvings", "touching")


class NoRestState(SimulationError):
    """The drape has no stable rest state (Relaxation.no_rest_state)."""


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
        self._gamma = None
        # a rest state needs something to hold the cloth: pins, or colliders it touches
        self._pinned = bool(sim.comm.max(np.array(
            [float(sim.pinned_local.size + sim.slide_local.size)]))[0])
        self._touched = False        # the cloth has touched a collider
        self._untouched = 0          # iterations since it last touched one
        self.touching = 0            # vertices touching a collider at the last residual
        self._stick = None           # owned contacts static friction held at the last residual
        # the force criterion's static friction (module docstring); the motion
        # criterion's garment drapes keep a simulation's contacts
        self._holds = spec.criterion == "force"
        if self._holds:
            # a contact's pull on the cloth counts whole in the residual: the
            # steps must not keep a contact that pulls by a tolerance's worth
            sim.contact.adhesion_tolerance = min(sim.contact.adhesion_tolerance,
                                                 0.1 * spec.tolerance)

    # ------------------------------------------------------------- measures
    def kinetic(self):
        n, v = self.ctx.n_owned, self.sim.state.v
        return float(self.ctx.global_sum(0.5 * np.sum(self.ctx.mass[:n, None] * v[:n] ** 2))[0])

    def residual(self):
        sim, ctx = self.sim, self.ctx
        n, state = ctx.n_owned, sim.state
        f = ctx.forces(state.x, np.zeros_like(state.v), want_jac=False)[:n]
        f = ctx.project(sim.constraints(), f)     # pins hold: only their free directions count
        sim.contact.place_layers(state.x, state.v, state.t)   # a garment rests on those under it
        # a body holds what presses on it, and static friction what stays in
        # its friction cone: a garment at rest on a body has its weight and
        # its tension carried there
        touching, normal, mu, _ = sim.contact.support(state.x, state.t, n)
        r = unbalanced_force(f, touching, normal, mu) / self.weight
        # the contacts static friction holds at rest stick in the next step
        # (held whole, not creeping under the regularised friction force); one
        # at impending slip within the tolerance is at rest too
        stick = coulomb_active_set(f, touching, normal, mu,
                                   self.spec.tolerance * self.weight)[0]
        vt = state.v[:n] - np.einsum("ij,ij->i", state.v[:n], normal)[:, None] * normal
        self._stick = stick & (np.einsum("ij,ij->i", vt, vt) <= V_STICK ** 2)
        worst = ctx.global_max(np.max(r, initial=0.0))[0]
        self.touching = int(ctx.global_sum(float(touching.sum()))[0])
        return float(worst)

    def no_rest_state(self) -> str | None:
        """Why the drape cannot come to rest, or None: under gravity, a cloth
        that no pin holds and that touches no collider (none in the scene, or
        it slid off every one and has touched none for ``window``
        iterations) falls for ever.  Collective values only: every rank
        answers the same."""
        cfg = self.sim.cfg
        if self._pinned or not (cfg.has("gravity") and np.any(cfg.gravity)):
            return None
        if not self.sim.contact.has_bodies:
            return "no stable rest state: nothing holds the cloth (no pins, no colliders)"
        if self.touching:
            self._touched, self._untouched = True, 0
            return None
        self._untouched += 1
        if self._touched and self._untouched >= self.spec.window:
            return (f"no stable rest state: the cloth slid off every collider and has touched "
                    f"none for {self._untouched} iterations (it falls for ever)")
        return None

    # ------------------------------------------------------------ iteration
    def iterate(self) -> dict:
        method = self.spec.method
        its, halvings = 0, 0
        if method == "newton":
            its, halvings = self._newton_step()
        elif method == "quasistatic":
            self._zero_velocities()
            self._stick_contacts()
            its = self.sim.step()["ksp_iterations"]
            self._zero_velocities()
        else:
            self._stick_contacts()
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
                "line_search_halvings": halvings, "touching": self.touching}

    def _stick_contacts(self):
        """The contacts static friction held at the last residual stick in
        the next step (the first step's: at the start state)."""
        if not self._holds:
            return
        if self._stick is None:
            self.residual()
        self.sim.contact.stick(self._stick)

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
        """One damped Newton step of the static problem with frictional
        contact: (K + gamma M) dx = f + f_friction under the contacts' active
        set (response.coulomb_active_set: sticking vertices held, sliding ones
        free in the tangent plane against the cone's limit force), the
        vertices it takes into a body pushed back out, and a backtracking
        line search on the potential less the work of the sliding contacts'
        friction held fixed over the step (lagged friction, as Li et al.
        2020 §5 lag theirs: its work is then linear in the motion and dx a
        descent direction; at a fixed point dx = 0 each sliding contact's
        tangential force is on its cone).  gamma is a Levenberg-Marquardt
        shift (Marquardt 1963): 1/h^2 at the start (the first step is a
        quasistatic one, Eq. 2, so a cloth in free flight falls by a step's
        worth, not to infinity), divided by 4 after every full step down to
        the vanishing 1e-8 lambda_max (Eq. 3), multiplied by 4 after a step
        the line search had to shorten."""
        sim, ctx = self.sim, self.ctx
        n, state = ctx.n_owned, sim.state
        if self._eps is None:
            self._eps = 1e-8 * sim.stiffness_bound()
            self._gamma = max(1.0 / sim.h ** 2, self._eps)
        self._zero_velocities()
        x0 = state.x.copy()
        f = ctx.forces(x0, state.v, want_jac=True)
        sim.contact.place_layers(x0, state.v, state.t)
        touching, normal, mu, _ = sim.contact.support(x0, state.t, n)
        stick, slide, friction = coulomb_active_set(f[:n], touching, normal, mu)
        held = np.nonzero(stick | slide)[0]
        S = np.zeros((held.size, 3, 3))
        ns = normal[held][slide[held]]
        S[slide[held]] = np.eye(3)[None] - np.einsum("ni,nj->nij", ns, ns)
        rhs = f[:n] + friction
        data = ctx.assemble(alpha=1.0, beta=0.0, gamma=self._gamma)
        dx_owned, info = ctx.solve(data, rhs,
                                   sim.constraints(static=(held, S, np.zeros((held.size, 3)))))
        dx = ctx.local_array(dx_owned)

        def merit(x):
            # the sliding contacts' friction lagged (frozen) over the step: its
            # work is linear in the motion, so dx is a descent direction
            work = float(np.sum(friction * (x[:n] - x0[:n])))
            return sum(sim.potential_energies(x)) - ctx.global_sum(work)[0]

        p0 = sum(sim.potential_energies(x0))
        slope = -ctx.global_sum(float(np.sum(rhs * dx_owned)))[0]   # dP/dt at t = 0
        t, halvings = 1.0, 0
        while halvings < 40:
            trial = sim.contact.push_out(x0 + t * dx, state.t) if sim.contact.has_bodies \
                else x0 + t * dx
            if merit(trial) <= p0 + 1e-4 * t * min(slope, 0.0):
                break
            t *= 0.5
            halvings += 1
        else:
            trial = x0                   # no decrease found: stay (the residual test decides)
        state.x[:] = trial
        self._gamma = max(self._gamma / 4.0, self._eps) if halvings == 0 else self._gamma * 4.0
        return info.iterations, halvings


def drape_converged(diag, spec) -> bool:
    if spec.criterion == "motion":
        return diag["window_motion"] <= spec.motion_tolerance     # NaN between windows: False
    return diag["residual"] <= spec.tolerance and math.isfinite(diag["residual"])


def relax_to_rest(relax: Relaxation, max_iterations: int):
    """Iterate ``relax`` until its drape converges, it has no rest state or
    ``max_iterations`` are done (a script's loop; ``distcloth drape`` writes
    every iteration).  Returns (iterations, last diagnostics, CG iterations
    in all, the no-rest-state reason or None, wall seconds from a common
    start on every rank)."""
    relax.sim.comm.synchronize()
    t0 = time.perf_counter()
    ksp, k, diag, reason = 0, 0, None, None
    for k in range(1, max_iterations + 1):
        diag = relax.iterate()
        ksp += diag["ksp_iterations"]
        if drape_converged(diag, relax.spec):
            break
        reason = relax.no_rest_state()
        if reason:
            break
    return k, diag, ksp, reason, time.perf_counter() - t0
