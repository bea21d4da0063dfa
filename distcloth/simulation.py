"""The SPMD driver: one Simulation per rank, stepping its own rows.

Set-up (collective, before any output): METIS partition on rank 0 and
broadcast, local layout, the State, the contact model, force terms, the
block pattern (built once), the PETSc system and solver options (unused
options refused), the explicit stability check.  Then each step runs the
stages declared in ``distcloth/stages.py``, in that order, with errors (NaN,
blow-up, solver failure) agreed collectively so every rank stops at the same
step with the same message.
"""
from __future__ import annotations

import contextlib
import math
import os
from dataclasses import replace

import numpy as np

from .collision.contact import MAX_CONTACT_PASSES, ContactModel
from .config.load import command_line_key
from .config.rules import barrier_misfit
from .config.schema import DEFAULT_SOLVER, OPTION_PREFIX, ConfigError
from .energy_guard import ENERGY_GAIN, EnergyGuard, drive_end as grip_drive_end, gravity_scale
from .frame_fields import FrameFields
from .integrate import make_integrator
from .kinematics import HeldVertices
from .io.console import log
from .linalg.assembly import (assemble_blocks, constraint_impulses, gershgorin_bound,
                              solve_constrained)
from .linalg.constraints import Constraints, filter_system
from .linalg.log_events import logged
from .linalg.pattern import BlockPattern
from .linalg.presets import choose as choose_solver
from .linalg.petsc import (current_options, insert_scene_options, remove_options,
                           unused_options, unused_unprefixed_options)
from .linalg.system import LinearSystem, SolverFailure
from .parallel.comm import partition_on_root
from .parallel.ghosts import GhostExchange
from .parallel.partition import build_layout, describe_partition
from .pipeline import Pipeline
from .stages import FORCE_STAGES, STEP_STAGES
from .state import State
from .strain_limiter import StrainLimiter
from .step_context import StepContext

DIAGNOSTICS = ("step_size", "kinetic_energy", "gravitational_energy", "elastic_energy",
               "total_energy", "max_strain", "max_speed", "newton_iterations",
               "newton_residual", "ksp_iterations", "ksp_residual", "rejected_steps", "newton_unconverged",
               "contacts", "max_penetration", "projected_vertices", "contact_work",
               "friction_work", "failsafe_work", "impulse_work", "impulse_hits",
               "impact_zone_vertices", "self_intersections", "traverse_wall",
               "traverse_busy_max", "traverse_busy_mean", "traverse_idle_mean", "traverse_tests",
               "tasks_created", "tasks_stolen", "steals_refused", "steal_messages",
               "steal_latency_max", "limited_springs", "limiter_passes", "limited_strain")
MAX_SPEED = 1.0e3   # m/s: beyond this a cloth simulation has blown up
STEP_GAIN = "energy gained in one step"
# a passive step of backward Euler (BDF-2's first) may gain this much of S (round-off,
# Newton and solver tolerance) before it is solved again with Newton: their
# converged steps lose energy; a linearised step from rest on the 1000 N/m
# hanging square gains 0.02 S at 20 ms, 0.8 S at 33 ms (docs/integrators.md)
STEP_GAIN_TOLERANCE = 1.0e-3


def reaction_names(group: int) -> tuple[str, str, str]:
    """Diagnostic names of pin group ``group``'s reaction (the result file's
    attribute ``grips`` names the groups in this order)."""
    return tuple(f"reaction_{group}_{c}" for c in "xyz")


class SimulationError(Exception):
    """A run stopped on a numerical failure at a given step."""

    def __init__(self, step: int, message: str):
        self.step = step
        super().__init__(f"step {step}: {message}")


