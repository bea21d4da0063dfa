"""The accuracy study's variants: what to vary, the reference, running each
variant in process and resuming a sweep.

Axes are ``key.path=v1,v2,...`` with the ``--set`` machinery
(``distcloth.config.load.apply_overrides``; values are YAML, commas inside
brackets belong to the value), plus shorthands that expand to several keys:

  * ``resolution=9,17``     every grid piece's ``mesh.grid.resolution`` = [N, N]
  * ``pc=jacobi,bjacobi_sgs,sgs32,gamg,hypre``   the solver's preconditioner
  * ``limiter=off,provot,velocity``   the strain_limiting effect and its method
  * ``combo=key=v;key=v;...``   one variant that sets several keys (shorthands
    included), e.g. soft springs, an explicit scheme at its own step and a
    limiter together

The reference is not one of the variants: the smallest step / 4, BDF-2 with
Newton to 1e-10, ``ksp_rtol`` 1e-10 on the unpreconditioned residual, the
finest resolution; axes that change the model (membrane, bending, effects)
keep the base scene's value, so their "error" is their distance from it.

Each variant runs collectively on the ranks of the study and writes an HDF5
result into the study directory, named by a hash of its overrides; one whose
file says ``status`` completed (or failed: a blow-up is a finished, repeatable
outcome) and carries the study's wall time is not run again.
"""
from __future__ import annotations

import copy
import dataclasses
import hashlib
import itertools
import math
import os
import time
from dataclasses import dataclass

import h5py
import numpy as np
import yaml

from ..config import ConfigError, format_config_error
from ..config.load import apply_overrides, config_from_dict
from ..config.describe import entry
from ..config.schema import LIMIT_METHODS, SceneConfig, TimeSpec
from ..io.console import Progress
from ..io.h5read import read_attrs
from ..io.h5writer import FINISHED
from ..linalg.presets import PRECONDITIONERS
from ..run import open_writer, setup, write_steps
from ..simulation import SimulationError

def _pc_overrides(options: dict, mat_type: str) -> dict:
    """One preset as scene overrides: pc_type, the matrix type where it is not
    the default BAIJ, then the preconditioner's own options."""
    out = {"solver.pc_type": options["pc_type"]}
    if mat_type != "baij":
        out["linear_system.mat_type"] = mat_type
    out.update({f"solver.{k}": v for k, v in options.items() if k != "pc_type"})
    return out


# the preconditioners as measured in docs/benchmarks.md (distcloth/linalg/presets.py)
PC_PRESETS = {name: _pc_overrides(*preset) for name, preset in PRECONDITIONERS.items()}
REFERENCE_DEFAULTS = ("time.integrator=bdf2", "time.newton_iterations=8",
                      "time.newton_tolerance=1e-10", "solver.ksp_rtol=1e-10",
                      "solver.ksp_norm_type=unpreconditioned")
REFERENCE_STEP_FACTOR = 4
# the noise floor: the reference rerun from positions moved by this much (m);
# far above round-off on a metre-sized cloth, far below any discretisation error
NOISE_AMPLITUDE = 1e-9
WALL_ATTR = "study_wall"


@dataclass(frozen=True)
class Variant:
    name: str                      # file stem, stable across runs (hash of the overrides)
    role: str                      # variant | reference | noise
    settings: tuple                # ((axis, value text), ...) as the user gave them
    overrides: tuple               # key.path=value, applied after the base overrides
    perturb: float = 0.0           # m, start positions moved (noise floor only)
    alone: bool = False            # an --alone axis value, varied around the base scene
    base: bool = False             # resolves to the base scene: what --alone variants compare with

    def label(self) -> str:
        return ", ".join(f"{k}={v}" for k, v in self.settings) or (
            "base scene" if self.base else self.role)


@dataclass
class Outcome:
    variant: Variant
    path: str
    status: str                    # completed | failed | refused
    wall: float = math.nan         # s, slowest rank, set-up included
    ran: bool = False              # False: found finished in the study directory
    message: str = ""


def split_values(text: str) -> list[str]:
    """'a,[1,2],b' -> ['a', '[1,2]', 'b']: commas at bracket depth 0 separate values."""
    out, depth, cur = [], 0, ""
    for ch in text:
        if ch in "[{":
            depth += 1
        elif ch in "]}":
            depth -= 1
        if ch == "," and depth == 0:
            out.append(cur.strip())
            cur = ""
        else:
            cur += ch
    if cur.strip():
        out.append(cur.strip())
    return out


