"""Implicit one-step schemes as Newton on the velocity change dv = v1 - v0.

Each scheme fixes, for its step, the state where forces are evaluated as an
affine function of dv and a residual (EG07 tutorial Part 2 §2.3 compares
backward Euler, BDF-2 and backward midpoint; Newmark 1959 for the beta/gamma
family):

    x_e = x_pred + a_x dv,   v_e = v0 + a_v dv
    g(dv) = M (dv - d) - s f(x_e, v_e)
    dg/ddv = M - s a_v df/dv - s a_x df/dx       (the assembled system)

The first Newton iteration starts from dv = 0, the predictor, and is
linearised there (forces and Jacobians at (x_pred, v0)):

    (M - s a_v D - s a_x K) dv = M d + s f(x_pred, v0)

so ``time.newton_iterations: 1`` is one linear solve per step for every
scheme (the default, except for the energy-momentum midpoint below); more
iterations continue Newton on g until |S g| <= tol |b0|.  Baraff and Witkin
(1998) linearise at the start state instead, b = M d + s (f0 + K (x_pred -
x0)); Newmark other than 1/4, 1/2 still does (its predictor needs f0).

Energy-momentum midpoint (``time.energy_momentum``, Simo and Tarnow 1992;
Gonzalez 1996).  The midpoint rule evaluates f at (x0 + x1)/2 and conserves
energy only for energies quadratic in x; on a stiff nonlinear membrane its
converged steps gain energy until the run blows up (docs/integrators.md), and
so does the trapezoidal rule (Newmark 1/4, 1/2).  With energy_momentum the
residual's conservative forces are discrete gradients between x0 and x1
(``ForceTerm.evaluate_between``), f . (x1 - x0) = -(U(x1) - U(x0)), so with
x1 - x0 = h (v0 + v1)/2 the kinetic energy changes by exactly the work
h f . (v0 + v1)/2 = -(U1 - U0): a converged step conserves energy to the Newton
tolerance, and the scheme stays second order (the discrete gradient differs
from f at the midpoint by O(|x1 - x0|^2)).  Newton's matrix is the midpoint
Hessian, which differs from the discrete gradient's own derivative by
O(|x1 - x0|): Newton converges linearly, fast while the step moves the
elements little against their size.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..config.schema import ENERGY_MOMENTUM_NEWTON_ITERATIONS
from ..linalg.constraints import Constraints
from ..state import MultistepHistory
from .base import Integrator, StepResult


# an iteration that leaves more than this fraction of the residual triggers the
# half-step test (measured on the stability suite's hanging sheet: a stalled
# step oscillates with ratios 0.85-1.1, healthy steps contract by 0.5-0.7)
DAMPING_TRIGGER = 0.8
# in the energy retry's Newton, an update that raises the residual's norm is
# halved until it lowers it, at most down to this fraction (5 halvings); if none
# does, the fraction that raised it least is kept
MIN_NEWTON_STEP = 1.0 / 32.0
# where an unconverged step is rejected anyway (time.require_newton_convergence),
# Newton gives up once the contraction of its last NEWTON_RATE_WINDOW iterations,
# continued, would not reach the tolerance within the iterations left: the
# energy-momentum Newton converges linearly, and a step that cannot converge
# used to spend all its iterations before being halved
NEWTON_RATE_WINDOW = 3
# the barrier's line search (IPC, Li et al. 2020 §4): sufficient decrease of
# the incremental potential, and how often a step is halved looking for it
ARMIJO = 1.0e-4
# the loosest relative tolerance of a Newton correction's linear solve, in the
# barrier's Newton and a scene's own iterations (the scene's ksp_rtol where
# that is looser).  On the stiff hanging square S1-41 (BDF-2, Newton to 1e-4
# in at most 4 iterations) 1e-2 took 30-34 % fewer CG iterations than every
# correction at ksp_rtol 1e-3 and left the error at 0.5 s, the least touched
# by the free edge's whip, where it was; 1e-1 saved 6-7 % more (docs/
# benchmarks.md, "Newton corrections solved inexactly")
MAX_FORCING = 1.0e-2
# a correction reaches the tolerance if it leaves this fraction of what the
# tolerance allows: the linear solve's residual is what is left of the Newton
# residual, up to the nonlinearity's second-order part
FORCING_MARGIN = 0.5
MAX_BARRIER_BACKTRACKS = 30
# a vertex whose gap at the start of a barrier step is below this fraction of
# the barrier's width is put outside first: the barrier's log needs s > 0, and
# its force grows without bound as s -> 0
BARRIER_START_GAP = 1.0e-3


@dataclass
class Affine:
    x_pred: np.ndarray     # (n_local, 3)
    a_x: float
    a_v: float
    d: np.ndarray          # (n_owned, 3) velocity offset of the residual
    s: float


class ImplicitScheme(Integrator):
    """A scheme defines ``affine`` (given f0 at the start state) and ``final``."""

    def affine(self, ctx, state, h, f0, cons) -> Affine:
        raise NotImplementedError

    def final(self, ctx, state, h, aff: Affine, dv):
        """(x1, v1) on the owned rows from the converged velocity change, and dx1/dv1."""
        n = ctx.n_owned
        return aff.x_pred[:n] + aff.a_x * dv[:n], state.v[:n] + dv[:n], aff.a_x

    def linearise_at_predictor(self) -> bool:
        """True: the first Newton iteration is linearised at the predictor
        (x_pred, v0), where the residual's dv = 0 evaluates its forces.
        Baraff and Witkin's linearisation at the start state x0 misses the
        forces' curvature over |x_pred - x0| = O(h): on a stiff membrane
        (h omega >> 1) that lags the membrane's turning (centripetal) force
        by a step and makes every scheme first order (docs/integrators.md,
        "Stiff membranes").  False where the affine map needs f0 (Newmark), and
        where the scene asks for the start state (time.linearise_at)."""
        return self.cfg.time.linearise_at != "start"

    def newton_iterations(self) -> int:
        """time.newton_iterations, or this scheme's default when it is null;
        with contact as a barrier, the barrier Newton's limit (its steps are
        never retried)."""
        if self.cfg.contact.model == "barrier" and self.cfg.has("collisions"):
            return self.cfg.contact.newton_iterations
        if self.newton_override is not None:
            return max(self.newton_override, self._configured_newton())
        return self._configured_newton()

    def _configured_newton(self) -> int:
        n = self.cfg.time.newton_iterations
        return n if n is not None else (ENERGY_MOMENTUM_NEWTON_ITERATIONS
                                        if self.energy_momentum() else 1)

    def energy_momentum(self) -> bool:
        """True if the Newton residual takes discrete-gradient forces."""
        return False

    def damped_newton(self) -> bool:
        """Halve a Newton update that reduced the residual by less than
        DAMPING_TRIGGER (the energy-momentum schemes: their energy is only
        as good as the converged residual)."""
        return self.energy_momentum()

    def residual_forces(self, ctx, state, h, aff: Affine, dv, want_jac=True):
        """The forces of the Newton residual at the velocity change dv (local
        rows); with ``want_jac`` the terms keep their Jacobians for the next
        Newton matrix."""
        return ctx.forces(aff.x_pred + aff.a_x * dv, state.v + aff.a_v * dv, want_jac=want_jac)

    def history(self, state, h) -> MultistepHistory | None:
        """What the state keeps of this step if it is committed (multistep schemes)."""
        return None

    def step(self, ctx, state, h, cons, guess=None):
        if ctx.barrier is not None:
            return self._barrier_step(ctx, state, h, cons)
        n = ctx.n_owned
        x0, v0 = state.x, state.v
        m = ctx.mass[:n, None]
        if self.linearise_at_predictor():
            # Newton's first iterate dv = 0 is the predictor: linearised there,
            # not at x0 (below), the step misses only O(|x1 - x_pred|^2) = O(h^4)
            aff = self.affine(ctx, state, h, None, cons)
            f = ctx.forces(aff.x_pred, v0, want_jac=True)
            f0 = f
            b = m * aff.d + aff.s * f[:n]
        else:
            f = ctx.forces(x0, v0, want_jac=True)
            f0 = f
            aff = self.affine(ctx, state, h, f, cons)
            kx = ctx.stiffness_product(aff.x_pred - x0)
            b = m * aff.d + aff.s * (f[:n] + kx[:n])
        alpha, beta = aff.s * aff.a_x, aff.s * aff.a_v
        data = ctx.assemble(alpha=alpha, beta=beta)
        max_its = self.newton_iterations()
        dv_owned, info = ctx.solve(data, b, cons, guess,
                                   target=self._solve_target(ctx, state, h, aff, max_its))
        ksp_its, ksp_res = info.iterations, info.residual
        dv = ctx.local_array(dv_owned)
        reaction = info.reaction
        newton_its, rel, converged, stopped = 1, 0.0, True, False
        if max_its > 1:
            converged = False
            b0 = max(ctx.global_norm(b), 1e-300)
            relaxed = Constraints(cons.index, cons.S, np.zeros_like(cons.z))
            delta, last = None, np.inf

            def residual(dv, want_jac=True):
                g = m * (dv[:n] - aff.d) - aff.s * self.residual_forces(ctx, state, h, aff, dv,
                                                                        want_jac)[:n]
                return g, ctx.global_norm(ctx.project(relaxed, -g)) / b0

            # the energy retry's Newton (newton_override) searches along its
            # directions; a scene's own Newton iterations stay plain Newton, which
            # reaches static equilibria (Peirce, elastica) in fewer iterations
            search = self.newton_override is not None
            give_up = self.cfg.time.require_newton_convergence
            g, rel = residual(dv)
            rels = [rel]
            while newton_its < max_its:
                if delta is not None and rel > DAMPING_TRIGGER * last and self.damped_newton():
                    # slow progress: Newton's matrix (projected Hessians at the
                    # midpoint) is far from the residual's derivative and the
                    # iteration overshoots; the half step is kept if it is better
                    half = dv.copy()
                    half[:n] -= 0.5 * delta
                    ctx.update_ghosts(half)
                    g_half, rel_half = residual(half)
                    if rel_half < rel:
                        dv, g, rel = half, g_half, rel_half
                        rels[-1] = rel
                last = rel
                if rel <= self.cfg.time.newton_tolerance:
                    converged = True
                    break
                if give_up and not _reachable(rels, self.cfg.time.newton_tolerance,
                                              max_its - newton_its):
                    break
                data = ctx.assemble(alpha=alpha, beta=beta)   # linearised at dv: its last evaluation
                # inexact Newton (Eisenstat and Walker 1996): while iterations
                # remain, a correction need only reduce the residual by the
                # residual's own relative size, or as far as reaches the
                # tolerance; the last one allowed is solved at the scene's
                # ksp_rtol unless a looser solve reaches the tolerance
                enough = FORCING_MARGIN * self.cfg.time.newton_tolerance / rel
                last_allowed = newton_its + 1 >= max_its
                forcing = min(MAX_FORCING, enough if last_allowed else max(rel, enough))
                # a multigrid preconditioner of the step's first solve serves
                # its corrections: on S1-101 (GAMG) a set-up per correction
                # cost 5.9 s of a 2 s run and saved no CG iterations; not with
                # contact as constraints, where on the tablecloth at 317² a
                # step's last solve took 18 % more CG iterations with it
                delta, info = ctx.solve(data, -g, relaxed, rtol=forcing, correction=True,
                                        keep_preconditioner=not ctx.contact_constraints)
                ksp_its += info.iterations
                ksp_res = max(ksp_res, info.residual)
                newton_its += 1
                reaction = info.reaction
                trial = dv.copy()
                # after the last iteration allowed no Newton matrix follows: its
                # residual needs no Jacobians (the membrane's projected element
                # Hessians are most of its cost where triangles are compressed;
                # docs/benchmarks.md, "The last Newton residual without Jacobians")
                more = newton_its < max_its

                def residual_at(fraction):       # of dv + fraction * delta, into trial
                    trial[:n] = dv[:n] + fraction * delta
                    ctx.update_ghosts(trial)
                    return residual(trial, more)

                fraction = 1.0
                g_trial, rel_trial = residual_at(fraction)
                best = (rel_trial, fraction)
                while rel_trial >= rel and fraction > MIN_NEWTON_STEP and search:
                    # Newton overshoots (in contact, or far from the solution):
                    # backtrack on the residual's norm, which the full step raised
                    fraction *= 0.5
                    g_trial, rel_trial = residual_at(fraction)
                    best = min(best, (rel_trial, fraction))
                if search and rel_trial >= rel and best[1] != fraction:
                    # no fraction lowers it: the least raising one (with projected
                    # Hessians the norm can rise on the way to converging, as on
                    # the Peirce strip's huge steps), evaluated again last so that
                    # the next matrix is linearised there
                    fraction = best[1]
                    g_trial, rel_trial = residual_at(fraction)
                delta = fraction * delta
                dv, g, rel = trial, g_trial, rel_trial
                rels.append(rel)
                if search and self.retry_stop is not None and rel > self.cfg.time.newton_tolerance:
                    # the retry exists to take the energy the linearisation made:
                    # once an iterate gains none, the rest of Newton's slow tail
                    # (x0.8-0.9 an iteration on the stiff membrane) is not needed
                    x1, v1, _ = self.final(ctx, state, h, aff, dv)
                    if self.retry_stop(x1, v1):
                        stopped = True
                        break
            # the last iterate allowed is tested too (the loop tests at its top)
            converged = converged or rel <= self.cfg.time.newton_tolerance
        x1, v1, gain = self.final(ctx, state, h, aff, dv)
        return StepResult(x=x1, v=v1, start_forces=f0, position_gain=gain,
                          history=self.history(state, h), reaction=reaction,
                          newton_iterations=newton_its,
                          ksp_iterations=ksp_its, ksp_residual=ksp_res, newton_residual=rel,
                          newton_converged=converged, stopped_early=stopped,
                          local_error=self._local_error_norm(ctx, state, h, x1))

    def local_error(self, ctx, state, h, x1) -> np.ndarray | None:
        """The step's local error estimated from its result x1 (owned rows),
        or None where the scheme has no estimate."""
        return None

    def _local_error_norm(self, ctx, state, h, x1):
        """(h, |e|_M) of the step's estimate, measured only where the solve
        tolerance follows it (linear_system.step_error_fraction)."""
        if self.cfg.linear_system.step_error_fraction is None:
            return None
        e = self.local_error(ctx, state, h, x1)
        if e is None:
            return None
        m = ctx.mass[: ctx.n_owned, None]
        return h, math.sqrt(float(ctx.global_sum(float(np.sum(m * e * e)))[0]))

    def _solve_target(self, ctx, state, h, aff, max_its):
        """|b - A dv| a one-solve step's solve may leave: step_error_fraction
        of the last step's local error (a step of the same size: the error
        moves slowly from step to step), or None (the configured tolerance).
        The filtered matrix is at least M (its stiffness and damping parts
        are positive semi-definite), so a solve that leaves the residual r
        leaves an error |d|_M <= |r|_(M^-1) <= |r| / sqrt(m_min) in dv, and
        a_x times that in the positions."""
        fraction = self.cfg.linear_system.step_error_fraction
        last = state.step_error
        if fraction is None or max_its > 1 or last is None or last[0] != h:
            return None
        return fraction * last[1] * math.sqrt(ctx.min_mass()) / aff.a_x

    def _barrier_step(self, ctx, state, h, cons):
        """Newton on the step's incremental potential with body contact as a
        barrier (physics/contact_barrier.py; IPC, Li et al. 2020 §4):

            Phi(dv) = 1/2 (dv - d)^T M (dv - d) + (s / a_x) U(x) + (s / a_v) R(v)

        with x = x_pred + a_x dv, v = v0 + a_v dv, U the potentials (barrier
        included) and R the dissipation potentials, whose positions
        (friction's normal forces and directions, the damping's springs) are
        lagged at the step's first iterate, so that Phi is one function
        through the step and grad Phi the residual g.  Each vertex's part of
        an update is cut to the fraction that keeps it outside its contact
        distance (conservative advancement, vertex by vertex) where that is
        a descent direction of Phi, else the whole update to the least such
        fraction; then halved until Phi decreases (Armijo).  The first
        iterate is the way from the start state to the predictor, cut as a
        whole.  Stops when Newton's update changes no velocity by more than
        contact.velocity_tolerance; each update's constrained part is what
        is left of the pins' z, so pins reach their targets."""
        n = ctx.n_owned
        spec = self.cfg.contact
        m = ctx.mass[:n, None]
        x0, v0 = state.x, state.v
        aff = self.affine(ctx, state, h, None, cons)
        alpha, beta = aff.s * aff.a_x, aff.s * aff.a_v
        wx, wv = aff.s / aff.a_x, aff.s / aff.a_v
        bar = ctx.barrier
        start = _outside(bar, x0)
        move = aff.x_pred - start
        # the whole cloth moves the same fraction of the way (IPC's first
        # iterate).  Measured on the tablecloth landing on the sphere at 20 ms:
        # a vertex held back alone (or moved out of a body by its normal)
        # stretches its neighbours by the distance the others fall in a step,
        # and from that start Newton stalled and the energy guard stopped the run
        reach = ctx.contact_step_bound(start, move)
        dv = np.zeros_like(x0)
        dv[:n] = (start[:n] + reach * move[:n] - aff.x_pred[:n]) / aff.a_x
        ctx.update_ghosts(dv)

        def at(dv):
            return aff.x_pred + aff.a_x * dv, v0 + aff.a_v * dv

        # The dissipation potentials' positions, lagged for the whole step
        # (IPC lags friction so, Li et al. 2020 §5): spring damping's R(x, v)
        # turns with the springs' directions, a part of its gradient the
        # damping force does not have.  Taken at each trial's positions, on
        # the tablecloth at 317² that part outweighed the rest and the merit
        # rose along Newton's own direction; lagged afresh at each iterate,
        # Phi changed from one iterate to the next and Newton could cycle
        # between two iterates, each a descent of the other's Phi (41²
        # tablecloth: steps at the 50-iteration cap, docs/benchmarks.md)
        lagged_at = at(dv)[0]
        bar.lag(lagged_at)

        def merit(dv):
            x, v = at(dv)
            dk = dv[:n] - aff.d
            return (0.5 * float(ctx.global_sum(float(np.sum(m * dk * dk)))[0])
                    + ctx.potential(x, v, wx, wv, dissipation_at=lagged_at))

        complement = np.eye(3)[None] - cons.S          # the constrained directions
        ksp_its, ksp_res, reaction = 0, 0.0, None
        newton_its, converged, rel, b0 = 0, False, 0.0, None
        f, phi_dv = None, None
        while newton_its < spec.newton_iterations:
            x, v = at(dv)
            f = ctx.forces(x, v, want_jac=True, dissipation_at=lagged_at)
            g = m * (dv[:n] - aff.d) - aff.s * f[:n]
            gnorm = ctx.global_norm(ctx.project(cons, g))
            b0 = gnorm if b0 is None else b0
            rel = gnorm / max(b0, 1e-300)
            data = ctx.assemble(alpha=alpha, beta=beta)
            left = Constraints(cons.index, cons.S,
                               np.einsum("nij,nj->ni", complement, cons.z - dv[cons.index]))
            # inexact Newton (Eisenstat and Walker 1996): the linear solve need
            # only be as accurate as the residual is small
            forcing = min(MAX_FORCING, rel) if newton_its else MAX_FORCING
            # a multigrid set-up costs several solves at 100k vertices: the
            # step's later iterations keep the first one's, as contact passes do
            delta, info = ctx.solve(data, -g, left, rtol=forcing,
                                    keep_preconditioner=newton_its > 0)
            newton_its += 1
            ksp_its += info.iterations
            ksp_res = max(ksp_res, info.residual)
            reaction = info.reaction
            step, fraction = _cut_per_vertex(ctx, x, ctx.local_array(delta), g, aff.a_x)
            # Phi at dv: the last accepted trial's value (one Phi a step), else evaluated
            phi0 = merit(dv) if phi_dv is None else phi_dv
            slope = float(ctx.global_sum(float(np.sum(g * step[:n])))[0])
            trial = dv.copy()
            for _ in range(MAX_BARRIER_BACKTRACKS):
                trial[:] = dv + fraction * step
                phi_dv = merit(trial)
                if phi_dv <= phi0 + ARMIJO * fraction * min(slope, 0.0):
                    break
                fraction *= 0.5
            else:
                break        # no decrease along Newton's direction: stalled, unconverged
            dv = trial
            # converged when Newton's own update is small, whatever fraction of it was taken
            change = float(ctx.global_max(float(np.max(np.abs(delta), initial=0.0)))[0])
            if change * aff.a_v <= spec.velocity_tolerance:
                converged = True
                break
        x1, v1, gain = self.final(ctx, state, h, aff, dv)
        return StepResult(x=x1, v=v1, start_forces=f, position_gain=gain,
                          history=self.history(state, h), reaction=reaction,
                          newton_iterations=newton_its, ksp_iterations=ksp_its,
                          ksp_residual=ksp_res, newton_residual=rel, newton_converged=converged)


