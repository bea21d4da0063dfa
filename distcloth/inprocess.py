"""Simulations built in process from raw scene mappings, collectively: the
studies and the fabric lab run many small scenes in one job and must refuse
a bad one on every rank together, never leave a rank waiting."""
from __future__ import annotations

from typing import Callable

from .config import format_config_error
from .config.load import config_from_dict
from .config.schema import ConfigError
from .scene import build_model
from .simulation import Simulation


def agreed(comm, fn: Callable):
    """fn() on every rank; (value, None) or (None, the agreed config-error message)."""
    value, err = None, None
    try:
        value = fn()
    except ConfigError as exc:
        err = format_config_error(exc)
    agreement = comm.agree(err)
    return (None, agreement[1]) if agreement is not None else (value, None)


def build_simulation(raw: dict, name: str, comm, *, force: bool = False,
                     hook: Callable | None = None, base_dir: str = "."):
    """(prepared Simulation, hook's note, None) or (None, note, refusal message);
    ``hook(model)`` sees the built model before the simulation is made."""
    cfg, err = agreed(comm, lambda: config_from_dict(raw, base_dir, name))
    if err:
        return None, "", err
    model, err = agreed(comm, lambda: build_model(cfg))
    if err:
        return None, "", err
    note = (hook(model) if hook else None) or ""
    holder = {}

    def make():
        holder["sim"] = Simulation(cfg, model, comm, quiet=True, force_explicit=force)
        holder["sim"].prepare()
        return holder["sim"]
    sim, err = agreed(comm, make)
    if err:
        if "sim" in holder:
            holder["sim"].destroy()
        return None, note, err
    return sim, note, None
