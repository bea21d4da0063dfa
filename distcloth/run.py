"""Run a scene end to end on every rank: check, set up, step, write.

Error protocol (every rank takes the same path, so none waits forever):
  * config errors are found before any output exists, by deterministic
    code on every rank, and agreed at two check points -> exit 2;
  * numerical failures (NaN, blow-up, solver failure) are agreed inside
    ``Simulation.step`` -> the error is recorded in the file, the frames
    already written stay, exit 1;
  * anything unexpected is a bug -> traceback and MPI_Abort (in cli.py);
  * SIGTERM or SIGINT while stepping -> the step ends on every rank, a
    checkpoint is written, status 'interrupted', exit 128 + signal.

Checkpoints (``output.checkpoint``, io/checkpoint.py, restart.py) are
written every so many steps or seconds and when a run ends or is
interrupted; ``--resume`` rebuilds the simulation from one and appends to
the result file.
"""
from __future__ import annotations

import math
import os
import sys
import time

import numpy as np

from .collision.surfaces import collider_surfaces
from .config import format_config_error
from .config.schema import ConfigError
from .frame_fields import FRAME_FIELDS
from .integrate.drape import DRAPE_DIAGNOSTICS, NoRestState, Relaxation, drape_converged
from .interrupt import Interrupts, signal_name
from .checkpointing import Checkpoints, open_resume
from .io.checkpoint import checkpoint_path
from .io.console import Progress, log
from .io.h5writer import ResultWriter, ResumeRefused
from .io.liveness import identity
from .restart import restore_solver, restore_state
from .scene import build_model
from .sew import garment_arrays, sew, welded_model
from .simulation import Simulation, SimulationError
from .stages import STAGES


def _agree_config(comm, err: ConfigError | None):
    agreed = comm.agree(format_config_error(err) if err is not None else None)
    if agreed is not None:
        if comm.rank == 0:
            print(agreed[1], file=sys.stderr, flush=True)
        return 2
    return 0


def setup(cfg, comm, *, force=False, cmdline_options=None, quiet=False, resume=None):
    """Build the model and the simulation, from the checkpoint of ``resume``
    (a Resume) if given; returns (sim, exit code)."""
    err = None
    model = None
    try:
        model = build_model(cfg)
        if resume is not None and "weld_rows" in resume.arrays:
            # a sewn garment: the same welded mesh from the same weld input
            model = welded_model(cfg, model, resume.arrays["weld_rows"],
                                 float(resume.scalars["weld_time"]))
    except ConfigError as exc:
        err = exc
    except MemoryError:      # past the up-front estimate (scene/build.py): still one line
        err = ConfigError("cloth", "the scene", "a scene whose model fits in memory")
    except ValueError as exc:     # the same on every rank: the model is replicated
        err = ConfigError("--resume", resume.checkpoint, f"its garment cannot be welded again: {exc}")
    code = _agree_config(comm, err)
    if code:
        return None, code
    for note in getattr(model, "load_notes", ()):
        log(comm, note)
    sim = None
    try:
        sim = Simulation(cfg, model, comm, force_explicit=force,
                         cmdline_options=cmdline_options, quiet=quiet)
        if resume is not None:
            restore_state(sim, resume.scalars, resume.arrays)
        sim.prepare()
        if resume is not None:
            restore_solver(sim, resume.scalars, resume.arrays)
    except ConfigError as exc:
        err = exc
    code = _agree_config(comm, err)
    if code:
        return None, code
    return sim, 0


def open_writer(sim, cfg, comm, path, diagnostic_names, extra_attrs, arrays=None,
                resume_step=None):
    """The run's result file, with what the run was and the colliders' surfaces,
    which every frame then records (collective); ``resume_step``: go on
    writing the existing file after that step."""
    lay = sim.layout
    hosts, pids = zip(*comm.gather_objects(identity()))
    attrs = {
        "scene": cfg.scene, "ranks": comm.size, "integrator": cfg.time.integrator,
        "time_step": cfg.time.step,
        "solver": sim.system.describe() if sim.system else "explicit",
        "block_jacobi_blocks": int(comm.sum(np.array(
            [sim.system.block_jacobi_blocks() if sim.system else 0]))[0]),
        "rows_per_rank": [int(v) for v in 3 * (lay.ownership[1:] - lay.ownership[:-1])],
        "edge_cut": lay.edge_cut, "imbalance": lay.imbalance, "cloth_size": sim.model.size(),
        "hosts": list(hosts), "pids": [int(p) for p in pids],
        **extra_attrs,
    }
    return ResultWriter(path, comm if comm.under_mpiexec else None,
                        rest_positions=sim.model.rest_positions, triangles=sim.model.triangles,
                        owned_input=lay.owned_input, part=lay.part, config_text=cfg.source_text,
                        attrs=attrs, stage_names=list(STAGES), diagnostic_names=diagnostic_names,
                        colliders=collider_surfaces(sim.contact.bodies,
                                                    sim.model.rest_positions),
                        arrays=arrays, fields=FRAME_FIELDS, resume_step=resume_step)


