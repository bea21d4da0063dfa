"""SIGTERM and SIGINT while a run steps: finish the step, then stop cleanly.

The handler only records the signal; the driver asks ``pending()`` at the
end of every step and the ranks agree on it (a signal that reached one rank
stops them all at the same step: mpiexec forwards a signal to every rank,
``kill`` on one pid does not).  A second signal exits at once with 128 +
its number (the signal's default action), without cleaning up.

Test hook: ``DISTCLOTH_SIGNAL_AT=RANK:STEP[:NAME]`` makes that rank send
itself the signal NAME (default TERM; KILL for a killed run) when that
step ends, before the ranks agree: a signal at a chosen step, reproducibly.
"""
from __future__ import annotations

import os
import signal
import threading

SIGNALS = (signal.SIGTERM, signal.SIGINT)


def signal_name(signum: int) -> str:
    try:
        return signal.Signals(signum).name
    except ValueError:
        return f"signal {signum}"


class Interrupts:
    """A context manager: SIGTERM and SIGINT recorded, not acted on, inside it."""

    def __init__(self, rank: int = 0):
        self.signum = 0
        self._old: dict[int, object] = {}
        self._hook = _signal_hook(rank)

    def __enter__(self) -> "Interrupts":
        if threading.current_thread() is threading.main_thread():
            for s in SIGNALS:
                self._old[s] = signal.signal(s, self._handle)
        return self

    def __exit__(self, *exc) -> bool:
        for s, old in self._old.items():
            signal.signal(s, old)
        self._old.clear()
        return False

    def _handle(self, signum, frame) -> None:
        if self.signum:
            os.write(2, f"[distcloth] second {signal_name(signum)}: stopping at once\n".encode())
            # the default action: the process ends by the signal (status 128 + signal)
            signal.signal(signum, signal.SIG_DFL)
            os.kill(os.getpid(), signum)
            return
        self.signum = signum

    def pending(self, step: int) -> int:
        """The signal received so far on this rank (0: none); fires the test hook."""
        if self._hook is not None and self._hook[0] == step:
            os.kill(os.getpid(), self._hook[1])
        return self.signum


def _signal_hook(rank: int):
    spec = os.environ.get("DISTCLOTH_SIGNAL_AT")
    if not spec:
        return None
    parts = spec.split(":")
    if int(parts[0]) != rank:
        return None
    name = parts[2] if len(parts) > 2 else "TERM"
    return int(parts[1]), getattr(signal, f"SIG{name}")