def _cut_per_vertex(ctx, x, step, g, a_x):
    """(direction, fraction of it that keeps every vertex outside): Newton's
    update ``step`` (local rows, ghosts filled) with each owned vertex's part
    cut to the fraction of it that keeps the vertex a tenth of its gap
    outside every body (the barrier's conservative bound, vertex by vertex),
    if any is cut and the result is still a descent direction of Phi (``g``
    its gradient on the owned rows); else ``step`` as it is, with the least
    vertex's fraction, cut as a whole.  Cut as a whole, the vertex closest to a
    body holds the whole cloth back, one vertex after another through a
    landing: on the tablecloth at 317² five to eight of a landing step's
    seven to eleven iterations were cut to 0.07-0.7 of themselves
    (docs/benchmarks.md).  Cut vertex by vertex, a vertex's neighbours may
    stretch toward it; Phi's line search weighs that."""
    n = ctx.n_owned
    own, least = ctx.contact_step_fractions(x, a_x * step)
    if least >= 1.0:
        return step, 1.0
    cut = step.copy()
    cut[:n] *= own[:, None]
    ctx.update_ghosts(cut)
    if float(ctx.global_sum(float(np.sum(g * cut[:n])))[0]) < 0.0:
        # the bound again along the cut moves (a vertex's own fraction was
        # found by advancing along its whole move: the cut one may end a
        # little short of it)
        return cut, ctx.contact_step_bound(x, a_x * cut)
    return step, least


