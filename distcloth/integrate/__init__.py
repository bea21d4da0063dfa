"""Time integrators behind one interface: ``step(sim, h, constraints) -> StepResult``.

An integrator reads the committed state ``sim.x, sim.v`` (local rows, ghosts
valid), may evaluate forces as often as it needs through ``sim.forces``, and
returns the proposed new owned state without committing it: the driver's
acceptance hooks may still reject the step.
"""
from .base import StepResult
from .backward_euler import BackwardEuler
from .symplectic_euler import SymplecticEuler

INTEGRATORS = {
    "backward_euler": BackwardEuler,
    "symplectic_euler": SymplecticEuler,
}


def make_integrator(cfg):
    return INTEGRATORS[cfg.time.integrator](cfg)