class Simulation:
    def __init__(self, cfg, model, comm, *, force_explicit: bool = False,
                 cmdline_options: set[str] | None = None, quiet: bool = False):
        self.cfg, self.model, self.comm = cfg, model, comm
        self.quiet = quiet
        # checked on the global model, identically on every rank, before any collective
        if np.any(model.vertex_mass <= 0):
            raise ConfigError("cloth", "mesh", "every vertex needs mass: a vertex belongs to no triangle")
        n_vertices = model.rest_positions.shape[0]
        if comm.size > n_vertices:
            raise ConfigError("mpiexec -n", comm.size, f"at most {n_vertices} ranks: the cloth "
                              f"has {n_vertices} vertices and every rank owns some")
        xadj, adjncy = model.matrix_graph()
        part = partition_on_root(comm, xadj, adjncy)
        self.layout = lay = build_layout(xadj, adjncy, model.spring_vertices, part, comm.rank,
                                         comm.size)
        self.say(describe_partition(lay))
        self.n_owned, self.n_local = lay.n_owned, lay.n_local
        local = lay.local_input
        self.mass = model.vertex_mass[local].copy()
        self.state = State(x=model.start_positions()[local].astype(np.float64).copy(),
                           v=model.start_velocities()[local].astype(np.float64).copy())
        self._hold(model, lay)
        self.held = HeldVertices(model, lay, self.pinned_local, self.slide_local, self.slide_S,
                                 self.mass)
        wanted = cfg.output.reactions
        self.record_reactions = bool(model.grips) and (
            wanted if wanted is not None
            else model.moving_grips or (cfg.has("loads") and model.loads is not None
                                        and model.loads.vertices.size > 0))
        self.warnings: list[tuple[int, float, str, str]] = []   # (step, t, kind, message) to record
        self.energy_warnings = 0          # accepted steps above the guard's bound (guard off)
        self._energy_excess = None
        self.ghosts = GhostExchange(lay, comm)
        self._fields = FrameFields(model, lay, comm.rank, self.ghosts)
        self.integrator = make_integrator(cfg)
        self.contact = ContactModel(cfg, model, lay, comm, self.ghosts, self.mass,
                                    np.concatenate([self.pinned_local, self.slide_local]),
                                    self.integrator.implicit)
        self.terms = self._build_terms(cfg, model, lay)
        self.limiter = None
        if cfg.has("strain_limiting"):
            self.limiter = StrainLimiter(cfg.strain_limiting, cfg, model, lay, self.mass,
                                         np.concatenate([self.pinned_local, self.slide_local]),
                                         self.ghosts, comm)
        self.limiter_unconverged_steps = 0
        self.energy_retries = 0           # steps solved again with Newton after a gain
        self._retry_stopped = False       # the retry's Newton stopped early in this attempt
        self._last_energy = None          # total energy of the committed state
        self.pattern = BlockPattern(self.n_owned, self.n_local,
                                    [s for t in self.terms for s in t.stencils()])
        for t in self.terms:
            t.bind(self.pattern)
        self.system = None
        collides = cfg.has("collisions") or cfg.has("self_collision")
        if self.integrator.implicit:
            ls = cfg.linear_system
            # the scene's solver: or, without one, the preset for its size
            self.solver_choice = choose_solver(
                cfg.solver_options, ls.mat_type, ls.warm_start, n_vertices, comm.size,
                contact=collides,
                aimed=ls.step_error_fraction is not None,
                newton=self.integrator.newton_iterations() > 1,
                # contact as a barrier only: no contact rows filtered out of the solves
                barrier=self.contact.barrier is not None and not cfg.has("self_collision"))
            self.system = LinearSystem(lay, self.pattern, comm, self.solver_choice.mat_type,
                                       self.solver_choice.warm_start, ls.pc_rebuild_every)
        self.pipeline = self._build_pipeline()
        self.ctx = StepContext(self.n_owned, self.mass, self.terms, self.pipeline, self.ghosts, comm,
                               barrier=self.contact.barrier,
                               contact_constraints=cfg.has("self_collision") or (
                                   cfg.has("collisions") and self.contact.barrier is None))
        tc = cfg.time
        # stitch springs shortening do work on the garment: a sewing scene is
        # driven until its seams are welded (the welded simulation is passive)
        drive_end = max(self.contact.drive_end, grip_drive_end(cfg, model))
        if model.stitch_pairs is not None:
            drive_end = max(drive_end, cfg.garment.sewing.max_duration)
        # off, the guard still measures: a gain past its bound is a warning of the run
        self.energy_guard = EnergyGuard(tc.max_energy_gain, drive_end, gravity_scale(cfg, model),
                                        enforce=tc.energy_guard)
        self.h = cfg.time.step
        self._cmdline = cmdline_options or set()
        self._inserted_options: list[str] = []
        self._inject = _nan_injection(comm.rank)
        self.force_explicit = force_explicit

    # ---------------------------------------------------------------- set-up
    def say(self, msg):
        if not self.quiet:
            log(self.comm, msg)

    def _hold(self, model, lay) -> None:
        """This rank's pinned vertices (S = 0) and sliding pins (held along an
        axis only, S = I - a a^T), in local numbering."""
        to_local = lay.input_to_local()
        pl = to_local[model.pinned]
        self.pinned_local = np.sort(pl[pl >= 0])
        self.slide_local = np.zeros(0, dtype=np.int64)
        self.slide_S = np.zeros((0, 3, 3))
        if model.slide_vertices is not None and model.slide_vertices.size:
            sl = to_local[model.slide_vertices]
            mine = sl >= 0
            a = model.slide_axes[mine]
            self.slide_local = sl[mine]
            self.slide_S = np.eye(3)[None] - np.einsum("ni,nj->nij", a, a)

    def _build_terms(self, cfg, model, lay) -> list:
        """The force terms of the scene's effects, in stage order; body-contact
        friction in the solve comes from the contact model."""
        terms = []
        for stage in STEP_STAGES:
            if stage.build is not None and (stage.effect is None or cfg.has(stage.effect)):
                term = stage.build(cfg, model, lay)
                if term is not None:
                    terms.append(term)
        if self.contact.friction_term is not None:
            terms.append(self.contact.friction_term)
        if self.contact.barrier is not None:
            terms.append(self.contact.barrier)
        return terms

    def _build_pipeline(self) -> Pipeline:
        implicit = self.integrator.implicit
        bindings = {"kinematics": (self._kinematics, True),
                    "constraints": (self.constraints, True),
                    "assembly": (self._assemble, implicit),
                    "solve": (self._solve, implicit),
                    "update": (self._update, True),
                    "diagnostics": (self._diagnostics, True),
                    "output": (self._output, True)}
        by_name = {t.name: t for t in self.terms}
        for name in FORCE_STAGES:
            term = by_name.get(name)
            bindings[name] = (term.stage if term else None, term is not None)
        if self.contact.has_bodies:   # only scenes that name colliders have the stages
            bindings["collision:bodies"] = (self.contact.detect, True)
        if self.limiter is not None:
            bindings["strain_limiting"] = (self.limiter.apply, True)
        if self.contact.has_response:
            bindings["collision:response"] = (self.contact.respond, True)
        return Pipeline.bind(bindings)

    def prepare(self) -> None:
        """Collective checks before the first step: solver options, explicit
        stability; the energy guard's reference if the scene starts passive."""
        state = self.state
        self._last_energy = sum(self.energies())
        if self.energy_guard.wants_reference(state.t, state.energy_reference):
            state.energy_reference = self.energy_guard.reference(*self.energies())
        if self.system is None:
            self.check_explicit_step()
            _refuse_unprefixed_options()
            return
        chosen = self.solver_choice.options
        self._inserted_options = insert_scene_options(chosen, self._cmdline)
        options = current_options()
        if options.get("pc_type") == "gamg" and self.solver_choice.mat_type == "baij":
            # the scene's own gamg is refused with the config (rules.py): this one is the command line's
            raise ConfigError(command_line_key("pc_type"), "gamg", "gamg with an aij matrix: "
                              f"add -{OPTION_PREFIX}mat_type aij "
                              "(PETSc's GAMG cannot build its graph from the default BAIJ matrix)")
        self.ctx.forces(state.x, state.v, want_jac=True)
        data = self.ctx.assemble(alpha=self.h ** 2, beta=self.h)
        self.system.set_values(filter_system(self.pattern, data, np.zeros((self.n_owned, 3)),
                                             self.constraints())[0])
        try:
            self.system.configure()
        except Exception as exc:   # PETSc error: a bad option value
            raise _solver_setup_error(exc, current_options(), self._cmdline) from None
        defaults = DEFAULT_SOLVER if self.cfg.solver_options else chosen
        for name in unused_options():
            if defaults.get(name, object()) == chosen.get(name):
                continue   # a default the scene did not ask for (sub_pc_type with pc_type jacobi)
            where = command_line_key(name) if name in self._cmdline else f"solver.{name}"
            value = chosen.get(name, "")
            raise ConfigError(where, value, "not an option of the configured solver "
                              "(PETSc did not use it: misspelt, or for another solver type)"
                              + _EQUALS_HINT * ("=" in name))
        _refuse_unprefixed_options()
        self.say(f"solver: {self.system.describe()} ({self.solver_choice.describe()})")

    def stiffness_bound(self) -> float:
        """Gershgorin bound of lambda_max(M^-1 K) at the rest state over all
        ranks, from the assembled stiffness of every enabled term (springs,
        FE membrane, hinges alike)."""
        rest = self.model.rest_positions[self.layout.local_input]
        self.ctx.forces(rest, np.zeros_like(rest), want_jac=True)
        stiffness = self._assemble(1.0, 0.0, 0.0)            # -df/dx, no mass
        local = gershgorin_bound(self.pattern, stiffness, self.mass[: self.n_owned])
        return float(self.comm.max(np.array([local]))[0])

    def explicit_step_limits(self) -> tuple[float, float]:
        """(0.9 * c / sqrt(lambda_max(M^-1 K)) with c the integrator's stability
        factor (2 for symplectic Euler), Vassilev et al. 2001 Eq. 4's
        0.4 pi sqrt(m / K))."""
        lam = self.stiffness_bound()
        kmax = self.comm.max(np.array([max((float(t.k.max()) for t in self.terms
                                            if hasattr(t, "k") and t.k.size), default=0.0)]))[0]
        mmin = self.ctx.min_mass()
        factor = self.integrator.stability_factor
        limit = 0.9 * factor / math.sqrt(lam) if lam > 0 else math.inf
        paper = 0.4 * math.pi * math.sqrt(mmin / kmax) if kmax > 0 else math.inf
        return limit, paper

    def check_explicit_step(self) -> None:
        """Refuse h >= 0.9 * c / sqrt(lambda_max(M^-1 K)) unless forced: Vassilev
        et al.'s bound is 1.3-2 times too generous for a grid with shear and
        flexion springs (docs/stability.md)."""
        limit, paper = self.explicit_step_limits()
        message = (f"explicit step limit: h < {limit:.4g} s (0.9*{self.integrator.stability_factor:.3g}"
                   f"/sqrt(lambda_max), Gershgorin); "
                   + (f"Vassilev et al. 2001 Eq. 4 gives {paper:.4g} s" if math.isfinite(paper)
                      else "Vassilev et al. 2001 Eq. 4 does not apply (no springs)")
                   + f"; h = {self.h:g} s")
        if self.h >= limit and self.force_explicit:
            log(self.comm, message + ": above the limit, running anyway because of --force")
        else:
            self.say(message)
        if self.h >= limit and not self.force_explicit:
            raise ConfigError("time.step", self.h,
                              f"{self.cfg.time.integrator} is unstable above {limit:.4g} s for this "
                              f"cloth (0.9*{self.integrator.stability_factor:.3g}/sqrt(lambda_max(M^-1 K))); "
                              f"use a smaller step, an implicit "
                              f"integrator, or --force")

    # ---------------------------------------------------------------- stages
    def _kinematics(self, t_end=None, h=None):
        """Target velocities of the held vertices (pins, then sliding pins): zero
        for pins at rest, for a moving grip the one that ends the step on its
        path (kinematics.py); and time-dependent terms (stitch rest lengths,
        load ramps) at the end of the step."""
        if t_end is None:
            return np.zeros((self.held.rows.size, 3))
        for term in self.terms:
            if hasattr(term, "at_time"):
                term.at_time(t_end)
        return self.held.targets(self.state, h, t_end, self.integrator)

    def constraints(self, target_velocity=None, contacts=None, static=None) -> Constraints:
        """Pins (S = 0), sliding pins (S = I - a a^T) and contacts (S = I - n n^T,
        never on held vertices): z takes the constrained directions of the
        velocity change to the target.  ``static``: (index, S, z) of a static
        relaxation's contacts (the drape's Newton step, z: their displacement)."""
        v = self.state.v
        idx = np.concatenate([self.pinned_local, self.slide_local])
        S = np.concatenate([np.zeros((self.pinned_local.size, 3, 3)), self.slide_S])
        if target_velocity is None:
            target_velocity = np.zeros((idx.size, 3))
        z = np.einsum("nij,nj->ni", np.eye(3)[None] - S, target_velocity - v[idx])
        if contacts is not None and contacts.index.size:
            cidx, cS, cz = self.contact.constraints(contacts, v)
            idx = np.concatenate([idx, cidx])
            S = np.concatenate([S, cS])
            z = np.concatenate([z, cz])
        if static is not None and static[0].size:
            idx = np.concatenate([idx, static[0]])
            S = np.concatenate([S, static[1]])
            z = np.concatenate([z, static[2]])
        order = np.argsort(idx, kind="stable")
        return Constraints(idx[order], S[order], z[order])

    def _assemble(self, alpha, beta, gamma):
        return assemble_blocks(self.pattern, self.mass[: self.n_owned], self.terms, alpha, beta,
                               gamma)

    def _solve(self, data, rhs, cons, guess=None, rtol=None, keep_preconditioner=False,
               correction=False, target=None):
        if keep_preconditioner:
            self.system.keep_preconditioner()
        with self._tolerance(rtol), self.system.aimed(target), \
                (self.system.correcting() if correction else contextlib.nullcontext()):
            y, info = solve_constrained(self.system, self.pattern, data, rhs, cons, guess)
        if self.contact.has_bodies:   # the same on every rank: the exchange is collective
            dv = np.zeros((self.n_local, 3))
            dv[: self.n_owned] = y
            self.ghosts.update(dv)
            info.reaction = constraint_impulses(self.pattern, data, rhs, dv)
        return y, info

    def _tolerance(self, rtol):
        """The linear solves' relative tolerance loosened to ``rtol`` (None: the scene's)."""
        return contextlib.nullcontext() if self.system is None else self.system.loosened(rtol)

    def _update(self, result):
        n = self.n_owned
        state = self.state
        state.x[:n] = result.x
        state.v[:n] = result.v
        if self._inject is not None and state.step == self._inject:
            state.x[0] = np.nan
        self.ghosts.update(state.x, state.v)

    def _local_potentials(self, x) -> tuple[float, float]:
        """(gravitational, elastic) energy of this rank's share at x: every term
        with a potential (springs, FE membrane, hinges, shells); damping, drag
        and friction have none.  The loads' potential -F . x, like gravity's a
        constant force's, is counted as gravitational."""
        grav = elastic = 0.0
        for t in self.terms:
            if t.name in ("force:gravity", "force:loads"):
                grav += t.energy(x)
            else:
                elastic += t.energy(x)
        return grav, elastic

    def energies(self, x=None, v=None) -> tuple[float, float, float]:
        """(kinetic, gravitational, elastic) energy at x (local rows, ghosts
        valid) and v (owned rows at least), default the current state's,
        summed over ranks."""
        n = self.n_owned
        x = self.state.x if x is None else x
        v = self.state.v if v is None else v
        kinetic = 0.5 * float(np.sum(self.mass[:n] * np.einsum("ij,ij->i", v[:n], v[:n])))
        k, g, e = self.comm.sum(np.array([kinetic, *self._local_potentials(x)]))
        return float(k), float(g), float(e)

    def potential_energies(self, x=None) -> tuple[float, float]:
        """(gravitational, elastic) potential energy at x (local rows, ghosts
        valid; default the state's), summed over ranks."""
        g, e = self.comm.sum(np.array(self._local_potentials(self.state.x if x is None else x)))
        return float(g), float(e)

    def largest_stitch_gap(self) -> float:
        """The widest stitched pair over all ranks (0 without stitches)."""
        local = max((t.largest_gap(self.state.x) for t in self.terms
                     if hasattr(t, "largest_gap")), default=0.0)
        return float(self.comm.max(np.array([local]))[0])

    def stitch_gaps(self) -> np.ndarray:
        """(k,) distance of every stitched pair of the model, in model order, on
        every rank (a collective reduction of the owned first ends)."""
        model = self.model
        if model.stitch_pairs is None:
            return np.zeros(0)
        to_local = self.layout.input_to_local()
        a, b = to_local[model.stitch_pairs[:, 0]], to_local[model.stitch_pairs[:, 1]]
        mine = (a >= 0) & (a < self.n_owned) & (b >= 0)
        gaps = np.zeros(model.stitch_pairs.shape[0])
        x = self.state.x
        gaps[mine] = np.linalg.norm(x[a[mine]] - x[b[mine]], axis=1)
        return self.comm.max(gaps)

    def max_strain(self) -> float:
        """Largest engineering membrane strain of this rank's rows: structural
        springs, or the FE triangles' principal stretch - 1."""
        return max((t.max_strain(self.state.x) for t in self.terms), default=0.0)

    def _diagnostics(self, result, h_min) -> dict:
        n = self.n_owned
        v = self.state.v
        # the health check already summed the committed state's energies
        kinetic, grav, elastic = result.energies
        speed = float(np.sqrt(np.max(np.einsum("ij,ij->i", v[:n], v[:n]), initial=0.0)))
        maxes = self.comm.max(np.array([self.max_strain(), speed]))
        return {
            "step_size": h_min,
            "kinetic_energy": kinetic, "gravitational_energy": grav, "elastic_energy": elastic,
            "total_energy": kinetic + grav + elastic,
            "max_strain": maxes[0], "max_speed": maxes[1],
            "newton_iterations": result.newton_iterations, "newton_residual": result.newton_residual,
            "ksp_iterations": result.ksp_iterations, "ksp_residual": result.ksp_residual,
            "rejected_steps": self.state.rejections,
            "newton_unconverged": self.state.newton_unconverged,
            **self.contact.diagnostics(result.contact_report),
            **(self.limiter.diagnostics(result.limit_report) if self.limiter else {}),
            **self._reactions(),
        }

    def diagnostic_names(self) -> list[str]:
        """The names of the diagnostics a step reports: DIAGNOSTICS, then each
        pin group's reaction components when the run records them."""
        groups = range(len(self.held.grips)) if self.record_reactions else range(0)
        return list(DIAGNOSTICS) + [name for g in groups for name in reaction_names(g)]

    def _reactions(self) -> dict:
        """Each pin group's reaction (N) at the committed state (collective):
        one evaluation of every force term there, outside the stage counters
        (they count the integrator's evaluations)."""
        if not self.record_reactions:
            return {}
        x, v = self.state.x, self.state.v
        f = np.zeros((self.n_local, 3))
        for t in self.terms:
            if t.name != "force:friction":     # acts on contacts, never on held vertices
                t.evaluate(x, v, f, False)
        total = self.comm.sum(self.held.reactions(f, self.state.acceleration).ravel())
        total = total.reshape(-1, 3)
        return {name: float(total[g, c]) for g in range(total.shape[0])
                for c, name in enumerate(reaction_names(g))}

    def _output(self, writer):
        writer.write_frame(self.state.step, self.state.t, self.owned_positions(),
                           fields=self.frame_fields())

    def frame_fields(self) -> dict:
        """Collective: this rank's rows of the fields a frame records (frame_fields.py)."""
        return self._fields.values(self.state)

    # ------------------------------------------------------------------ run
    def owned_positions(self) -> np.ndarray:
        return self.state.x[: self.n_owned]

    def step(self) -> dict:
        """Advance one step of the scene's h; returns the diagnostics.  Raises
        SimulationError on every rank together.

        A rejected attempt (failed solve; NaN, blow-up or strain bound after
        the tentative update; the energy guard) is undone and, with
        ``time.adaptive``, retried as two steps of h/2, recursively up to
        ``time.max_halvings`` times; otherwise the run stops naming the cause."""
        state = self.state
        state.step += 1
        # the step ends on the time grid, with no drift from summed substeps
        result, h_min = self._advance(self.h, state.step * self.h, 0)
        return self.pipeline.run("diagnostics", result, h_min)

    def _advance(self, h, t_end, depth):
        """Attempts from the state's time to ``t_end`` (= t + h up to round-off)."""
        result, reason, fatal = self._attempt(h, t_end)
        tc = self.cfg.time
        retry = tc.energy_retry_newton
        if (reason is not None and reason.startswith((ENERGY_GAIN, STEP_GAIN))
                and self.integrator.implicit and retry > self.integrator.newton_iterations()):
            # a linearised step that gained energy: Newton iterated on the same
            # step before any halving (docs/integrators.md, "Large steps")
            self.integrator.newton_override = retry
            # ... as a one-step scheme: a multistep history from before a
            # contact's velocity jump carries the energy it removed back in
            history, self.state.history = self.state.history, None
            # (not where an unconverged step is rejected anyway)
            early = tc.energy_retry_until == "no_gain" and not tc.require_newton_convergence
            try:
                self.integrator.retry_stop = self._gains_none if early else None
                self._retry_stopped = False
                result, reason, fatal = self._attempt(h, t_end)
                if (self._retry_stopped and reason is not None and not fatal
                        and reason.startswith((ENERGY_GAIN, STEP_GAIN))):
                    # the checks after the solve (contact response, strain
                    # limiting) can add what the iterate did not have: Newton
                    # to its limit, as without the early stop (a retry that
                    # never stopped early already went there)
                    self.integrator.retry_stop = None
                    result, reason, fatal = self._attempt(h, t_end)
            finally:
                self.integrator.newton_override = None
                self.integrator.retry_stop = None
                if reason is not None:
                    self.state.history = history
            if reason is None:
                self.energy_retries = self._counted(
                    self.energy_retries, f"step {self.state.step}: the linearised step gained "
                    f"energy; solved again with at most {retry} Newton iterations "
                    f"(time.energy_retry_newton; later retries are counted)")
        if reason is None:
            return result, h
        if fatal or not tc.adaptive or depth >= tc.max_halvings:
            if tc.adaptive and not fatal:
                reason += f" (after {depth} halvings, h = {h:.3g} s)"
            if reason.startswith(ENERGY_GAIN) and self._barrier_would_serve():
                reason += ("; contact.model: barrier takes large steps onto a body "
                           "(docs/integrators.md, \"Large steps onto a body\")")
            raise SimulationError(self.state.step, reason)
        self.say(f"step {self.state.step}: rejected at h = {h:.3g} s ({reason}); "
                 f"retrying as two steps of {h / 2:.3g} s")
        self.state.rejections += 1
        self._advance(h / 2, self.state.t + h / 2, depth + 1)
        result, h2 = self._advance(h / 2, t_end, depth + 1)
        return result, min(h2, h / 2)

    def _barrier_would_serve(self) -> bool:
        """Does the scene hold bodies as contact constraints, where the barrier
        could serve it?  Constraints chosen from a free-flight prediction gain
        energy in large steps onto a body; a barrier in the Newton solve does not."""
        cfg = self.cfg
        if not self.contact.has_bodies or cfg.contact.model != "constraints":
            return False
        as_barrier = replace(cfg, contact=replace(cfg.contact, model="barrier"))
        return barrier_misfit(as_barrier) is None

    def _attempt(self, h, t_end):
        """One tentative step of size h: (result, None, False) if accepted and
        committed (the state's time becomes ``t_end``), else (None, reason,
        fatal) with the state unchanged.  The force terms are told the step's
        start state first (StepContext.begin_step)."""
        self.ctx.begin_step(self.state.x)
        return self._try_step(h, t_end)

    def _try_step(self, h, t_end):
        state, pipe, contact = self.state, self.pipeline, self.contact
        target = pipe.run("kinematics", t_end, h)
        revision, contacts, result = None, None, None
        # while the contact set changes, a pass only has to show which contacts
        # hold: it solves to contact.pass_rtol; once a loose solve leaves the set
        # unchanged, the same contacts are solved again to the scene's tolerance
        # (from the loose answer) and that solve is revised like any other.
        # Only after a step whose contact set changed: where one solve settles
        # the set, a loose one first would only add a solve
        loose = contact.pass_rtol if contact.has_bodies and self.system is not None else None
        if loose is not None and (self.system.rtol >= loose or state.contact_changes == 0):
            loose = None
        changes, iterations = 0, 0
        # a barrier has no contact set to revise: one Newton solve
        revised_contacts = contact.has_bodies and contact.barrier is None
        if not revised_contacts:
            loose = None
        passes = (MAX_CONTACT_PASSES + (loose is not None)) if revised_contacts else 1
        detect = True
        for k in range(passes):
            if contact.has_bodies and detect:
                contacts = pipe.run("collision:bodies", state, h, revision)
                contact.begin_attempt(contacts, h)
            cons = pipe.run("constraints", target, contacts)
            rtol = loose if k < passes - 1 else None
            error, solver_failure = None, False
            try:
                # a re-solve starts from the last solve's velocity change
                guess = None if result is None else result.v - state.v[: self.n_owned]
                with self._tolerance(rtol):
                    result = self.integrator.step(self.ctx, state, h, cons, guess)
                iterations += result.ksp_iterations
            except SolverFailure as exc:      # the same on every rank
                error, solver_failure = f"SolverFailure: {exc}", True
            except Exception as exc:          # a local bug is not: agree on it
                error = f"{type(exc).__name__}: {exc}"
            agreed = self.comm.agree(error)
            if agreed is not None:
                where = f" (rank {agreed[0]})" if self.comm.size > 1 and not solver_failure else ""
                return None, agreed[1] + where, not solver_failure
            if not revised_contacts:
                break
            # an adhesive contact, or a vertex the prediction missed that ends the
            # step inside a body: solve the step again with the revised contacts
            revised = contact.revise(contacts, result, state.t + h, h, revision)
            if revised is None and rtol is None:
                break
            if revised is None:
                loose, detect = None, False
            else:
                revision, detect, changes = revised, True, changes + 1
            if self.system is not None:      # the re-solve's matrix is nearly the same
                self.system.keep_preconditioner()
        result.ksp_iterations = iterations        # every pass's
        self.held.hold(result.v, t_end)
        result.contact_report, result.touching, result.limit_report = None, None, None
        if self.limiter is not None:
            result.limit_report = pipe.run("strain_limiting", state, result, contacts, h)
        if contact.has_response:
            error = None
            try:
                response = pipe.run("collision:response", state, contacts, result, h)
                result.x, result.v = response.x, response.v
                result.contact_report, result.touching = response.report, response.touching
            except Exception as exc:
                error = f"{type(exc).__name__} in the collision response: {exc}"
            agreed = self.comm.agree(error)
            if agreed is not None:
                return None, agreed[1] + (f" (rank {agreed[0]})" if self.comm.size > 1 else ""), True
        if not result.newton_converged and self.cfg.time.require_newton_convergence:
            return None, (f"Newton did not converge in {result.newton_iterations} iterations "
                          f"(relative residual {result.newton_residual:.3g} > "
                          f"time.newton_tolerance = {self.cfg.time.newton_tolerance:g})"), False
        saved = state.snapshot()
        pipe.run("update", result)
        with logged("health"):
            reason, result.energies = self._check_state()
        if reason is None and self._gains_in_step(result.energies, h):
            reason = STEP_GAIN    # only ever retried with Newton, never a rejection
        if reason:
            state.restore(saved)
            return None, reason, False
        state.contact_changes = changes
        self._commit(result, contacts, t_end, (state.v - saved.v) / h)
        return result, None, False

    def _commit(self, result, contacts, t_end, acceleration) -> None:
        """The attempt's state becomes the state: time, multistep history,
        contacts, the step's acceleration."""
        state = self.state
        state.t = t_end
        state.history = result.history
        state.step_error = result.local_error
        state.contacts = contacts
        state.touching = result.touching
        state.acceleration = acceleration
        if not result.newton_converged:
            how = (f"stopped after {result.newton_iterations} iterations once the step "
                   f"gained no energy (time.energy_retry_until)" if result.stopped_early else
                   f"used all {result.newton_iterations} iterations")
            state.newton_unconverged = self._counted(
                state.newton_unconverged,
                f"step {state.step}: Newton {how} (residual {result.newton_residual:.3g} > "
                f"{self.cfg.time.newton_tolerance:g}); accepted, counted in "
                f"newton_unconverged (time.require_newton_convergence rejects)")
        if self.energy_guard.wants_reference(state.t, state.energy_reference):
            state.energy_reference = self.energy_guard.reference(*result.energies)
        self._last_energy = sum(result.energies)
        if self._energy_excess is not None:
            if self.energy_warnings == 0:
                message = (f"step {state.step} (t = {state.t:.6g} s): {self._energy_excess}; "
                           f"accepted because time.energy_guard is false")
                self.say("warning: " + message)
                self.warnings.append((state.step, state.t, "energy_gain", message))
            self.energy_warnings += 1
            self._energy_excess = None
        report = result.limit_report
        if report is not None and not report.converged:
            self.limiter_unconverged_steps = self._counted(
                self.limiter_unconverged_steps,
                f"step {state.step}: warning: strain limiting left a spring at strain "
                f"{report.strain:.4g}, {report.excess:.3g} above its bound, after "
                f"{report.passes} passes (strain_limiting.passes); later steps like "
                f"this are counted and reported at the end")

    def _counted(self, count: int, message: str) -> int:
        """One more step of a kind the log names only the first time."""
        if count == 0:
            self.say(message)
        return count + 1

    def _check_state(self):
        """Health check of the tentative state (two reductions): NaN, speed
        limit, strain bound, energy guard.  Returns (reason or None, the
        state's energies or None)."""
        n = self.n_owned
        x, v = self.state.x, self.state.v
        finite = bool(np.all(np.isfinite(x[:n])) and np.all(np.isfinite(v[:n])))
        speed = float(np.sqrt(np.max(np.einsum("ij,ij->i", v[:n], v[:n]), initial=0.0))) \
            if finite else 0.0
        strain = self.max_strain() if finite and self.cfg.time.max_strain is not None else 0.0
        bad, speed, strain = self.comm.max(np.array([0.0 if finite else 1.0, speed, strain]))
        if bad:
            return "NaN or Inf in positions or velocities", None
        if speed > MAX_SPEED:
            return f"blow-up: a vertex moves at {speed:.3g} m/s (limit {MAX_SPEED:g} m/s)", None
        if self.cfg.time.max_strain is not None and strain > self.cfg.time.max_strain:
            return f"strain {strain:.3g} exceeds time.max_strain = {self.cfg.time.max_strain:g}", None
        energies = self.energies()
        reason = self.energy_guard.check(self.state.energy_reference, *energies)
        self._energy_excess = None
        if reason is not None and not self.energy_guard.enforce:
            self._energy_excess, reason = reason, None     # accepted: a warning at commit
        return reason, energies

    def _gains_none(self, x1, v1) -> bool:
        """Collective: would the owned rows (x1, v1) of a retried step's Newton
        iterate pass the energy guard and end no higher than the last
        committed energy (within STEP_GAIN_TOLERANCE * S)?  False where the
        scene has no energy reference (not passive): the retry then iterates
        to its limit."""
        ref, last = self.state.energy_reference, self._last_energy
        if ref is None or last is None:
            return False
        energies = self.energies(self.ctx.local_array(x1), v1)
        if self.energy_guard.check(ref, *energies) is not None:
            return False
        if _gains(energies, last, ref):
            return False
        self._retry_stopped = True      # a rejection after it deserves the full retry
        return True

    def _gains_in_step(self, energies, h) -> bool:
        """A step of a dissipative scheme (backward Euler, BDF-2's first) on a passive
        scene that ends with more than STEP_GAIN_TOLERANCE * S above its start:
        the linearisation, not the scheme, made the energy (retried once with
        Newton when time.energy_retry_newton allows it)."""
        ref, last = self.state.energy_reference, self._last_energy
        if (ref is None or last is None or not self.integrator.monotone_energy(self.state, h)
                or self.integrator.newton_override is not None
                or self.cfg.time.energy_retry_newton <= self.integrator.newton_iterations()):
            return False
        return _gains(energies, last, ref)

    def destroy(self):
        if self.system is not None:
            remove_options(self._inserted_options)
            self.system.destroy()


