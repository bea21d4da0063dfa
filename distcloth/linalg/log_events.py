"""The step's stages as PETSc log events, so ``-log_view`` times them
beside PETSc's own (KSPSolve, MatAssemblyEnd, ...) under the stage names
of distcloth/stages.py.  Events are registered once per process; their
begin/end cost a few counters, so every stage call is wrapped.

Work inside a stage or between stages that is worth seeing on its own has
an event too (``logged``): the solve's constraint filter, its insertion of
the values into PETSc and its true-residual check, and the health check
after the update (energies, strain, speed)."""
from __future__ import annotations

from contextlib import contextmanager

from .petsc import petsc

_events: dict = {}


def stage_event(name: str):
    """The PETSc log event of the stage ``name`` (begin() / end())."""
    event = _events.get(name)
    if event is None:
        event = _events[name] = petsc().Log.Event(name)
    return event


@contextmanager
def logged(name: str):
    """Time the block as the PETSc log event ``name``."""
    event = stage_event(name)
    event.begin()
    try:
        yield
    finally:
        event.end()
