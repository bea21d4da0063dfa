"""Checkpoints of a running simulation and ``--resume``: when a run writes
one (every so many steps or seconds, on a signal, at the end) and how a
resumed run finds its checkpoint and result file and checks that it is
the same scene.  What a checkpoint holds is restart.py's; the file format
io/checkpoint.py's."""
from __future__ import annotations

import os
import time
from dataclasses import dataclass

import numpy as np

from .config import format_config_error
from .config.compare import check_resumable
from .config.schema import ConfigError
from .io.checkpoint import checkpoint_path, is_checkpoint, read_checkpoint, write_checkpoint
from .io.console import log, shared_or_refused
from .io.h5read import read_attrs
from .io.h5writer import FORMAT_NAME
from .io.liveness import ALIVE, judge
from .restart import capture


@dataclass
class Resume:
    """What ``--resume`` continues: the checkpoint and the result file it belongs to."""
    checkpoint: str
    result: str
    scalars: dict
    arrays: dict
    killed: str | None = None      # how the run that wrote the result ended, if it was killed


def open_resume(cfg, comm, target: str, output: str | None):
    """The Resume of ``--resume TARGET`` (a result file or its checkpoint), read
    on rank 0 and broadcast; (None, 2) after a config error on every rank."""
    resume, message = None, None
    if comm.rank == 0:
        try:
            resume = _read_resume(cfg, target, output)
        except ConfigError as exc:
            message = format_config_error(exc)
    return shared_or_refused(comm, resume, message)


def _read_resume(cfg, target: str, output: str | None) -> Resume:
    if output is not None:
        raise ConfigError("--output", output, "not with --resume: the run goes on in the "
                                              "resumed result file")
    if not os.path.isfile(target):
        raise ConfigError("--resume", target, "an existing result file or its checkpoint")
    killed = None
    if is_checkpoint(target):
        ckpt = os.path.abspath(target)
        attrs = read_attrs(ckpt)
        result = os.path.join(os.path.dirname(ckpt), str(attrs.get("result", "")))
        if not os.path.isfile(result):
            raise ConfigError("--resume", target, f"a checkpoint beside its result file "
                                                  f"({result} does not exist)")
    else:
        result = os.path.abspath(target)
        try:
            attrs = read_attrs(result)
        except OSError as exc:
            raise ConfigError("--resume", target, f"a distcloth result file or checkpoint "
                                                  f"(cannot read it: {exc})") from None
        if attrs.get("format") != FORMAT_NAME:
            raise ConfigError("--resume", target, "a distcloth result file or checkpoint")
        ckpt = os.path.join(os.path.dirname(result),
                            str(attrs.get("checkpoint") or os.path.basename(checkpoint_path(result))))
        if not os.path.isfile(ckpt):
            raise ConfigError("--resume", target, f"a result with a checkpoint: {ckpt} does not "
                                                  f"exist (the run stopped before its first "
                                                  f"checkpoint, or while sewing)")
    attrs = read_attrs(result)
    if attrs.get("status") == "running":
        state, why = judge(attrs)
        if state == ALIVE:
            raise ConfigError("--resume", target, f"a result no run is writing: {why}")
        killed = why
    try:
        scalars, text, arrays = read_checkpoint(ckpt)
    except (OSError, ValueError) as exc:
        raise ConfigError("--resume", ckpt, f"a readable checkpoint ({exc})") from None
    check_resumable(text, cfg.source_text)
    if cfg.time.end < float(scalars["time"]) - 1e-12:
        raise ConfigError("time.end", cfg.time.end, f"at least the checkpoint's time "
                                                    f"{float(scalars['time']):g} s")
    return Resume(ckpt, result, scalars, arrays, killed)




class Checkpoints:
    """When and how a run writes its checkpoint (collective methods)."""

    def __init__(self, sim, cfg, comm, writer, path: str, extra: dict, interrupts):
        self.sim, self.cfg, self.comm, self.writer = sim, cfg, comm, writer
        self.path, self.result = checkpoint_path(path), os.path.basename(path)
        self.extra, self.interrupts = extra, interrupts
        spec = cfg.output.checkpoint
        self.every_steps, self.every_seconds = spec.every_steps, spec.every_seconds
        self.last = time.monotonic()

    def after_step(self) -> int:
        """At the end of every step: the ranks agree on a signal any of them
        received and on rank 0's clock; a checkpoint if one is due or the run
        stops.  Returns the signal that stops the run, or 0."""
        step = self.sim.state.step
        received = self.interrupts.pending(step)
        late = bool(self.comm.rank == 0 and self.every_seconds is not None
                    and time.monotonic() - self.last >= self.every_seconds)
        signum, due = self.comm.max(np.array([float(received), float(late)]))
        if signum or due or (self.every_steps and step % self.every_steps == 0):
            self.write()
        return int(signum)

    def write(self) -> None:
        """The checkpoint of the current state; the result file flushed first,
        so it holds every step up to it.  A checkpoint that cannot be written
        is reported, not fatal: the run's frames are still being written."""
        self.writer.flush()
        scalars, arrays = capture(self.sim, self.extra.get("weld"))
        error = None
        if self.comm.rank == 0:
            attrs = {**scalars, "result": self.result, "ranks": self.comm.size,
                     "phase_start_step": int(self.extra["phase_start_step"])}
            try:
                write_checkpoint(self.path, self.cfg.source_text, attrs, arrays)
            except OSError as exc:
                error = f"warning: checkpoint not written: {exc}"
        agreed = self.comm.agree(error)    # every rank returns once rank 0 has renamed
        if agreed is not None:
            log(self.comm, agreed[1])
        self.last = time.monotonic()
