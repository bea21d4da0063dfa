"""The integrator interface: ``step(ctx, state, h, constraints) -> StepResult``.

An integrator reads the committed state (``state.x``, ``state.v``: local
rows, ghosts valid; ``state.history`` for multistep schemes) and does
everything else through the step context (``distcloth/step_context.py``):
force evaluations (as often as it needs), stiffness products, assembly, the
constrained solve, ghost exchanges and global norms.  It proposes the new
owned rows without committing them, and says in its result what the rest of
the step needs: the forces at the start state, how positions follow a
velocity change made after the solve, and the history a multistep scheme
keeps if the driver commits the step.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..state import MultistepHistory


@dataclass
class StepResult:
    x: np.ndarray                 # (n_owned, 3) proposed positions
    v: np.ndarray                 # (n_owned, 3) proposed velocities
    start_forces: np.ndarray      # (n_local, 3) forces at the start state (contact response)
    position_gain: float          # dx1/dv1: positions follow a post-solve velocity change by it
    history: MultistepHistory | None = None   # kept by the state if the step is committed
    # (n_owned, 3) impulses of the constraints in the last solve (implicit schemes
    # with body contacts; linalg/assembly.constraint_impulses), else None
    reaction: np.ndarray | None = None
    newton_iterations: int = 0
    ksp_iterations: int = 0       # summed over the step's solves (and contact passes)
    ksp_residual: float = 0.0     # largest true relative residual of the step's solves
    newton_residual: float = 0.0  # final relative Newton residual (0 for explicit steps)
    newton_converged: bool = True # False: the Newton loop used every iteration above tolerance
    stopped_early: bool = False   # the energy retry's Newton stopped once the step gained none
    # (h, |e|_M of the step's local error estimate) if the scheme has one
    local_error: tuple[float, float] | None = None


class Integrator:
    implicit = True
    stability_factor = math.inf      # explicit schemes: h < 0.9 * factor / sqrt(lambda_max)
    held_gain = 1.0                  # a held row ends at x0 + h v0 + held_gain * h * z
    newton_override: int | None = None   # Newton iterations of a retried step (implicit)
    # the retried step's Newton stops before converging once this predicate of
    # its iterate's (x1, v1) (owned rows; collective) holds; None: it does not
    retry_stop = None

    def __init__(self, cfg):
        self.cfg = cfg

    def held_path(self, state, h: float, rows: np.ndarray) -> tuple[np.ndarray, float]:
        """(where the step puts the local ``rows`` in their constrained directions
        when their velocity change z is zero, dx1/dz): the kinematics stage
        solves x1 = path(t + h) for z, so a grip is exactly on its path after
        the step (BW98 §5.3's prescribed change, not a correction after it)."""
        return state.x[rows] + h * state.v[rows], self.held_gain * h

    def monotone_energy(self, state, h: float) -> bool:
        """True if this step, converged, cannot raise a passive scene's energy."""
        return False

    def step(self, ctx, state, h: float, cons, guess=None) -> StepResult:
        """``guess``: a velocity change (owned rows) to start the first solve from,
        when the step is solved again with revised contacts (implicit schemes)."""
        raise NotImplementedError
