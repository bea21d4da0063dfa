"""Rank 0's messages on stderr: log lines and the progress line."""
from __future__ import annotations

import sys
import time
from collections import deque

# the progress line last written to a terminal without its newline (a log
# line must first end it); None when there is none
_open_line: list = [None]


def log(comm, msg: str) -> None:
    if comm.rank == 0:
        _end_open_line()
        print(f"[distcloth] {msg}", file=sys.stderr, flush=True)


def shared_or_refused(comm, value, message: str | None):
    """Rank 0's ``(value, message)`` on every rank: ``(value, 0)``, or, when
    rank 0 met a config error (``message``), ``(None, 2)`` with the message
    printed once."""
    value, message = comm.broadcast((value, message))
    if message is not None:
        if comm.rank == 0:
            _end_open_line()
            print(message, file=sys.stderr, flush=True)
        return None, 2
    return value, 0


def _end_open_line() -> None:
    stream = _open_line[0]
    if stream is not None:
        stream.write("\n")
        stream.flush()
        _open_line[0] = None


class Progress:
    """Rank 0's progress with an ETA.

    On a terminal: one line rewritten in place (carriage return), at most
    every ``refresh`` seconds.  Otherwise (a log file, a batch system): a
    plain line each time another ``every_fraction`` of the steps is done or
    ``every_seconds`` have passed, whichever comes first, and at the end.

    The ETA divides the steps left by the rate of the last ``window`` steps,
    not of the whole run: the first step pays numba's compilation and the
    setup of the solver, which would otherwise dominate the estimate for a
    long time."""

    def __init__(self, comm, total_steps: int, enabled: bool = True, *, stream=None,
                 clock=time.perf_counter, tty: bool | None = None, window: int = 50,
                 refresh: float = 0.25, every_fraction: float = 0.1,
                 every_seconds: float = 30.0):
        self.total = max(int(total_steps), 1)
        self.enabled = enabled and comm.rank == 0
        self.stream = stream if stream is not None else sys.stderr
        self.clock = clock
        self.tty = bool(tty if tty is not None else _isatty(self.stream))
        self.refresh, self.every_fraction, self.every_seconds = refresh, every_fraction, every_seconds
        self.recent: deque = deque(maxlen=max(2, int(window)))
        self.last_print = self.clock()
        self.mark = 1               # the next plain line at mark * every_fraction of the steps
        self.width = 0

    def rate(self) -> float | None:
        """Steps per second over the recent window (None before two updates)."""
        if len(self.recent) < 2:
            return None
        (t0, s0), (t1, s1) = self.recent[0], self.recent[-1]
        return (s1 - s0) / (t1 - t0) if t1 > t0 and s1 > s0 else None

    def eta(self, step: int) -> float | None:
        rate = self.rate()
        return None if rate is None else (self.total - step) / rate

    def line(self, step: int, t: float) -> str:
        rate, eta = self.rate(), self.eta(step)
        return (f"[distcloth] step {step}/{self.total} ({100.0 * step / self.total:.0f} %)  "
                f"t = {t:.3f} s  " + (f"{rate:.3g} steps/s  ETA {_hms(eta)}"
                                      if rate is not None else "ETA --"))

    def update(self, step: int, t: float) -> None:
        if not self.enabled:
            return
        now = self.clock()
        self.recent.append((now, step))
        last = step >= self.total
        if self.tty:
            if last or now - self.last_print >= self.refresh:
                self._rewrite(self.line(step, t), last)
                self.last_print = now
            return
        if last or step >= self._mark_step() or now - self.last_print >= self.every_seconds:
            while self._mark_step() <= step:
                self.mark += 1
            self.stream.write(self.line(step, t) + "\n")
            self.stream.flush()
            self.last_print = now

    def _mark_step(self) -> int:
        return int(round(self.mark * self.every_fraction * self.total))

    def _rewrite(self, text: str, last: bool) -> None:
        pad = " " * max(0, self.width - len(text))     # clear what a longer line left
        self.width = len(text)
        self.stream.write("\r" + text + pad + ("\n" if last else ""))
        self.stream.flush()
        _open_line[0] = None if last else self.stream


def _isatty(stream) -> bool:
    try:
        return stream.isatty()
    except (AttributeError, ValueError):
        return False


def _hms(seconds: float) -> str:
    seconds = int(round(seconds))
    h, rem = divmod(seconds, 3600)
    m, s = divmod(rem, 60)
    return f"{h}h{m:02d}m{s:02d}s" if h else (f"{m}m{s:02d}s" if m else f"{s}s")
