"""Run a scene end to end on every rank: check, set up, step, write.

Error protocol (every rank takes the same path, so none waits forever):
  * config errors are found before any output exists, by deterministic
    code on every rank, and agreed at two check points -> exit 2;
  * numerical failures (NaN, blow-up, solver failure) are agreed inside
    ``Simulation.step`` -> the error is recorded in the file, the frames
    already written stay, exit 1;
  * anything unexpected is a bug -> traceback and MPI_Abort (in cli.py).
"""
from __future__ import annotations

import os
import sys
import time

import numpy as np

from .collision.surfaces import collider_surfaces
from .config import format_config_error
from .config.schema import ConfigError
from .frame_fields import FRAME_FIELDS
from .integrate.drape import DRAPE_DIAGNOSTICS, Relaxation, drape_converged
from .io.console import Progress, log
from .io.h5writer import ResultWriter
from .scene import build_model
from .sew import garment_arrays, sew
from .simulation import DIAGNOSTICS, Simulation, SimulationError
from .stages import STAGES


def _agree_config(comm, err: ConfigError | None):
    agreed = comm.agree(format_config_error(err) if err is not None else None)
    if agreed is not None:
        if comm.rank == 0:
            print(agreed[1], file=sys.stderr, flush=True)
        return 2
    return 0


def setup(cfg, comm, *, force=False, cmdline_options=None, quiet=False):
    """Build the model and the simulation; returns (sim, exit code)."""
    err = None
    model = None
    try:
        model = build_model(cfg)
    except ConfigError as exc:
        err = exc
    except MemoryError:      # past the up-front estimate (scene/build.py): still one line
        err = ConfigError("cloth", "the scene", "a scene whose model fits in memory")
    code = _agree_config(comm, err)
    if code:
        return None, code
    for note in getattr(model, "load_notes", ()):
        log(comm, note)
    sim = None
    try:
        sim = Simulation(cfg, model, comm, force_explicit=force,
                         cmdline_options=cmdline_options, quiet=quiet)
        sim.prepare()
    except ConfigError as exc:
        err = exc
    code = _agree_config(comm, err)
    if code:
        return None, code
    return sim, 0


def open_writer(sim, cfg, comm, path, diagnostic_names, extra_attrs, arrays=None):
    """The run's result file, with what the run was and the colliders' surfaces,
    which every frame then records (collective)."""
    lay = sim.layout
    attrs = {
        "scene": cfg.scene, "ranks": comm.size, "integrator": cfg.time.integrator,
        "time_step": cfg.time.step,
        "solver": sim.system.describe() if sim.system else "explicit",
        "block_jacobi_blocks": int(comm.sum(np.array(
            [sim.system.block_jacobi_blocks() if sim.system else 0]))[0]),
        "rows_per_rank": [int(v) for v in 3 * (lay.ownership[1:] - lay.ownership[:-1])],
        "edge_cut": lay.edge_cut, "imbalance": lay.imbalance, "cloth_size": sim.model.size(),
        **extra_attrs,
    }
    return ResultWriter(path, comm if comm.under_mpiexec else None,
                        rest_positions=sim.model.rest_positions, triangles=sim.model.triangles,
                        owned_input=lay.owned_input, part=lay.part, config_text=cfg.source_text,
                        attrs=attrs, stage_names=list(STAGES), diagnostic_names=diagnostic_names,
                        colliders=collider_surfaces(sim.contact.colliders,
                                                    sim.model.rest_positions),
                        arrays=arrays, fields=FRAME_FIELDS)


