"""The step as a list of named stages, each with a switch, a call counter and a timer.

A stage that is off is never called: ``run`` returns None without touching
its function, so what a scene does not ask for costs nothing.  The counters
prove it (tests read them from the output file).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable


@dataclass
class Stage:
    name: str
    fn: Callable | None
    enabled: bool
    calls: int = 0
    seconds: float = 0.0
    step_calls: int = 0
    step_seconds: float = 0.0


@dataclass
class Pipeline:
    stages: dict[str, Stage] = field(default_factory=dict)

    def add(self, name: str, fn: Callable | None, enabled: bool = True) -> None:
        if name in self.stages:
            raise ValueError(f"stage {name} added twice")
        self.stages[name] = Stage(name, fn, enabled and fn is not None)

    def enabled(self, name: str) -> bool:
        st = self.stages.get(name)
        return st is not None and st.enabled

    def run(self, name: str, *args, **kwargs):
        st = self.stages[name]
        if not st.enabled:
            return None
        t0 = time.perf_counter()
        try:
            return st.fn(*args, **kwargs)
        finally:
            dt = time.perf_counter() - t0
            st.calls += 1
            st.seconds += dt
            st.step_calls += 1
            st.step_seconds += dt

    def timed(self, name: str):
        """Context manager that charges a block of code to a stage (for stages
        whose work is inline, e.g. the solve inside an integrator)."""
        return _Timed(self.stages[name])

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
        lines = [f"{'stage':<18}{'on':>4}{'calls':>9}{'seconds':>11}{'share':>8}"]
        for s in self.stages.values():
            lines.append(f"{s.name:<18}{'yes' if s.enabled else 'no':>4}{s.calls:>9}"
                         f"{s.seconds:>11.3f}{100 * s.seconds / total:>7.1f}%")
        return "\n".join(lines)


class _Timed:
    def __init__(self, stage: Stage):
        self.stage = stage

    def __enter__(self):
        self.t0 = time.perf_counter()
        return self

    def __exit__(self, *exc):
        dt = time.perf_counter() - self.t0
        self.stage.calls += 1
        self.stage.seconds += dt
        self.stage.step_calls += 1
        self.stage.step_seconds += dt
        return False
