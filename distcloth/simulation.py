"""The SPMD driver: one Simulation per rank, stepping its own rows.

Set-up (collective, before any output): METIS partition on rank 0 and
broadcast, local layout, force terms, the block pattern (built once), the
PETSc system and solver options (unused options refused), the explicit
stability check.  Then each step runs the pipeline

    kinematics -> constraints -> force:* -> assembly -> solve -> update
    -> diagnostics -> output

with errors (NaN, blow-up, solver failure) agreed collectively so every
rank stops at the same step with the same message.
"""
from __future__ import annotations

import math
import os
import sys
import time

import numpy as np

from .config.schema import DEFAULT_SOLVER, ConfigError
from .integrate import make_integrator
from .linalg.constraints import Constraints, filter_system
from .linalg.system import SolverFailure
from .linalg.pattern import BlockPattern
from .physics.terms import FORCE_STAGES, build_terms
from .collision_stages import MAX_CONTACT_PASSES
from .energy_guard import EnergyGuard, gravity_scale
from .pipeline import Pipeline

STAGES = ("kinematics", "collision:bodies", "constraints") + FORCE_STAGES + ("assembly", "solve", "update",
                                                        "diagnostics", "output",
                                                        "collision:response")
DIAGNOSTICS = ("step_size", "kinetic_energy", "gravitational_energy", "elastic_energy",
               "total_energy", "max_strain", "max_speed", "newton_iterations",
               "newton_residual", "ksp_iterations", "ksp_residual", "rejected_steps", "newton_unconverged",
               "contacts", "max_penetration", "projected_vertices", "impulse_hits",
               "impact_zone_vertices", "self_intersections", "traverse_wall",
               "traverse_busy_max", "traverse_busy_mean", "traverse_idle_mean", "traverse_tests",
               "tasks_created", "tasks_stolen", "steals_refused", "steal_messages",
               "steal_latency_max")
MAX_SPEED = 1.0e3   # m/s: beyond this a cloth simulation has blown up


class SimulationError(Exception):
    """A run stopped on a numerical failure at a given step."""

    def __init__(self, step: int, message: str):
        self.step = step
        super().__init__(f"step {step}: {message}")


def log(comm, msg: str) -> None:
    if comm.rank == 0:
        print(f"[distcloth] {msg}", file=sys.stderr, flush=True)