def _outside(barrier, x):
    """x (local rows) with every free owned vertex that lies at or inside its
    contact distance of a body (a body that moved onto it, a correction after
    the last step) put half the barrier's width outside it along the normal."""
    out = x.copy()
    for s, normal, _ in barrier.gaps(x):
        rows = np.nonzero(barrier.free & (s <= BARRIER_START_GAP * barrier.width))[0]
        out[rows] += (0.5 * barrier.width - s[rows])[:, None] * normal[rows]
    return out


def _reachable(rels, tolerance, left) -> bool:
    """Whether Newton, contracting as over its last NEWTON_RATE_WINDOW
    iterations, reaches ``tolerance`` from ``rels[-1]`` within ``left`` more."""
    if len(rels) <= NEWTON_RATE_WINDOW:
        return True
    rate = (rels[-1] / rels[-1 - NEWTON_RATE_WINDOW]) ** (1.0 / NEWTON_RATE_WINDOW)
    if rate >= 1.0:
        return False
    return rels[-1] * rate ** left <= tolerance


class BackwardEuler(ImplicitScheme):
    """x1 = x0 + h v1, M (v1 - v0) = h f(x1, v1): first order, dissipative."""

    def monotone_energy(self, state, h):
        # dissipative: its converged passive steps lose energy (docs/integrators.md)
        return True

    def affine(self, ctx, state, h, f0, cons):
        return Affine(state.x + h * state.v, h, 1.0, np.zeros((ctx.n_owned, 3)), h)

    def local_error(self, ctx, state, h, x1):
        # against the explicit Euler predictor x0 + h v0 (error -h^2 a/2 + O(h^3))
        # backward Euler's own error is +h^2 a/2: half their difference (Milne's device)
        n = ctx.n_owned
        return 0.5 * (x1 - state.x[:n] - h * state.v[:n])