def grip_attrs(sim) -> dict:
    """The result file's names of the pin groups whose reactions it records
    (diagnostics reaction_<k>_x/y/z, k the position in this list)."""
    return {"grips": sim.held.names} if sim.record_reactions else {}


def refuse_moving_grips(cfg) -> ConfigError | None:
    """``distcloth drape`` relaxes to a rest state, which a moving grip never has."""
    for p, spec in enumerate(cfg.cloth):
        for k, pin in enumerate(spec.pins):
            if pin.motion is not None:
                return ConfigError(f"cloth.{p}.pins.{k}.motion", "a motion",
                                   "null for distcloth drape (a grip that moves has no rest "
                                   "state to relax to; use distcloth run)")
        if spec.follow_skin is not None:
            return ConfigError(f"cloth.{p}.follow_skin", "a region", "null for distcloth drape "
                               "(a region that follows a body moves with it; use distcloth run)")
    return None


def sew_if_needed(sim, cfg, comm, path, *, force=False, quiet=False, cmdline_options=None,
                  progress=True):
    """A scene with stitches is sewn and welded first (sew.py); returns the
    simulation to go on with, an exit code (1: the sewing failed) and what
    the weld was made from ((rows, t, step), for checkpoints; None unsewn)."""
    if sim.model.stitch_pairs is None:
        return sim, 0, None
    try:
        sim, figures = sew(sim, cfg, comm, path,
                           lambda s, p, names, attrs: open_writer(s, cfg, comm, p, names, attrs),
                           quiet=quiet, progress=progress, force=force,
                           cmdline_options=cmdline_options)
    except SimulationError as exc:
        log(comm, f"stopped: {exc}")
        return None, 1, None
    log(comm, f"sewn in {figures['sewing_time']:g} s ({figures['sewing_steps']} steps), widest "
              f"stitch {1e3 * figures['stitch_gap']:.2f} mm")
    return sim, 0, figures["weld"]


def write_steps(sim, writer, n_steps: int, every: int, bar=None, after_step=None,
                first: int = 0) -> int:
    """Steps ``first``+1..n_steps of a phase that started at step
    ``sim.state.step - first``: each step's diagnostics row, a frame every
    ``every`` steps and after the last; ``after_step()`` (collective) may
    stop the run by returning a signal number, which is returned (0: all
    steps done).  Raises SimulationError as ``sim.step`` does (collective)."""
    for k in range(first + 1, n_steps + 1):
        diag = sim.step()
        # the step's row first, so the frame's flush carries it; the output
        # stage's time is charged to the following step's row
        times, calls = sim.pipeline.take_step_counters()
        _agreed_write(sim, writer, writer.write_step, sim.state.step, sim.state.t, diag, times,
                      calls)
        while sim.warnings:          # the same on every rank: from global sums
            step, _, kind, message = sim.warnings.pop(0)
            _agreed_write(sim, writer, writer.record_warning, step, kind, message)
        if k % every == 0 or k == n_steps:
            _agreed_write(sim, writer, sim.pipeline.run, "output", writer)
        if bar:
            bar.update(k - first, sim.state.t)
        stop = after_step() if after_step is not None else 0
        if stop:
            return stop
    return 0


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


