"""Is the run that writes a result file still alive?

A run records its ranks' host names and process ids in the file (root
attributes ``hosts``, ``pids``) and the writer keeps a ``heartbeat`` (the
time of the last frame or flush).  A file whose status is still 'running'
was either killed (SIGKILL, a crash, a lost node) or is being written right
now: on the host that wrote it the process ids answer that; elsewhere only
the heartbeat hints at it.
"""
from __future__ import annotations

import os
import socket
import time
from typing import Any, Mapping

import numpy as np

ALIVE, DEAD, UNKNOWN = "alive", "dead", "unknown"


def identity() -> tuple[str, int]:
    """This process's (host, pid), as a run records it."""
    return socket.gethostname(), os.getpid()


def _running(pid: int) -> bool:
    """A live process with this id that is a distcloth run (not a reused id)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        pass
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as stream:
            return b"distcloth" in stream.read()
    except OSError:
        return True    # no /proc: trust the signal test


def _listed(value) -> list:
    return [] if value is None else list(np.atleast_1d(value))


def judge(attrs: Mapping[str, Any]) -> tuple[str, str]:
    """(ALIVE | DEAD | UNKNOWN, one-line explanation) for a file whose status
    is 'running'."""
    hosts = [h.decode() if isinstance(h, bytes) else str(h) for h in _listed(attrs.get("hosts"))]
    pids = [int(p) for p in _listed(attrs.get("pids"))]
    beat = attrs.get("heartbeat")
    ago = f"; last sign of life {time.time() - float(beat):.0f} s ago" if beat is not None else ""
    here = socket.gethostname()
    if not pids:
        return UNKNOWN, f"the run was killed or is still running elsewhere (no process ids recorded{ago})"
    if all(h == here for h in hosts):
        alive = [p for p in pids if _running(p)]
        if alive:
            return ALIVE, f"still running (pid {', '.join(map(str, alive))} on this host{ago})"
        return DEAD, (f"the run was killed: none of its processes is alive (pid "
                      f"{', '.join(map(str, pids))} on {here}{ago})")
    others = sorted(set(hosts) - {here}) or sorted(set(hosts))
    return UNKNOWN, (f"the run was killed or is still running elsewhere (host "
                     f"{', '.join(others)}{ago})")
