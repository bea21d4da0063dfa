"""Time integrators behind one interface: ``step(sim, h, constraints) -> StepResult``.

An integrator reads the committed state ``sim.x, sim.v`` (local rows, ghosts
valid), may evaluate forces as often as it needs through ``sim.forces``, and
returns the proposed new owned state without committing it: the driver's
acceptance hooks may still reject the step; ``accepted()`` is called when
the driver commits it (multistep schemes keep their history there).
"""
from .base import StepResult
from .explicit import RK4, ExplicitMidpoint, SymplecticEuler
from .implicit import BDF2, BackwardEuler, ImplicitMidpoint, Newmark

INTEGRATORS = {
    "backward_euler": BackwardEuler,
    "bdf2": BDF2,
    "implicit_midpoint": ImplicitMidpoint,
    "newmark": Newmark,
    "symplectic_euler": SymplecticEuler,
    "explicit_midpoint": ExplicitMidpoint,
    "rk4": RK4,
}


def make_integrator(cfg):
    return INTEGRATORS[cfg.time.integrator](cfg)