def run(cfg, comm, *, output=None, resume=None, force=False, cmdline_options=None,
        check_only=False, quiet=False, progress=True) -> int:
    """``distcloth run`` (and ``check``); ``resume``: a result file or
    checkpoint to go on from (``--resume``)."""
    t_start = time.perf_counter()
    restart = None
    if resume is not None and not check_only:
        restart, code = open_resume(cfg, comm, resume, output)
        if code:
            return code
    sim, code = setup(cfg, comm, force=force, cmdline_options=cmdline_options, quiet=quiet,
                      resume=restart)
    if code:
        return code
    if check_only:
        log(comm, "check: the scene is valid")
        sim.destroy()
        return 0
    h = cfg.time.step
    if restart is None:
        path = output or cfg.output.file
        sim, code, weld = sew_if_needed(sim, cfg, comm, path, force=force, quiet=quiet,
                                        cmdline_options=cmdline_options, progress=progress)
        if code:
            return code
        phase_start = sim.state.step
    else:
        path = restart.result
        weld = None
        if "weld_rows" in restart.arrays:
            weld = (restart.arrays["weld_rows"], restart.scalars["weld_time"],
                    restart.scalars["weld_step"])
        phase_start = int(restart.scalars["phase_start_step"])
    # a sewn garment goes on from the time its sewing ended, to time.end
    n_steps = max(0, max(1, int(round(cfg.time.end / h))) - phase_start)
    done = sim.state.step - phase_start
    every = max(1, int(round(cfg.output.every / h)))
    bounds = sim.contact.image_error_bounds()
    image = {f"image_error_bound/{name}": list(bound) for name, bound in bounds.items()}
    for name, (du, dv) in bounds.items():
        log(comm, f"image-space collider {name}: x-y error bound (Vassilev et al. 2001 Eq. 14) "
                  f"{1e3 * du:.2f} x {1e3 * dv:.2f} mm")
    for c in sim.contact.bodies:
        if c.region is not None:
            log(comm, f"collider {c.name} in contact: {c.region}")
        spread = getattr(c.body, "arm_spread_degrees", None)
        if spread is not None:
            log(comm, f"collider {c.name}: arms turned out up to {spread[0]:.1f} (left) and "
                      f"{spread[1]:.1f} (right) degrees to keep the upper arms off the chest")
        legs = getattr(c.body, "leg_spread_degrees", None)
        if legs is not None:
            log(comm, f"collider {c.name}: legs turned apart up to {legs:.1f} degrees each to "
                      f"keep the lower legs off each other")
    try:
        writer = open_writer(sim, cfg, comm, path, sim.diagnostic_names(),
                             {"steps": n_steps, "output_every_steps": every,
                              "checkpoint": os.path.basename(checkpoint_path(path)), **image,
                              **grip_attrs(sim)},
                             garment_arrays(sim.model),
                             resume_step=None if restart is None else sim.state.step)
    except ResumeRefused as exc:
        # on every rank alike, before anything in the file changed
        sim.destroy()
        why = str(exc).removeprefix(f"{restart.result} ")
        return _agree_config(comm, ConfigError("--resume", restart.result,
                                               f"a result this checkpoint belongs to (it {why})"))
    if restart is None:
        log(comm, f"writing {os.path.abspath(path)}: {n_steps} steps of {h:g} s, a frame every {every}")
        sim.pipeline.run("output", writer)
    else:
        if restart.killed:
            log(comm, restart.killed)
        log(comm, f"resuming {os.path.abspath(path)} from {restart.checkpoint}: step {done} of "
                  f"{n_steps} (t = {sim.state.t:g} s), {comm.size} ranks")
    sim.pipeline.take_step_counters()
    bar = Progress(comm, n_steps - done, enabled=progress and not quiet)
    status, code, signum = "completed", 0, 0
    with Interrupts(comm.rank) as interrupts:
        checkpoints = Checkpoints(sim, cfg, comm, writer, path,
                                  {"weld": weld, "phase_start_step": phase_start}, interrupts)
        try:
            signum = write_steps(sim, writer, n_steps, every, bar, checkpoints.after_step, done)
            if not signum:
                checkpoints.write()     # a finished run can be extended (a later time.end)
        except SimulationError as exc:
            log(comm, f"stopped: {exc}")
            writer.record_error(exc.step, str(exc))
            status, code = "failed", 1
    if signum:
        writer.record_interrupt(sim.state.step, signal_name(signum))
        status, code = "interrupted", 128 + signum
    status = writer.close(status)
    wall = time.perf_counter() - t_start
    traversal = sim.contact.traversal_summary()      # collective
    if signum:
        log(comm, f"interrupted by {signal_name(signum)} after step {sim.state.step} "
                  f"(t = {sim.state.t:g} s): go on with --resume {os.path.abspath(path)}")
    elif not quiet:
        log(comm, f"stage times (rank 0):\n{sim.pipeline.summary()}")
        if traversal:
            log(comm, traversal)
        if sim.energy_warnings:
            log(comm, f"warning: {sim.energy_warnings} accepted steps above the energy guard's "
                      f"bound (time.energy_guard: false); the first is recorded in the result")
        if sim.limiter_unconverged_steps:
            log(comm, f"warning: strain limiting did not reach its bound in "
                      f"{sim.limiter_unconverged_steps} steps (strain_limiting.passes = "
                      f"{cfg.strain_limiting.passes}; limited_strain in the diagnostics)")
        log(comm, f"{status} in {wall:.2f} s: {os.path.abspath(path)} "
                  f"(+ {os.path.splitext(os.path.basename(path))[0]}.xdmf for ParaView)")
    _previews(cfg, comm, path, quiet=bool(signum))
    sim.destroy()
    return code