def parse_vary(specs) -> dict[str, list[str]]:
    """['time.step=0.02,0.01', ...] -> {'time.step': ['0.02', '0.01'], ...} (order kept)."""
    axes: dict[str, list[str]] = {}
    for spec in specs:
        key, eq, values = spec.partition("=")
        vals = split_values(values)
        if not eq or not key.strip() or not vals:
            raise ValueError(f"--vary {spec!r}: key.path=value1,value2,...")
        axes.setdefault(key.strip(), []).extend(vals)
    return axes


def normalise_scene(raw: dict) -> dict:
    """A one-piece cloth mapping becomes a list, so cloth.0.* paths address it."""
    raw = copy.deepcopy(raw)
    if isinstance(raw.get("cloth"), dict):
        raw["cloth"] = [raw["cloth"]]
    return raw


def _grid_pieces(raw: dict) -> list[int]:
    return [i for i, c in enumerate(raw.get("cloth") or [])
            if isinstance(c, dict) and isinstance(c.get("mesh"), dict) and "grid" in c["mesh"]]


def expand(raw: dict, axis: str, value: str) -> tuple[str, ...]:
    """One axis value -> key.path=value overrides."""
    if axis == "resolution":
        v = yaml.safe_load(value)
        res = v if isinstance(v, list) else [v, v]
        pieces = _grid_pieces(raw)
        if not pieces:
            raise ValueError("resolution: the scene has no grid piece")
        return tuple(f"cloth.{i}.mesh.grid.resolution=[{res[0]}, {res[1]}]" for i in pieces)
    if axis == "limiter":
        if value not in ("off",) + LIMIT_METHODS:
            raise ValueError(f"limiter={value}: one of off, {', '.join(LIMIT_METHODS)}")
        effects = [e for e in (raw.get("effects") or entry(SceneConfig, "effects").default)
                   if e != "strain_limiting"]
        if value == "off":
            return (f"effects=[{', '.join(effects)}]",)
        return (f"effects=[{', '.join(effects + ['strain_limiting'])}]",
                f"strain_limiting.method={value}")
    if axis == "combo":
        out: tuple[str, ...] = ()
        for part in (p.strip() for p in value.split(";")):
            key, eq, val = part.partition("=")
            if not part or not eq or not key.strip() or key.strip() == "combo":
                raise ValueError(f"combo={value}: key=value parts separated by ';'")
            out += expand(raw, key.strip(), val.strip())
        return out
    if axis == "pc":
        if value not in PC_PRESETS:
            raise ValueError(f"pc={value}: one of {', '.join(PC_PRESETS)}")
        return tuple(f"{k}={v}" for k, v in PC_PRESETS[value].items())
    return (f"{axis}={value}",)


def _name(role: str, overrides) -> str:
    digest = hashlib.sha1("\n".join((role,) + tuple(overrides)).encode()).hexdigest()[:12]
    return f"{role}-{digest}"


def _resolved_time_step(raw: dict, base_overrides) -> float:
    r = apply_overrides(raw, base_overrides)
    step = (r.get("time") or {}).get("step")
    if step is None:
        return TimeSpec().step
    return float(step)


def _resolved(raw: dict, overrides) -> dict:
    return apply_overrides(raw, tuple(overrides))


def _combos(axes: dict[str, list[str]], one_at_a_time: bool) -> list[tuple]:
    if one_at_a_time:
        return [((k, v),) for k, vals in axes.items() for v in vals]
    return [tuple(zip(axes, vals)) for vals in itertools.product(*axes.values())]


def _base_resolution(raw: dict, base_overrides) -> str | None:
    """The first grid piece's resolution in the base scene, as an axis value."""
    r = _resolved(raw, base_overrides)
    pieces = _grid_pieces(r)
    if not pieces:
        return None
    return str(list(r["cloth"][pieces[0]]["mesh"]["grid"].get("resolution", [])))


