"""The State: everything a step reads and writes, on this rank's local rows.

A step starts from one State and either commits a new one or leaves it as it
was: the driver takes a ``snapshot()`` before it changes anything and
``restore``s it when the step is rejected, so no part of the step keeps
memory of its own that a rejection could leave stale.  A checkpoint is a
State (plus the scene it belongs to).

Arrays are local: owned vertices first, then ghosts (their rows are copies
of other ranks' owned rows, refreshed by the ghost exchange).
"""
from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import Any

import numpy as np


@dataclass
class MultistepHistory:
    """What a multistep integrator keeps of the last accepted step (BDF-2:
    the state it started from and its size)."""
    x: np.ndarray          # (n_local, 3)
    v: np.ndarray          # (n_local, 3)
    h: float


@dataclass
class State:
    x: np.ndarray                        # (n_local, 3) positions, m
    v: np.ndarray                        # (n_local, 3) velocities, m/s
    t: float = 0.0                       # s: time of the committed state
    step: int = 0                        # steps completed (or being taken)
    history: MultistepHistory | None = None
    contacts: Any = None                 # the body contacts the last committed step used
    touching: np.ndarray | None = None   # (k, n_local) bool: near each body at its end
    acceleration: np.ndarray | None = None   # (n_local, 3) (v - v_before) / h of the last step
    # the energy guard's (E_ref, S) once the scene became passive
    energy_reference: tuple[float, float] | None = None
    rejections: int = 0                  # attempts undone so far (adaptive halving)
    newton_unconverged: int = 0          # accepted steps whose Newton loop ran out
    contact_changes: int = 0             # re-solves the last step's contact set needed
    # (h, the mass-weighted norm of its local error estimate) of the last
    # committed step, for the next one's solve tolerance (integrate/implicit.py)
    step_error: tuple[float, float] | None = None

    def snapshot(self) -> "State":
        """A copy to restore if the step is rejected (the history, contacts and
        energy reference are replaced, never changed in place: shared)."""
        saved = copy.copy(self)
        saved.x, saved.v = self.x.copy(), self.v.copy()
        return saved

    def restore(self, saved: "State") -> None:
        """Become ``saved`` again, keeping the array objects (other code holds them)."""
        self.x[...] = saved.x
        self.v[...] = saved.v
        for name in ("t", "step", "history", "contacts", "touching", "acceleration",
                     "energy_reference",
                     "rejections", "newton_unconverged", "contact_changes", "step_error"):
            setattr(self, name, getattr(saved, name))

    def clear_history(self) -> None:
        """Velocities were reset from outside (draping): a multistep history no longer applies."""
        self.history = None