class ImplicitMidpoint(ImplicitScheme):
    """x1 = x0 + h (v0 + v1)/2, M (v1 - v0) = h f((x0 + x1)/2, (v0 + v1)/2):
    second order, symplectic, no numerical damping."""
    held_gain = 0.5

    def affine(self, ctx, state, h, f0, cons):
        return Affine(state.x + 0.5 * h * state.v, 0.25 * h, 0.5, np.zeros((ctx.n_owned, 3)), h)

    def final(self, ctx, state, h, aff, dv):
        n = ctx.n_owned
        v1 = state.v[:n] + dv[:n]
        return state.x[:n] + 0.5 * h * (state.v[:n] + v1), v1, 0.5 * h

    def energy_momentum(self):
        return self.cfg.time.energy_momentum_scheme

    def residual_forces(self, ctx, state, h, aff, dv, want_jac=True):
        if not self.energy_momentum():
            return super().residual_forces(ctx, state, h, aff, dv, want_jac)
        x1 = state.x + h * state.v + 0.5 * h * dv
        return ctx.forces(x1, state.v + 0.5 * dv, want_jac=want_jac, start=state.x)


class Newmark(ImplicitScheme):
    """x1 = x0 + h v0 + h^2 ((1/2 - beta) a0 + beta a1), v1 = v0 + h ((1 - gamma) a0 + gamma a1),
    M a1 = f(x1, v1); a0 = M^-1 f(x0, v0) with constrained directions at rest.
    Second order for gamma = 1/2; beta = 1/4 is the average-acceleration rule.

    With beta = 1/4, gamma = 1/2 the positions follow x1 - x0 = h (v0 + v1)/2 and
    M (v1 - v0) = h (f0 + f1)/2: the midpoint rule's kinematics with the
    trapezoidal force average.  With ``time.energy_momentum`` that average is
    replaced by the discrete gradient, which makes the step the energy-momentum
    midpoint (ImplicitMidpoint's); other beta, gamma are not conserving."""

    def energy_momentum(self):
        return self.cfg.time.energy_momentum_scheme

    def final(self, ctx, state, h, aff, dv):
        if self.energy_momentum():
            return ImplicitMidpoint.final(self, ctx, state, h, aff, dv)
        return super().final(ctx, state, h, aff, dv)

    def residual_forces(self, ctx, state, h, aff, dv, want_jac=True):
        if self.energy_momentum():
            return ImplicitMidpoint.residual_forces(self, ctx, state, h, aff, dv, want_jac)
        return super().residual_forces(ctx, state, h, aff, dv, want_jac)

    def linearise_at_predictor(self):
        # the other predictors need f0 (a0)
        return self.energy_momentum() and self.cfg.time.linearise_at != "start"

    def affine(self, ctx, state, h, f0, cons):
        if self.energy_momentum():
            return ImplicitMidpoint.affine(self, ctx, state, h, f0, cons)
        beta, gamma = self.cfg.time.newmark_beta, self.cfg.time.newmark_gamma
        n = ctx.n_owned
        a0 = ctx.local_array(ctx.project(cons, f0[:n] / ctx.mass[:n, None]))
        x_pred = state.x + h * state.v + h * h * (0.5 - beta - beta * (1.0 - gamma) / gamma) * a0
        return Affine(x_pred, h * beta / gamma, 1.0, h * (1.0 - gamma) * a0[:n], h * gamma)

    def held_path(self, state, h, rows):
        # a0 has no constrained component (projected): x_pred there is x0 + h v0
        beta, gamma = self.cfg.time.newmark_beta, self.cfg.time.newmark_gamma
        return state.x[rows] + h * state.v[rows], h * beta / gamma