def _reference(raw, axes, base_overrides, reference_overrides, with_base=False) -> tuple:
    """The reference's overrides: smallest step / 4, finest resolution, tight solves;
    ``with_base``: the base scene is a variant too, so its step and mesh count."""
    steps = [float(v) for v in axes.get("time.step", [])]
    if with_base or not steps:
        steps.append(_resolved_time_step(raw, base_overrides))
    ref = base_overrides + tuple(REFERENCE_DEFAULTS) + (
        f"time.step={min(steps) / REFERENCE_STEP_FACTOR!r}",)
    if "resolution" in axes:
        values = list(axes["resolution"])
        base_res = _base_resolution(raw, base_overrides) if with_base else None
        if base_res is not None:
            values.append(base_res)
        finest = max(values, key=lambda s: np.prod(np.atleast_1d(yaml.safe_load(s))))
        if finest != base_res:           # the base mesh needs no override
            ref += expand(raw, "resolution", finest)
    return ref + tuple(reference_overrides)


def plan(raw: dict, axes: dict[str, list[str]], base_overrides=(), *, one_at_a_time=False,
         reference_overrides=(), noise_floor=True, alone=None) -> list[Variant]:
    """The variants (full product of the axes, or each axis alone around the base),
    then each value of the ``alone`` axes by itself around the base scene (with the
    variant that is the base scene, added if no product variant resolves to it),
    then the reference and its perturbed rerun."""
    raw = normalise_scene(raw)
    base_overrides = tuple(base_overrides)
    alone = alone or {}
    base_scene = _resolved(raw, base_overrides) if alone else None
    variants = []
    for settings in _combos(axes, one_at_a_time) if axes or not alone else []:
        ov = base_overrides + tuple(o for k, v in settings for o in expand(raw, k, v))
        is_base = bool(alone) and _resolved(raw, ov) == base_scene
        variants.append(Variant(_name("variant", ov), "variant", settings, ov, base=is_base))
    if alone and not any(v.base for v in variants):
        variants.append(Variant(_name("variant", base_overrides), "variant", (), base_overrides,
                                base=True))
    for k, vals in alone.items():
        for v in vals:
            ov = base_overrides + expand(raw, k, v)
            variants.append(Variant(_name("variant", ov), "variant", ((k, v),), ov, alone=True))
    every_axis = {k: list(axes.get(k, [])) + list(alone.get(k, [])) for k in {**axes, **alone}}
    ref = _reference(raw, every_axis, base_overrides, reference_overrides, with_base=bool(alone))
    out = variants + [Variant(_name("reference", ref), "reference", (), ref)]
    if noise_floor:
        out.append(Variant(_name("noise", ref), "noise", (), ref, perturb=NOISE_AMPLITUDE))
    return out


def finished(path: str) -> tuple[bool, str, float]:
    """(finished?, status, wall) of a variant's result file, read on one rank."""
    if not os.path.exists(path):
        return False, "", math.nan
    try:
        attrs = read_attrs(path)
    except OSError:               # a file cut off mid-write: run it again
        return False, "", math.nan
    status = attrs.get("status", "")
    wall = attrs.get(WALL_ATTR)
    if status in FINISHED:       # a study judges the energy itself: warnings are its data
        status = "completed"
    if status in ("completed", "failed") and wall is not None:
        return True, status, float(wall)
    return False, status, math.nan


def _config(raw, base_dir, source_name, overrides, every, comm):
    """The variant's checked configuration, built on rank 0 and broadcast
    (as the CLI does), or the config error's one line."""
    cfg = message = None
    if comm.rank == 0:
        try:
            r = apply_overrides(raw, overrides)
            r.setdefault("output", {})
            r["output"] = dict(r["output"] or {}, preview=False)
            if every is not None:
                r["output"]["every"] = every
            cfg = config_from_dict(r, base_dir, source_name)
        except ConfigError as exc:
            message = format_config_error(exc)
    return comm.broadcast((cfg, message))


def refusals(variants, raw: dict, base_dir: str, source_name: str, comm,
             every: float | None = None) -> dict[str, str]:
    """Each variant whose configuration is refused -> the error's one line,
    found before anything runs; collective."""
    raw = normalise_scene(raw)
    out = {}
    for var in variants:
        _, message = _config(raw, base_dir, source_name, var.overrides, every, comm)
        if message is not None:
            out[var.name] = message
    return out