def sew_if_needed(sim, cfg, comm, path, *, force=False, quiet=False, cmdline_options=None,
                  progress=True):
    """A scene with stitches is sewn and welded first (sew.py); returns the
    simulation to go on with and an exit code (1: the sewing failed)."""
    if sim.model.stitch_pairs is None:
        return sim, 0
    try:
        sim, figures = sew(sim, cfg, comm, path,
                           lambda s, p, names, attrs: open_writer(s, cfg, comm, p, names, attrs),
                           quiet=quiet, progress=progress, force=force,
                           cmdline_options=cmdline_options)
    except SimulationError as exc:
        log(comm, f"stopped: {exc}")
        return None, 1
    log(comm, f"sewn in {figures['sewing_time']:g} s ({figures['sewing_steps']} steps), widest "
              f"stitch {1e3 * figures['stitch_gap']:.2f} mm")
    return sim, 0


def write_steps(sim, writer, n_steps: int, every: int, bar=None) -> None:
    """Steps 1..n_steps: each step's diagnostics row, a frame every ``every`` steps
    and after the last; raises SimulationError as ``sim.step`` does (collective)."""
    for k in range(1, n_steps + 1):
        diag = sim.step()
        # the step's row first, so the frame's flush carries it; the output
        # stage's time is charged to the following step's row
        times, calls = sim.pipeline.take_step_counters()
        _agreed_write(sim, writer, writer.write_step, sim.state.step, sim.state.t, diag, times,
                      calls)
        if k % every == 0 or k == n_steps:
            _agreed_write(sim, writer, sim.pipeline.run, "output", writer)
        if bar:
            bar.update(k, sim.state.t)


def _agreed_write(sim, writer, write, *args) -> None:
    """``write(*args)`` on every rank, then agreed before anyone goes on to the next
    collective: a write that fails (a full disk, a lost file system), maybe on
    some ranks only, stops every rank as a failed step (SimulationError)."""
    failure = None
    try:
        write(*args)
    except OSError as exc:
        failure = f"writing {writer.path} failed: {exc}"
    agreed = sim.comm.agree(failure)
    if agreed is not None:
        raise SimulationError(sim.state.step, agreed[1])


def run(cfg, comm, *, output=None, force=False, cmdline_options=None, check_only=False,
        quiet=False, progress=True) -> int:
    t_start = time.perf_counter()
    sim, code = setup(cfg, comm, force=force, cmdline_options=cmdline_options, quiet=quiet)
    if code:
        return code
    if check_only:
        log(comm, "check: the scene is valid")
        sim.destroy()
        return 0
    path = output or cfg.output.file
    h = cfg.time.step
    sim, code = sew_if_needed(sim, cfg, comm, path, force=force, quiet=quiet,
                              cmdline_options=cmdline_options, progress=progress)
    if code:
        return code
    # a sewn garment goes on from the time its sewing ended, to time.end
    n_steps = max(0, max(1, int(round(cfg.time.end / h))) - sim.state.step)
    every = max(1, int(round(cfg.output.every / h)))
    bounds = sim.contact.image_error_bounds()
    image = {f"image_error_bound/{name}": list(bound) for name, bound in bounds.items()}
    for name, (du, dv) in bounds.items():
        log(comm, f"image-space collider {name}: x-y error bound (Vassilev et al. 2001 Eq. 14) "
                  f"{1e3 * du:.2f} x {1e3 * dv:.2f} mm")
    for c in sim.contact.colliders:
        if c.region is not None:
            log(comm, f"collider {c.name} in contact: {c.region}")
    writer = open_writer(sim, cfg, comm, path, list(DIAGNOSTICS),
                         {"steps": n_steps, "output_every_steps": every, **image},
                         garment_arrays(sim.model))
    log(comm, f"writing {os.path.abspath(path)}: {n_steps} steps of {h:g} s, a frame every {every}")
    sim.pipeline.run("output", writer)
    sim.pipeline.take_step_counters()
    bar = Progress(comm, n_steps, enabled=progress and not quiet)
    status, code = "completed", 0
    try:
        write_steps(sim, writer, n_steps, every, bar)
    except SimulationError as exc:
        log(comm, f"stopped: {exc}")
        writer.record_error(exc.step, str(exc))
        status, code = "failed", 1
    writer.close(status)
    wall = time.perf_counter() - t_start
    traversal = sim.contact.traversal_summary()      # collective
    if not quiet:
        log(comm, f"stage times (rank 0):\n{sim.pipeline.summary()}")
        if traversal:
            log(comm, traversal)
        if sim.limiter_unconverged_steps:
            log(comm, f"warning: strain limiting did not reach its bound in "
                      f"{sim.limiter_unconverged_steps} steps (strain_limiting.passes = "
                      f"{cfg.strain_limiting.passes}; limited_strain in the diagnostics)")
        log(comm, f"{status} in {wall:.2f} s: {os.path.abspath(path)} "
                  f"(+ {os.path.splitext(os.path.basename(path))[0]}.xdmf for ParaView)")
    _previews(cfg, comm, path)
    sim.destroy()
    return code