class Simulation:
    def __init__(self, cfg, model, comm, *, force_explicit: bool = False,
                 cmdline_options: set[str] | None = None, quiet: bool = False):
        from .linalg.ghosts import GhostExchange
        from .parallel.comm import partition_on_root
        from .parallel.partition import build_layout, describe_partition

        self.cfg, self.model, self.comm = cfg, model, comm
        self.quiet = quiet
        # checked on the global model, identically on every rank, before any collective
        if np.any(model.vertex_mass <= 0):
            raise ConfigError("cloth", "mesh", "every vertex needs mass: a vertex belongs to no triangle")
        xadj, adjncy = model.matrix_graph()
        part = partition_on_root(comm, xadj, adjncy)
        self.layout = build_layout(xadj, adjncy, model.spring_vertices, part, comm.rank, comm.size)
        self.say(describe_partition(self.layout))
        lay = self.layout
        self.n_owned, self.n_local = lay.n_owned, lay.n_local
        local = lay.local_input
        self.mass = model.vertex_mass[local].copy()
        self.x = model.start_positions()[local].astype(np.float64).copy()
        self.v = model.start_velocities()[local].astype(np.float64).copy()
        to_local = np.full(model.num_vertices, -1, dtype=np.int64)
        to_local[local] = np.arange(self.n_local)
        pl = to_local[model.pinned]
        self.pinned_local = np.sort(pl[pl >= 0])
        # sliding pins: held along an axis only, S = I - a a^T
        self.slide_local = np.zeros(0, dtype=np.int64)
        self.slide_S = np.zeros((0, 3, 3))
        if model.slide_vertices is not None and model.slide_vertices.size:
            sl = to_local[model.slide_vertices]
            mine = sl >= 0
            a = model.slide_axes[mine]
            self.slide_local = sl[mine]
            self.slide_S = np.eye(3)[None] - np.einsum("ni,nj->nij", a, a)
        from .collision_stages import CollisionStages
        self._first_forces = None
        self.collisions = CollisionStages(self, cfg, model, local)
        self.terms = build_terms(cfg, model, lay)
        self.integrator = make_integrator(cfg)
        # implicit schemes take body-contact friction into the solve
        # (physics/contact_friction.py); explicit ones keep it after the step
        self.friction_term = None
        if self.integrator.implicit and self.collisions.solve_friction:
            from .physics.contact_friction import ContactFrictionTerm
            self.friction_term = ContactFrictionTerm(self.mass, self.n_owned)
            self.terms.append(self.friction_term)
            self.collisions.friction_in_solve = True
        self.pattern = BlockPattern(self.n_owned, self.n_local,
                                    [s for t in self.terms for s in t.stencils()])
        for t in self.terms:
            t.bind(self.pattern)
        self.ghosts = GhostExchange(lay)
        self.system = None
        if self.integrator.implicit:
            from .linalg.system import LinearSystem
            self.system = LinearSystem(lay, self.pattern, cfg.mat_type, cfg.warm_start,
                                       cfg.pc_rebuild_every)
        self.pipeline = self._build_pipeline()
        # callables(sim, result) -> reason or None, run on the tentative state
        # (ghosts valid); a reason rejects the step. A hook must give the same
        # verdict on every rank (reduce what it checks).
        self.accept_hooks = []
        self.rejections = 0
        self.newton_unconverged = 0
        tc = cfg.time
        self.energy_guard = EnergyGuard(tc.max_energy_gain if tc.energy_guard else None,
                                        self.collisions.drive_end, gravity_scale(cfg, model))
        self._energies_now = None   # (kinetic, gravitational, elastic) of the committed state
        self.time = 0.0
        self.step_index = 0
        self.h = cfg.time.step
        self._cmdline = cmdline_options or set()
        self._inject = _nan_injection(comm.rank)
        self.force_explicit = force_explicit

    # ---------------------------------------------------------------- set-up
    def say(self, msg):
        if not self.quiet:
            log(self.comm, msg)

    def _build_pipeline(self) -> Pipeline:
        p = Pipeline()
        p.add("kinematics", self._kinematics)
        if self.collisions.has_bodies:   # only scenes that name colliders have the stages
            p.add("collision:bodies", self._collision_bodies)
        p.add("constraints", self._constraints)
        by_name = {t.name: t for t in self.terms}
        for name in FORCE_STAGES:
            term = by_name.get(name)
            p.add(name, term.evaluate if term else None, enabled=term is not None)
        p.add("assembly", self._assemble, enabled=self.integrator.implicit)
        p.add("solve", self._solve, enabled=self.integrator.implicit)
        p.add("update", self._update)
        p.add("diagnostics", self._diagnostics)
        p.add("output", self._output)
        if self.collisions.has_response:
            p.add("collision:response", self._collision_response)
        return p

    def prepare(self) -> None:
        """Collective checks before the first step: solver options, explicit
        stability; the energy guard's reference if the scene starts passive."""
        if self.energy_guard.wants_reference(self.time):
            self.energy_guard.set_reference(*self.energies())
        if self.system is not None:
            from .linalg.petsc import insert_scene_options, unused_options
            self._inserted_options = insert_scene_options(self.cfg.solver_options, self._cmdline)
            self.forces(self.x, self.v, want_jac=True)
            data = self.assemble(alpha=self.h ** 2, beta=self.h)
            self.system.set_values(filter_system(self.pattern, data, np.zeros((self.n_owned, 3)),
                                                 self._constraints())[0])
            try:
                self.system.configure()
            except Exception as exc:   # PETSc error: a bad option value
                from .linalg.petsc import current_options
                raise _solver_setup_error(exc, current_options(), self._cmdline) from None
            for name in unused_options():
                if DEFAULT_SOLVER.get(name, object()) == self.cfg.solver_options.get(name):
                    continue   # a default the scene did not ask for (sub_pc_type with pc_type jacobi)
                where = f"command line -distcloth_{name}" if name in self._cmdline else f"solver.{name}"
                value = self.cfg.solver_options.get(name, "")
                raise ConfigError(where, value, "not an option of the configured solver "
                                  "(PETSc did not use it: misspelt, or for another solver type)")
            self.say(f"solver: {self.system.describe()}")
        else:
            self.check_explicit_step()

    def explicit_step_limits(self) -> tuple[float, float]:
        """(0.9 * c / sqrt(lambda_max(M^-1 K)) with lambda_max from Gershgorin and c
        the integrator's stability factor (2 for symplectic Euler),
        seed 002 Eq. 4's 0.4 pi sqrt(m / K)); collective."""
        lam = self.comm.max(np.array([self._gershgorin_local()]))[0]
        kmax = self.comm.max(np.array([max((float(t.k.max()) for t in self.terms
                                            if hasattr(t, "k") and t.k.size), default=0.0)]))[0]
        mmin = -self.comm.max(np.array([-float(self.mass[: self.n_owned].min())]))[0]
        factor = self.integrator.stability_factor
        limit = 0.9 * factor / math.sqrt(lam) if lam > 0 else math.inf
        seed = 0.4 * math.pi * math.sqrt(mmin / kmax) if kmax > 0 else math.inf
        return limit, seed

    def check_explicit_step(self) -> None:
        """Refuse h >= 0.9 * 2 / sqrt(lambda_max(M^-1 K)) (DESIGN.md §9) unless forced."""
        limit, seed = self.explicit_step_limits()
        message = (f"explicit step limit: h < {limit:.4g} s (0.9*{self.integrator.stability_factor:.3g}"
                   f"/sqrt(lambda_max), Gershgorin); "
                   + (f"seed 002 Eq. 4 gives {seed:.4g} s" if math.isfinite(seed)
                      else "seed 002 Eq. 4 does not apply (no springs)") + f"; h = {self.h:g} s")
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

    def _gershgorin_local(self) -> float:
        """Gershgorin bound of M^-1 K at the rest state, from the assembled
        stiffness of every enabled term (springs, FE membrane, hinges alike):
        lambda_max <= max_i sum_j |K_ij| / m_i over this rank's scalar rows."""
        rest = self.model.rest_positions[self.layout.local_input]
        self.forces(rest, np.zeros_like(rest), want_jac=True)
        data = self._assemble(1.0, 0.0, 0.0)            # -df/dx, no mass
        rows = np.abs(data).sum(axis=2)                  # (nnzb, 3) scalar-row sums per block
        rowsum = np.zeros((self.n_owned, 3))
        for a in range(3):
            rowsum[:, a] = np.bincount(self.pattern.block_rows, weights=rows[:, a],
                                       minlength=self.n_owned)
        return float(np.max(rowsum.max(axis=1) / self.mass[: self.n_owned], initial=0.0))

    # ---------------------------------------------------------- primitives
    def forces(self, x, v, want_jac: bool) -> np.ndarray:
        """Sum of the enabled force terms on every local row (each term is a stage)."""
        f = np.zeros((self.n_local, 3))
        for name in FORCE_STAGES:
            self.pipeline.run(name, x, v, f, want_jac)
        if self._first_forces is None:      # the step's forces at the start state (friction)
            self._first_forces = f.copy()
        return f

    def stiffness_product(self, w) -> np.ndarray:
        out = np.zeros((self.n_local, 3))
        for t in self.terms:
            if t.has_jacobian and self.pipeline.enabled(t.name):
                t.stiffness_product(w, out)
        return out

    def assemble(self, alpha: float, beta: float, gamma: float = 1.0) -> np.ndarray:
        return self.pipeline.run("assembly", alpha, beta, gamma)

    def _assemble(self, alpha, beta, gamma):
        """Block values of A = gamma M - beta df/dv - alpha df/dx for the owned rows."""
        data = self.pattern.new_values()
        m = gamma * self.mass[: self.n_owned]
        ds = self.pattern.diag_slots
        for a in range(3):
            data[ds, a, a] += m
        for t in self.terms:
            if t.has_jacobian:
                t.add_to_system(data, alpha, beta)
        return data

    def solve(self, data, rhs, cons):
        return self.pipeline.run("solve", data, rhs, cons)

    def _solve(self, data, rhs, cons):
        fdata, frhs = filter_system(self.pattern, data, rhs, cons)
        self.system.set_values(fdata)
        y, info = self.system.solve(frhs)
        owned = cons.index < self.n_owned
        y[cons.index[owned]] += cons.z[owned]
        return y, info

    def local_array(self, owned_rows: np.ndarray) -> np.ndarray:
        a = np.zeros((self.n_local, owned_rows.shape[1]))
        a[: self.n_owned] = owned_rows
        self.ghosts.update(a)
        return a

    def project(self, cons, rows):
        """S applied to the constrained owned rows of an (n_owned, 3) array."""
        out = rows.copy()
        owned = cons.index < self.n_owned
        idx = cons.index[owned]
        out[idx] = np.einsum("nij,nj->ni", cons.S[owned], rows[idx])
        return out

    def global_norm(self, rows) -> float:
        return math.sqrt(self.comm.sum(np.array([float(np.sum(rows * rows))]))[0])

    # ---------------------------------------------------------------- stages
    def _kinematics(self, t_new):
        """Prescribed velocities at t + h of the constrained vertices (pins, then
        sliding pins): at rest for now (moving pins and colliders join here)."""
        return np.zeros((self.pinned_local.size + self.slide_local.size, 3))

    def _constraints(self, target_velocity=None):
        """Pins (S = 0) and sliding pins (S = I - a a^T): z takes the constrained
        directions of the velocity change to the target (at rest for now)."""
        idx = np.concatenate([self.pinned_local, self.slide_local])
        S = np.concatenate([np.zeros((self.pinned_local.size, 3, 3)), self.slide_S])
        if target_velocity is None:
            target_velocity = np.zeros((idx.size, 3))
        z = np.einsum("nij,nj->ni", np.eye(3)[None] - S, target_velocity - self.v[idx])
        contacts = self.collisions.contacts
        if contacts is not None and contacts.index.size:
            # contacts (never on pinned or sliding vertices): S = I - n n^T
            from .collision.response import contact_constraint
            cS, cz = contact_constraint(contacts, self.v)
            idx = np.concatenate([idx, contacts.index])
            S = np.concatenate([S, cS])
            z = np.concatenate([z, cz])
        order = np.argsort(idx, kind="stable")
        return Constraints(idx[order], S[order], z[order])

    def _collision_bodies(self, t, h, missed=None):
        return self.collisions.bodies(t, h, missed)

    def _collision_response(self, result, h):
        return self.collisions.response(result, h)

    def _update(self, result):
        n = self.n_owned
        self.x[:n] = result.x
        self.v[:n] = result.v
        if self._inject is not None and self.step_index == self._inject:
            self.x[0] = np.nan
        self.ghosts.update(self.x, self.v)

    def energies(self) -> tuple[float, float, float]:
        """(kinetic, gravitational, elastic) energy of the current state, summed
        over ranks (collective). Elastic counts every term with a potential:
        springs, FE membrane, hinges, shells; damping and drag have none."""
        n = self.n_owned
        kinetic = 0.5 * float(np.sum(self.mass[:n] * np.einsum("ij,ij->i", self.v[:n], self.v[:n])))
        grav = elastic = 0.0
        for t in self.terms:
            if t.name == "force:gravity":
                grav += t.energy(self.x)
            else:
                elastic += t.energy(self.x)
        k, g, e = self.comm.sum(np.array([kinetic, grav, elastic]))
        return float(k), float(g), float(e)

    def _diagnostics(self, result) -> dict:
        n = self.n_owned
        # the health check already summed the committed state's energies
        now, self._energies_now = self._energies_now, None
        kinetic, grav, elastic = now if now is not None else self.energies()
        speed = float(np.sqrt(np.max(np.einsum("ij,ij->i", self.v[:n], self.v[:n]), initial=0.0)))
        sums = (kinetic, grav, elastic)
        maxes = self.comm.max(np.array([self._max_strain(), speed]))
        return {
            "step_size": self.h,
            "kinetic_energy": sums[0], "gravitational_energy": sums[1], "elastic_energy": sums[2],
            "total_energy": sums[0] + sums[1] + sums[2],
            "max_strain": maxes[0], "max_speed": maxes[1],
            "newton_iterations": result.newton_iterations, "newton_residual": result.newton_residual,
            "ksp_iterations": result.ksp_iterations, "ksp_residual": result.ksp_residual,
            "rejected_steps": self.rejections, "newton_unconverged": self.newton_unconverged,
            **self.collisions.diagnostics(),
        }

    def _output(self, writer):
        writer.write_frame(self.step_index, self.time, self.x[: self.n_owned])

    # ------------------------------------------------------------------ run
    def owned_positions(self) -> np.ndarray:
        return self.x[: self.n_owned]

    def step(self) -> dict:
        """Advance one step of the scene's h; returns the diagnostics.  Raises
        SimulationError on every rank together.

        A rejected attempt (failed solve; NaN, blow-up or strain bound after
        the tentative update; an acceptance hook's verdict) is undone and,
        with ``time.adaptive``, retried as two steps of h/2, recursively up to
        ``time.max_halvings`` times; otherwise the run stops naming the cause."""
        self.step_index += 1
        result, h_min = self._advance(self.h, 0)
        self.time = self.step_index * self.h        # no drift from summed substeps
        diag = self.pipeline.run("diagnostics", result)
        diag["step_size"] = h_min
        return diag

    def _advance(self, h, depth):
        result, reason, fatal = self._attempt(h)
        if reason is None:
            return result, h
        tc = self.cfg.time
        if fatal or not tc.adaptive or depth >= tc.max_halvings:
            if tc.adaptive and not fatal:
                reason += f" (after {depth} halvings, h = {h:.3g} s)"
            raise SimulationError(self.step_index, reason)
        self.say(f"step {self.step_index}: rejected at h = {h:.3g} s ({reason}); "
                 f"retrying as two steps of {h / 2:.3g} s")
        self.rejections += 1
        self._advance(h / 2, depth + 1)
        result, h2 = self._advance(h / 2, depth + 1)
        return result, min(h2, h / 2)

    def _attempt(self, h):
        """One tentative step: (result, None, False) if accepted and committed,
        else (None, reason, fatal) with the state unchanged."""
        target = self.pipeline.run("kinematics", self.time + h)
        missed = None
        col = self.collisions
        for _ in range(MAX_CONTACT_PASSES if col.has_bodies else 1):
            if col.has_bodies:
                col.contacts = self.pipeline.run("collision:bodies", self.time, h, missed)
                if self.friction_term is not None:
                    self.friction_term.begin_step(col.contacts, h, col.solved_friction(col.contacts))
            cons = self.pipeline.run("constraints", target)
            error, solver_failure, result = None, False, None
            self._first_forces = None
            try:
                result = self.integrator.step(self, h, cons)
            except SolverFailure as exc:      # the same on every rank
                error, solver_failure = f"SolverFailure: {exc}", True
            except Exception as exc:          # a local bug is not: agree on it
                error = f"{type(exc).__name__}: {exc}"
            agreed = self.comm.agree(error)
            if agreed is not None:
                where = f" (rank {agreed[0]})" if self.comm.size > 1 and not solver_failure else ""
                return None, agreed[1] + where, not solver_failure
            if not col.has_bodies:
                break
            # a vertex the prediction missed that ends the step inside a body:
            # solve the step again with it as a contact (collective)
            missed = col.missed_contacts(result, h, missed)
            if missed is None:
                break
        if col.has_response:    # collective (every rank got here): friction, impulses, fail-safe
            error = None
            try:
                result = self.pipeline.run("collision:response", result, h)
            except Exception as exc:
                error = f"{type(exc).__name__} in the collision response: {exc}"
            agreed = self.comm.agree(error)
            if agreed is not None:
                return None, agreed[1] + (f" (rank {agreed[0]})" if self.comm.size > 1 else ""), True
        if not result.newton_converged and self.cfg.time.require_newton_convergence:
            return None, (f"Newton did not converge in {result.newton_iterations} iterations "
                          f"(relative residual {result.newton_residual:.3g} > "
                          f"time.newton_tolerance = {self.cfg.time.newton_tolerance:g})"), False
        saved = (self.x.copy(), self.v.copy())
        self.pipeline.run("update", result)
        reason = self._check_state()
        for hook in self.accept_hooks:
            reason = reason or hook(self, result)
        if reason:
            self.x, self.v = saved
            return None, reason, False
        self.integrator.accepted()
        self.collisions.accepted()
        self.time += h
        if not result.newton_converged:
            if self.newton_unconverged == 0:
                self.say(f"step {self.step_index}: Newton used all {result.newton_iterations} "
                         f"iterations (residual {result.newton_residual:.3g} > "
                         f"{self.cfg.time.newton_tolerance:g}); accepted, counted in "
                         f"newton_unconverged (time.require_newton_convergence rejects)")
            self.newton_unconverged += 1
        if self.energy_guard.wants_reference(self.time):
            self.energy_guard.set_reference(*self._energies_now)
        return result, None, False

    def _check_state(self) -> str | None:
        """Collective health check of the tentative state (two reductions):
        NaN, speed limit, strain bound, energy guard.  Keeps the state's
        energies for the diagnostics stage and the guard's reference."""
        n = self.n_owned
        finite = bool(np.all(np.isfinite(self.x[:n])) and np.all(np.isfinite(self.v[:n])))
        speed = float(np.sqrt(np.max(np.einsum("ij,ij->i", self.v[:n], self.v[:n]), initial=0.0))) \
            if finite else 0.0
        strain = self._max_strain() if finite and self.cfg.time.max_strain is not None else 0.0
        bad, speed, strain = self.comm.max(np.array([0.0 if finite else 1.0, speed, strain]))
        self._energies_now = None
        if bad:
            return "NaN or Inf in positions or velocities"
        if speed > MAX_SPEED:
            return f"blow-up: a vertex moves at {speed:.3g} m/s (limit {MAX_SPEED:g} m/s)"
        if self.cfg.time.max_strain is not None and strain > self.cfg.time.max_strain:
            return f"strain {strain:.3g} exceeds time.max_strain = {self.cfg.time.max_strain:g}"
        self._energies_now = self.energies()
        return self.energy_guard.check(*self._energies_now)

    def _max_strain(self) -> float:
        """Largest engineering membrane strain (local, ghosts valid): structural
        springs, or the FE triangles' principal stretch - 1."""
        return max((t.max_strain(self.x) for t in self.terms), default=0.0)

    def destroy(self):
        if self.system is not None:
            from .linalg.petsc import remove_options
            remove_options(getattr(self, "_inserted_options", []))
            self.system.destroy()
        self.ghosts.destroy()


