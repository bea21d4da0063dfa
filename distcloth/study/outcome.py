"""The record of one stability-suite variant: how it was run and how it ended."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from .classify import Trace

# explicit runs at their stable step: the case's duration, at most this many steps
MAX_EXPLICIT_STEPS, MAX_EXPLICIT_STEPS_REDUCED = 2_000, 200


@dataclass
class Result:
    case: str
    integrator: str
    setting: str
    status: str
    step: int | None = None
    reason: str = ""
    h: float = math.nan
    steps_planned: int = 0
    steps_run: int = 0
    sim_time: float = 0.0
    wall: float = 0.0
    energy_excess: float = math.nan
    slope_rise: float = math.nan
    penetration: float = math.nan
    first_violation: int | None = None
    note: str = ""
    trace: Trace | None = field(default=None, repr=False)   # per-step records (not in the CSV)
