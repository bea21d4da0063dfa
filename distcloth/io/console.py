"""Rank 0's messages on stderr: log lines and the progress line."""
from __future__ import annotations

import sys
import time


def log(comm, msg: str) -> None:
    if comm.rank == 0:
        print(f"[distcloth] {msg}", file=sys.stderr, flush=True)


class Progress:
    """Rank 0's progress line with an ETA, at most once a second."""

    def __init__(self, comm, total_steps: int, enabled: bool = True):
        self.comm, self.total = comm, total_steps
        self.enabled = enabled and comm.rank == 0
        self.t0 = self.last = time.perf_counter()

    def update(self, step: int, t: float):
        if not self.enabled:
            return
        now = time.perf_counter()
        if now - self.last < 1.0 and step < self.total:
            return
        self.last = now
        rate = step / max(now - self.t0, 1e-9)
        eta = (self.total - step) / rate if rate > 0 else 0.0
        print(f"[distcloth] step {step}/{self.total}  t = {t:.3f} s  {rate:.1f} steps/s  "
              f"ETA {_hms(eta)}", file=sys.stderr, flush=True)


def _hms(seconds: float) -> str:
    seconds = int(round(seconds))
    h, rem = divmod(seconds, 3600)
    m, s = divmod(rem, 60)
    return f"{h}h{m:02d}m{s:02d}s" if h else (f"{m}m{s:02d}s" if m else f"{s}s")
