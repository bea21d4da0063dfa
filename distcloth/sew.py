"""The sewing phase of a garment scene, and the weld that ends it.

The panels start where the pattern places them; stitch springs (the
``force:sewing`` stage) pull every stitched pair together over
``garment.sewing.duration`` while the bodies and the panels themselves
collide.  When every pair is within ``garment.sewing.tolerance`` the
stitches are welded (garment/weld.py) and the run goes on with a new
Simulation on the welded model: the topology changes once, so the model is
partitioned again, and its result file starts afresh.  The sewing phase has
its own result file (``<output>_sewing.h5``, the panels' mesh), and the
main file maps pattern vertices to simulated ones (``/garment``).
"""
from __future__ import annotations

import os

import numpy as np

from .config.schema import ConfigError
from .garment.weld import SeamMaterial, weld_model
from .io.console import Progress, log
from .scene.skin_follow import add_skin_grips
from .simulation import Simulation, SimulationError


def sewing_path(path: str) -> str:
    stem, ext = os.path.splitext(path)
    return f"{stem}_sewing{ext}"


def sew(sim: Simulation, cfg, comm, path: str, writer_factory, *, quiet=False,
        progress=True, force=False, cmdline_options=None) -> tuple[Simulation, dict]:
    """Run the sewing phase of ``sim`` into the sewing file and weld.  Returns
    the welded Simulation (``sim`` destroyed) and figures of the phase.
    Raises SimulationError (collectively) when the seams do not close or the
    weld fails; the sewing file then records the error."""
    spec = cfg.garment.sewing
    h = cfg.time.step
    every = max(1, int(round(cfg.output.every / h)))
    max_steps = int(np.ceil(spec.max_duration / h - 1e-9))
    writer = writer_factory(sim, sewing_path(path), sim.diagnostic_names() + ["stitch_gap"],
                            {"phase": "sewing", "sewing_duration": spec.duration,
                             "sewing_tolerance": spec.tolerance})
    log(comm, f"sewing {sim.model.stitch_pairs.shape[0]} stitched pairs "
              f"(widest {1e3 * sim.largest_stitch_gap():.1f} mm) over {spec.duration:g} s into "
              f"{os.path.abspath(sewing_path(path))}")
    sim.pipeline.run("output", writer)
    sim.pipeline.take_step_counters()
    bar = Progress(comm, max_steps, enabled=progress and not quiet)
    gap = np.inf
    try:
        for k in range(1, max_steps + 1):
            diag = sim.step()
            gap = sim.largest_stitch_gap()
            diag["stitch_gap"] = gap
            times, calls = sim.pipeline.take_step_counters()
            writer.write_step(sim.state.step, sim.state.t, diag, times, calls)
            closed = gap <= spec.tolerance
            if k % every == 0 or closed:
                sim.pipeline.run("output", writer)
            if bar:
                bar.update(k, sim.state.t)
            if closed:
                break
        else:
            raise SimulationError(sim.state.step, _not_closed(sim, spec))
    except SimulationError as exc:
        writer.record_error(exc.step, f"sewing: {exc}")
        writer.close("failed")
        raise
    writer.close("completed")
    rows = weld_rows(sim, comm)
    # the weld's input: a checkpoint keeps it to rebuild the welded garment
    figures = {"sewing_time": sim.state.t, "sewing_steps": sim.state.step, "stitch_gap": gap,
               "weld": (rows, sim.state.t, sim.state.step)}
    welded = weld(sim, cfg, comm, quiet=quiet, force=force, cmdline_options=cmdline_options,
                  rows=rows)
    return welded, figures


def _not_closed(sim, spec) -> str:
    gaps = sim.stitch_gaps()
    worst = int(np.argmax(gaps))
    stitch = int(sim.model.stitch_index[worst])
    open_count = int(np.count_nonzero(gaps > spec.tolerance))
    return (f"sewing: the seams did not close in garment.sewing.max_duration = "
            f"{spec.max_duration:g} s: {open_count} stitched pairs wider than "
            f"{1e3 * spec.tolerance:g} mm, the widest {1e3 * gaps[worst]:.1f} mm (stitch "
            f"{stitch}, vertices {sim.model.stitch_pairs[worst].tolist()})")


def _per_vertex(cfg, model, value) -> np.ndarray:
    return model.per_vertex([float(value(spec.material)) for spec in cfg.cloth])


def weld_rows(sim: Simulation, comm) -> np.ndarray:
    """(n, 6) positions and velocities of every pattern vertex, in input order,
    on every rank (one all-gather): what the weld is made from."""
    n = sim.n_owned
    return comm.allgather_rows(sim.layout.owned_input,
                               np.hstack([sim.state.x[:n], sim.state.v[:n]]),
                               sim.model.num_vertices)


def welded_model(cfg, model, rows: np.ndarray, t: float):
    """The welded model of the pattern ``model`` sewn to ``rows`` (weld_rows)
    at time t, its skin-following regions attached then; ValueError if the
    weld fails, ConfigError if a region does not reach its body (the same on
    every rank)."""
    seams = cfg.garment.seams
    material = SeamMaterial(seams.stretch, seams.width, seams.bending, seams.shrinkage)
    welded = weld_model(model, rows[:, :3], rows[:, 3:], material,
                        _per_vertex(cfg, model, lambda m: m.orthotropic()[0]
                                    if m.model == "fem" else m.stretch),
                        _per_vertex(cfg, model, lambda m: m.bending),
                        _per_vertex(cfg, model, lambda m: m.damping))
    welded.follow_regions = model.follow_regions
    add_skin_grips(cfg, welded, t)
    return welded


def weld(sim: Simulation, cfg, comm, *, quiet=False, force=False,
         cmdline_options=None, rows=None) -> Simulation:
    """The welded Simulation of a sewn ``sim`` (collective): one all-gather of
    the state (unless ``rows`` has it), the same new model built on every
    rank, partitioned again."""
    model = sim.model
    if rows is None:
        rows = weld_rows(sim, comm)
    t, step = sim.state.t, sim.state.step
    error, new_model = None, None
    try:
        new_model = welded_model(cfg, model, rows, t)
    except ValueError as exc:       # the same on every rank: the model is replicated
        error = f"welding the sewn garment failed: {exc}"
    except ConfigError as exc:      # a skin-following region out of reach: the same everywhere
        error = f"the welded garment cannot be simulated: {exc}"
    sim.destroy()
    if error is not None:
        raise SimulationError(step, error)
    try:
        welded = Simulation(cfg, new_model, comm, quiet=quiet, force_explicit=force,
                            cmdline_options=cmdline_options)
        welded.prepare()
    except ConfigError as exc:
        raise SimulationError(step, f"the welded garment cannot be simulated: {exc}") from None
    welded.state.t, welded.state.step = t, step
    log(comm, f"welded at t = {t:g} s: {model.num_vertices} pattern vertices -> "
              f"{new_model.num_vertices} ({new_model.triangles.shape[0]} triangles, "
              f"{new_model.seam_lines.shape[0]} seam edges)")
    return welded


def garment_arrays(model) -> dict:
    """The main result file's static datasets from the model: the garment's
    /garment maps and the mesh's UVs (/mesh/uv, /mesh/uv_index)."""
    uvs = ({} if model.uv is None else
           {"mesh/uv": model.uv.astype(np.float64), "mesh/uv_index": model.uv_index.astype(np.int64)})
    if model.pattern_vertex is None or model.seam_lines is None:
        return uvs
    return {**uvs, "garment/pattern_vertex": model.pattern_vertex.astype(np.int64),
            "garment/seam_lines": model.seam_lines.astype(np.int64)}