def drape(cfg, comm, *, output=None, cmdline_options=None, quiet=False) -> int:
    """``distcloth drape``: relax to the rest state (Volino and Magnenat-Thalmann
    2007); a frame every ``drape.frame_every`` iterations and the last; frame
    'time' is the iteration."""
    t_start = time.perf_counter()
    sim, code = setup(cfg, comm, cmdline_options=cmdline_options, quiet=quiet)
    if code:
        return code
    spec = cfg.drape
    path = output or cfg.output.file
    sim, code = sew_if_needed(sim, cfg, comm, path, quiet=quiet, cmdline_options=cmdline_options)
    if code:
        return code
    writer = open_writer(sim, cfg, comm, path, list(DRAPE_DIAGNOSTICS),
                         {"drape_method": spec.method, "drape_stop_on": spec.stop_on,
                          "drape_tolerance": spec.tolerance}, garment_arrays(sim.model))
    log(comm, f"draping ({spec.method}) into {os.path.abspath(path)}: residual tolerance "
              f"{spec.tolerance:g}, at most {spec.max_iterations} iterations")
    relax = Relaxation(sim, spec)
    # a frame's 'time' is the iteration; the colliders are drawn where the state's time puts them
    writer.write_frame(0, 0.0, sim.owned_positions(), body_time=sim.state.t,
                       fields=sim.frame_fields())
    bar = Progress(comm, spec.max_iterations, enabled=not quiet)
    status, code, k = "completed", 0, 0
    try:
        for k in range(1, spec.max_iterations + 1):
            diag = relax.iterate()
            times, calls = sim.pipeline.take_step_counters()
            writer.write_step(k, float(k), diag, times, calls)
            done = drape_converged(diag, spec)
            if done or k % spec.frame_every == 0 or k == spec.max_iterations:
                writer.write_frame(k, float(k), sim.owned_positions(), body_time=sim.state.t,
                                   fields=sim.frame_fields())
            bar.update(k, float(k))
            if done:
                break
        else:
            raise SimulationError(k, f"drape did not converge in {spec.max_iterations} iterations "
                                     f"(residual {diag['residual']:.3g} > {spec.tolerance:g})")
    except SimulationError as exc:
        log(comm, f"stopped: {exc}")
        writer.record_error(exc.step, str(exc))
        status, code = "failed", 1
    writer.close(status)
    _previews(cfg, comm, path)
    if code == 0:
        log(comm, f"converged in {k} iterations ({relax.stops} stops), residual "
                  f"{diag['residual']:.3g}, {time.perf_counter() - t_start:.2f} s: {os.path.abspath(path)}")
    sim.destroy()
    return code


def _previews(cfg, comm, path):
    if cfg.output.preview and comm.rank == 0:
        try:
            # matplotlib takes a second to import: only runs that draw pay for it
            from .io.preview import write_previews
            for p in write_previews(path):
                log(comm, f"preview: {os.path.abspath(p)}")
        except Exception as exc:   # a picture must never turn a finished run into a failure
            log(comm, f"preview failed: {exc}")
