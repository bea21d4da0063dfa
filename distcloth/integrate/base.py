"""What an integrator returns for one step."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass
class StepResult:
    x: np.ndarray                 # (n_owned, 3) proposed positions
    v: np.ndarray                 # (n_owned, 3) proposed velocities
    newton_iterations: int = 0
    ksp_iterations: int = 0       # summed over the step's solves
    ksp_residual: float = 0.0     # largest true relative residual of the step's solves
    newton_residual: float = 0.0  # final relative Newton residual (0 for explicit steps)
    newton_converged: bool = True # False: the Newton loop used every iteration above tolerance


class Integrator:
    implicit = True
    stability_factor = math.inf      # explicit schemes: h < 0.9 * factor / sqrt(lambda_max)

    def __init__(self, cfg):
        self.cfg = cfg

    def step(self, sim, h: float, cons) -> StepResult:
        raise NotImplementedError

    def accepted(self) -> None:
        """The driver committed the last proposed step."""
