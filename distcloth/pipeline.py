"""The step's stages at run time: each with a switch, a call counter and a timer.

The stages and their order come from ``distcloth/stages.py``; a simulation
binds a function to each stage its scene has.  A stage that is off is never
called: ``run`` returns None without touching its function, so what a scene
does not ask for costs nothing.  The counters prove it (tests read them from
the output file).  Each enabled stage is also a PETSc log event
(linalg/log_events.py), so ``-log_view`` lists it.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, Callable

from .linalg.log_events import stage_event
from .stages import STAGES


@dataclass
class Stage:
    name: str
    fn: Callable | None
    enabled: bool
    calls: int = 0
    seconds: float = 0.0
    step_calls: int = 0
    step_seconds: float = 0.0
    event: Any = None          # its PETSc log event (-log_view)


@dataclass
class Pipeline:
    stages: dict[str, Stage] = field(default_factory=dict)
    trace: list[str] | None = None    # a list: every call's stage name is appended (tests)

    @classmethod
    def bind(cls, bindings: dict[str, tuple[Callable | None, bool]]) -> "Pipeline":
        """The declared stages that have a binding (name -> (function, enabled)),
        in the declared order."""
        unknown = set(bindings) - set(STAGES)
        if unknown:
            raise ValueError(f"stages not declared in distcloth/stages.py: {sorted(unknown)}")
        p = cls()
        for name in STAGES:
            if name in bindings:
                fn, enabled = bindings[name]
                on = bool(enabled) and fn is not None
                p.stages[name] = Stage(name, fn, on, event=stage_event(name))
        return p

    def enabled(self, name: str) -> bool:
        st = self.stages.get(name)
        return st is not None and st.enabled

    def run(self, name: str, *args, **kwargs):
        st = self.stages[name]
        if not st.enabled:
            return None
        if self.trace is not None:
            self.trace.append(name)
        t0 = time.perf_counter()
        st.event.begin()
        try:
            return st.fn(*args, **kwargs)
        finally:
            st.event.end()
            dt = time.perf_counter() - t0
            st.calls += 1
            st.seconds += dt
            st.step_calls += 1
            st.step_seconds += dt

    def names(self) -> list[str]:
        return list(self.stages)

    def take_step_counters(self) -> tuple[dict[str, float], dict[str, int]]:
        """Per-stage time and calls since the last call, then reset them."""
        times = {n: s.step_seconds for n, s in self.stages.items()}
        calls = {n: s.step_calls for n, s in self.stages.items()}
        for s in self.stages.values():
            s.step_seconds, s.step_calls = 0.0, 0
        return times, calls

    def summary(self) -> str:
        total = sum(s.seconds for s in self.stages.values()) or 1.0
        lines = [f"{'stage':<20}{'on':>4}{'calls':>9}{'seconds':>11}{'share':>8}"]
        for s in self.stages.values():
            lines.append(f"{s.name:<20}{'yes' if s.enabled else 'no':>4}{s.calls:>9}"
                         f"{s.seconds:>11.3f}{100 * s.seconds / total:>7.1f}%")
        return "\n".join(lines)