def perturb_start(sim, amplitude: float, seed: int = 20240601) -> None:
    """Move every start position by a fixed pseudo-random vector of this length:
    drawn for all vertices in input order on every rank, so ghosts agree."""
    rng = np.random.default_rng(seed)
    d = rng.standard_normal((sim.model.num_vertices, 3))
    d *= amplitude / np.linalg.norm(d, axis=1, keepdims=True)
    sim.state.x += d[sim.layout.local_input]


def run_variant(cfg, comm, path: str, *, perturb: float = 0.0, progress: bool = False):
    """One run, as ``distcloth.run.run`` does it, into ``path``; collective.
    Returns (status, wall seconds of the slowest rank, message)."""
    t0 = time.perf_counter()
    sim, code = setup(cfg, comm, quiet=True)
    if code:
        return "refused", math.nan, "configuration refused (see the message above)"
    if perturb:
        perturb_start(sim, perturb)
    h = cfg.time.step
    n_steps = max(1, int(round(cfg.time.end / h)))
    every = max(1, int(round(cfg.output.every / h)))
    writer = open_writer(sim, cfg, comm, path, sim.diagnostic_names(),
                         {"steps": n_steps, "output_every_steps": every, "study_perturb": perturb})
    sim.pipeline.run("output", writer)
    sim.pipeline.take_step_counters()
    bar = Progress(comm, n_steps, enabled=progress)
    status, message = "completed", ""
    try:
        write_steps(sim, writer, n_steps, every, bar)
    except SimulationError as exc:
        writer.record_error(exc.step, str(exc))
        status, message = "failed", str(exc)
    writer.close(status)
    sim.destroy()
    wall = float(comm.max(np.array([time.perf_counter() - t0]))[0])
    if comm.rank == 0:         # the wall time marks the file as a finished study variant
        with h5py.File(path, "a") as f:
            f.attrs[WALL_ATTR] = wall
    comm.synchronize()
    return status, wall, message


def warm_up(cfg, comm, directory: str) -> None:
    """One step of the first variant to run, thrown away: imports, numba
    compilation and PETSc's first set-up would otherwise be charged to it."""
    cfg1 = dataclasses.replace(cfg, time=dataclasses.replace(cfg.time, end=cfg.time.step))
    path = os.path.join(directory, "_warmup.h5")
    run_variant(cfg1, comm, path)
    if comm.rank == 0:
        for p in (path, path[:-3] + ".xdmf"):
            if os.path.exists(p):
                os.remove(p)
    comm.synchronize()


def run_sweep(variants, raw: dict, base_dir: str, source_name: str, comm, directory: str, *,
              every: float | None = None, say=None, step_progress: bool = False) -> list[Outcome]:
    """Run every variant not already finished in ``directory``; collective.
    ``say(msg)`` is called on rank 0 with the progress through the sweep."""
    raw = normalise_scene(raw)
    if comm.rank == 0:
        os.makedirs(directory, exist_ok=True)
    comm.synchronize()
    outcomes = []
    warmed = False
    for i, var in enumerate(variants, 1):
        path = os.path.join(directory, var.name + ".h5")
        done = comm.broadcast(finished(path) if comm.rank == 0 else None)
        head = f"[{i}/{len(variants)}] {var.role} {var.label()}"
        if done[0]:
            outcomes.append(Outcome(var, path, done[1], done[2], ran=False))
            if say:
                say(f"{head}: already {done[1]} ({done[2]:.2f} s), not rerun")
            continue
        cfg, message = _config(raw, base_dir, source_name, var.overrides, every, comm)
        if message is not None:
            outcomes.append(Outcome(var, path, "refused", ran=True, message=message))
            if say:
                say(f"{head}: refused: {message}")
            continue
        if not warmed:
            warm_up(cfg, comm, directory)
            warmed = True
        if say:
            say(f"{head}: running {int(round(cfg.time.end / cfg.time.step))} steps of {cfg.time.step:g} s")
        status, wall, msg = run_variant(cfg, comm, path, perturb=var.perturb, progress=step_progress)
        outcomes.append(Outcome(var, path, status, wall, ran=True, message=msg))
        if say:
            say(f"{head}: {status} in {wall:.2f} s" + (f" ({msg})" if msg else ""))
    return outcomes
