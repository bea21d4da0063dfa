"""The step's stages as PETSc log events, so ``-log_view`` times them
beside PETSc's own (KSPSolve, MatAssemblyEnd, ...) under the stage names
of distcloth/stages.py.  Events are registered once per process; their
begin/end cost a few counters, so every stage call is wrapped."""
from __future__ import annotations

from .petsc import petsc

_events: dict = {}


def stage_event(name: str):
    """The PETSc log event of the stage ``name`` (begin() / end())."""
    event = _events.get(name)
    if event is None:
        event = _events[name] = petsc().Log.Event(name)
    return event