def drape(cfg, comm, *, output=None, cmdline_options=None, quiet=False) -> int:
    """``distcloth drape``: relax to the rest state (Volino and Magnenat-Thalmann
    2007); a frame every ``drape.frame_every`` iterations and the last; frame
    'time' is the iteration.  SIGTERM or SIGINT ends it after the iteration
    (status 'interrupted'); a relaxation has no checkpoint: it starts again.
    A cloth that can come to no rest (Relaxation.no_rest_state) stops with
    status 'no_rest_state', the cause, and exit status 3."""
    t_start = time.perf_counter()
    code = _agree_config(comm, refuse_moving_grips(cfg))
    if code:
        return code
    sim, code = setup(cfg, comm, cmdline_options=cmdline_options, quiet=quiet)
    if code:
        return code
    for term in sim.terms:         # a drape relaxes under the loads' full values
        if term.name == "force:loads":
            term.at_time(math.inf)
    spec = cfg.drape
    path = output or cfg.output.file
    sim, code, _ = sew_if_needed(sim, cfg, comm, path, quiet=quiet,
                                 cmdline_options=cmdline_options)
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
    status, code, k, signum = "completed", 0, 0, 0
    with Interrupts(comm.rank) as interrupts:
        try:
            for k in range(1, spec.max_iterations + 1):
                diag = relax.iterate()
                times, calls = sim.pipeline.take_step_counters()
                writer.write_step(k, float(k), diag, times, calls)
                done = drape_converged(diag, spec)
                stuck = None if done else relax.no_rest_state()
                signum = int(comm.max(np.array([float(interrupts.pending(k))]))[0])
                if done or stuck or signum or k % spec.frame_every == 0 \
                        or k == spec.max_iterations:
                    writer.write_frame(k, float(k), sim.owned_positions(), body_time=sim.state.t,
                                       fields=sim.frame_fields())
                bar.update(k, float(k))
                if stuck:
                    raise NoRestState(k, stuck)
                if done or signum:
                    break
            else:
                raise SimulationError(k, f"drape did not converge in {spec.max_iterations} "
                                         f"iterations (residual {diag['residual']:.3g} > "
                                         f"{spec.tolerance:g})")
        except SimulationError as exc:
            log(comm, f"stopped: {exc}")
            status, code = ("no_rest_state", 3) if isinstance(exc, NoRestState) else ("failed", 1)
            writer.record_error(exc.step, str(exc), status)
    if signum:
        writer.record_interrupt(k, signal_name(signum))
        status, code = "interrupted", 128 + signum
        log(comm, f"interrupted by {signal_name(signum)} after iteration {k}: a drape has no "
                  f"checkpoint, run it again to finish")
    writer.close(status)
    _previews(cfg, comm, path, quiet=bool(signum))
    if code == 0:
        log(comm, f"converged in {k} iterations ({relax.stops} stops), residual "
                  f"{diag['residual']:.3g}, {time.perf_counter() - t_start:.2f} s: {os.path.abspath(path)}")
    sim.destroy()
    return code


def _previews(cfg, comm, path, quiet=False):
    if cfg.output.preview and comm.rank == 0:
        try:
            # matplotlib takes a second to import: only runs that draw pay for it
            from .io.preview import write_previews
            for p in write_previews(path):
                if not quiet:
                    log(comm, f"preview: {os.path.abspath(p)}")
        except Exception as exc:   # a picture must never turn a finished run into a failure
            log(comm, f"preview failed: {exc}")