class BDF2(ImplicitScheme):
    """x1 = 4/3 x0 - 1/3 x_-1 + 2/3 h v1, v1 = 4/3 v0 - 1/3 v_-1 + 2/3 h M^-1 f(x1, v1):
    second order; the first step, and any step after a change of h, is backward Euler."""

    def monotone_energy(self, state, h):
        # its own steps are not (BDF-2's energy may oscillate), its backward Euler steps are
        return state.history is None or state.history.h != h

    def affine(self, ctx, state, h, f0, cons):
        hist = state.history
        if hist is None or hist.h != h:
            return BackwardEuler.affine(self, ctx, state, h, f0, cons)
        n = ctx.n_owned
        x_pred = (4.0 * state.x - hist.x) / 3.0 + (2.0 / 3.0) * h * state.v
        return Affine(x_pred, 2.0 * h / 3.0, 1.0, (state.v[:n] - hist.v[:n]) / 3.0, 2.0 * h / 3.0)

    def history(self, state, h):
        return MultistepHistory(state.x.copy(), state.v.copy(), h)

    def local_error(self, ctx, state, h, x1):
        # Milne's device: BDF-2 leaves +2/9 h^3 x''' + O(h^4), the second-order
        # predictor x_-1 + 2 h v0 (leapfrog) -1/3 h^3 x''', so the step's error
        # is 2/5 of their difference (after a change of h: backward Euler's own)
        hist = state.history
        if hist is None or hist.h != h:
            return BackwardEuler.local_error(self, ctx, state, h, x1)
        n = ctx.n_owned
        return 0.4 * (x1 - hist.x[:n] - 2.0 * h * state.v[:n])

    def held_path(self, state, h, rows):
        hist = state.history
        if hist is None or hist.h != h:
            return super().held_path(state, h, rows)
        return ((4.0 * state.x[rows] - hist.x[rows]) / 3.0 + (2.0 / 3.0) * h * state.v[rows],
                2.0 * h / 3.0)