def _solver_setup_error(exc, options: dict, cmdline: set) -> ConfigError:
    """One line naming the option PETSc refused (the one whose value its message quotes)."""
    parts = [p.strip() for p in str(exc).split("[0]") if p.strip()]
    reason = parts[-1] if parts else str(exc)
    for name, value in options.items():
        if str(value) and str(value) in reason:
            where = f"command line -distcloth_{name}" if name in cmdline else f"solver.{name}"
            return ConfigError(where, value, f"PETSc refused it: {reason}")
    return ConfigError("solver", "", f"PETSc refused the solver set-up: {reason}")


def _nan_injection(rank: int):
    """Test hook: DISTCLOTH_INJECT_NAN=RANK:STEP poisons one position on that rank after that step."""
    spec = os.environ.get("DISTCLOTH_INJECT_NAN")
    if not spec:
        return None
    r, s = spec.split(":")
    return int(s) if int(r) == rank else None


class Progress:
    """Rank 0's progress line with an ETA, at most once a second."""

    def __init__(self, comm, total_steps: int, enabled: bool = True):
        self.comm, self.total = comm, total_steps
        self.enabled = enabled and comm.rank == 0
        self.t0 = self.last = time.perf_counter()

    def update(self, step: int, t: float):
        if not self.enabled:
            return
        now = time.perf_counter()
        if now - self.last < 1.0 and step < self.total:
            return
        self.last = now
        rate = step / max(now - self.t0, 1e-9)
        eta = (self.total - step) / rate if rate > 0 else 0.0
        print(f"[distcloth] step {step}/{self.total}  t = {t:.3f} s  {rate:.1f} steps/s  "
              f"ETA {_hms(eta)}", file=sys.stderr, flush=True)


def _hms(seconds: float) -> str:
    seconds = int(round(seconds))
    h, rem = divmod(seconds, 3600)
    m, s = divmod(rem, 60)
    return f"{h}h{m:02d}m{s:02d}s" if h else (f"{m}m{s:02d}s" if m else f"{s}s")