_EQUALS_HINT = "; an option and its value are two words: -name value, not -name=value"


def _gains(energies, last: float, reference) -> bool:
    """Do the state's ``energies`` end more than STEP_GAIN_TOLERANCE * S above
    the last committed total ``last`` (S: the energy reference's scale)?"""
    return sum(energies) - last > STEP_GAIN_TOLERANCE * reference[1]


def _refuse_unprefixed_options() -> None:
    """An option without the prefix that PETSc did not read was meant for
    distcloth's solver (-ksp_monitor for -distcloth_ksp_monitor) or misspelt:
    refused like an unused prefixed one rather than ignored."""
    unused = unused_unprefixed_options()
    if unused:
        name = unused[0]
        raise ConfigError(f"command line -{name}", current_options(prefixed=False).get(name) or "",
                          "not an option PETSc used: distcloth's solver options take the prefix "
                          f"{OPTION_PREFIX} (-{OPTION_PREFIX}{name.split('=')[0]})"
                          + _EQUALS_HINT * ("=" in name))


def _solver_setup_error(exc, options: dict, cmdline: set) -> ConfigError:
    """One line naming the option PETSc refused (the one whose value its message quotes)."""
    parts = [p.strip() for p in str(exc).split("[0]") if p.strip()]
    reason = parts[-1] if parts else str(exc)
    for name, value in options.items():
        if str(value) and str(value) in reason:
            where = command_line_key(name) if name in cmdline else f"solver.{name}"
            return ConfigError(where, value, f"PETSc refused it: {reason}")
    for name in sorted(cmdline):        # a command-line option given without its value
        if options.get(name) in (None, ""):
            return ConfigError(command_line_key(name), "", f"a value: PETSc refused the solver "
                               f"set-up without one ({reason})")
    return ConfigError("solver", "", f"PETSc refused the solver set-up: {reason}")


def _nan_injection(rank: int):
    """Test hook: DISTCLOTH_INJECT_NAN=RANK:STEP poisons one position on that rank after that step."""
    spec = os.environ.get("DISTCLOTH_INJECT_NAN")
    if not spec:
        return None
    r, s = spec.split(":")
    return int(s) if int(r) == rank else None
