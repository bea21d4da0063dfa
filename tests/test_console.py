"""The progress line (io/console.py): one rewritten line on a terminal,
sparse plain lines otherwise, and an ETA the first slow step does not spoil."""
from __future__ import annotations

import io
import subprocess
import sys

import pytest

from conftest import ROOT, clean_env

from distcloth.io.console import Progress, log


class Rank:
    def __init__(self, rank=0):
        self.rank = rank


class Clock:
    def __init__(self):
        self.now = 0.0

    def __call__(self):
        return self.now


def drive(bar, clock, steps, first=60.0, each=0.1):
    """``steps`` steps: the first takes ``first`` seconds (compilation), the
    others ``each``."""
    for k in range(1, steps + 1):
        clock.now += first if k == 1 else each
        bar.update(k, 0.01 * k)


def test_eta_from_the_recent_rate_not_the_compiling_first_step():
    clock, out = Clock(), io.StringIO()
    bar = Progress(Rank(), 1000, stream=out, clock=clock, tty=False)
    drive(bar, clock, 100)
    assert abs(bar.rate() - 10.0) < 1e-9
    assert abs(bar.eta(100) - 90.0) < 1e-6      # 900 steps at 0.1 s, not at 0.7 s
    assert "10 steps/s  ETA 1m30s" in out.getvalue().splitlines()[-1]


def test_plain_lines_every_tenth_or_thirty_seconds():
    clock, out = Clock(), io.StringIO()
    bar = Progress(Rank(), 1000, stream=out, clock=clock, tty=False)
    drive(bar, clock, 1000, first=0.1, each=0.01)          # 10 s in all
    lines = out.getvalue().splitlines()
    assert len(lines) == 10 and "\r" not in out.getvalue()
    assert [line.split()[2] for line in lines] == [f"{k}/1000" for k in range(100, 1001, 100)]
    clock, out = Clock(), io.StringIO()
    slow = Progress(Rank(), 1000, stream=out, clock=clock, tty=False)
    drive(slow, clock, 99, first=1.0, each=1.0)           # 99 s before the first tenth
    assert [line.split()[2] for line in out.getvalue().splitlines()] == ["30/1000", "60/1000",
                                                                         "90/1000"]


def test_terminal_line_rewritten_in_place_and_ended_by_a_log_line(monkeypatch):
    clock, out = Clock(), io.StringIO()
    out.isatty = lambda: True
    bar = Progress(Rank(), 50, stream=out, clock=clock)
    assert bar.tty
    drive(bar, clock, 20, first=1.0, each=0.3)
    text = out.getvalue()
    assert text.count("\r") == 20 and "\n" not in text
    monkeypatch.setattr(sys, "stderr", out)      # log() writes where the line is
    log(Rank(), "stopped")
    monkeypatch.undo()
    assert out.getvalue().endswith("\n[distcloth] stopped\n")
    drive(bar, clock, 50, first=0.3, each=0.3)
    assert out.getvalue().endswith("(100 %)  t = 0.500 s  3.33 steps/s  ETA 0s\n")


def test_other_ranks_and_disabled_print_nothing():
    for bar in (Progress(Rank(1), 10, stream=io.StringIO(), tty=False),
                Progress(Rank(0), 10, enabled=False, stream=io.StringIO(), tty=False)):
        for k in range(1, 11):
            bar.update(k, 0.0)
        assert bar.stream.getvalue() == ""


@pytest.mark.rank0_only
def test_launcher_keeps_a_config_error_one_line():
    """scripts/mpiexec.sh passes --quiet to Open MPI: no banner after the
    error line of a rank that exits with status 2, unless asked for."""
    cmd = [str(ROOT / "scripts" / "mpiexec.sh"), "2", sys.executable, "-m", "distcloth", "check",
           str(ROOT / "configs" / "default.yaml"), "--set", "time.end=x"]
    quiet = subprocess.run(cmd, env=clean_env(), capture_output=True, text=True, timeout=300)
    assert quiet.returncode == 2
    assert quiet.stderr.strip().splitlines() == [
        "distcloth: config error: time.end: 'x' — a finite number > 0"], quiet.stderr
    loud = subprocess.run(cmd, env=clean_env(DISTCLOTH_MPI_VERBOSE="1"), capture_output=True,
                          text=True, timeout=300)
    assert loud.returncode == 2 and "non-zero" in loud.stderr
