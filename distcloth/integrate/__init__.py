"""Time integrators behind one interface (``integrate/base.py``):
``step(ctx, state, h, constraints) -> StepResult``; relaxation to rest in
``integrate/drape.py``."""
from .base import StepResult
from .explicit import RK4, ExplicitMidpoint, SymplecticEuler
from .implicit import BDF2, BackwardEuler, ImplicitMidpoint, Newmark

__all__ = ["StepResult", "INTEGRATORS", "make_integrator"]

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
