"""Cusick drape test (Cusick 1968; ISO 9073-9 geometry): a 30 cm disc of
fabric clamped between two 18 cm discs, hanging under its own weight; the
drape coefficient is the fraction of the hanging annulus still covered by
the shadow, DC = (A_shadow - A_disc) / (A_specimen - A_disc).

No closed form gives DC; what the test can check is its limits (a stiff
specimen stays flat, DC -> 1; a limp one hangs, DC small) and, for a
fabric with a published measurement, the measured value.

The specimen starts flat with a seeded out-of-plane noise (a real
specimen is never perfectly flat; a perfect disc would hang in an
axisymmetric state that folds do not form from), and is relaxed to rest
with stop-and-go draping (Volino and Magnenat-Thalmann 2007 §2.1).
"""
from __future__ import annotations

import os
import tempfile
import time
from dataclasses import dataclass

import numpy as np

from ..inprocess import build_simulation
from ..integrate.drape import Relaxation, drape_converged, relax_to_rest
from ..simulation import SimulationError
from .shadow import drape_coefficient, node_count, shadow_mask
from .specimens import disc, write_obj

SPECIMEN_RADIUS = 0.15      # m: ISO 9073-9, 30 cm specimen
CLAMP_RADIUS = 0.09         # m: on an 18 cm supporting disc
PIXEL = 5.0e-4              # m: shadow raster
NOISE = 5.0e-4              # m: start noise, standard deviation along the normal
SPACING = {"coarse": 0.01, "standard": 0.005}


@dataclass
class CusickResult:
    spacing: float
    vertices: int
    drape_coefficient: float
    nodes: int
    iterations: int
    residual: float
    converged: bool
    wall: float
    reason: str = ""        # why it did not run, or did not converge
    shadow: np.ndarray | None = None    # the shadow's cell mask, PIXEL cells, centred


def scene(material: dict, mesh_file: str, clamped: np.ndarray, *, tolerance: float,
          max_iterations: int) -> dict:
    return {
        "scene": "lab_cusick",
        "cloth": [{"name": "specimen",
                   "mesh": {"file": mesh_file, "center": [0.0, 0.0, 1.0], "weld": False},
                   "pins": [{"indices": [int(i) for i in clamped]}],
                   "material": dict(material),
                   "start_noise": {"amplitude": NOISE, "seed": 1}}],
        "effects": ["gravity", "membrane", "bending"],
        "time": {"end": 1.0, "step": 0.01, "integrator": "backward_euler"},
        "drape": {"method": "stop_and_go", "tolerance": tolerance,
                  "max_iterations": max_iterations},
        "output": {"file": "unused.h5", "every": 1.0, "preview": False},
    }


def shadow_area(sim) -> tuple[float, np.ndarray]:
    """Collective: the specimen's shadow area and pixel mask, from every rank's
    own triangles."""
    model, lay = sim.model, sim.layout
    tri = np.asarray(model.triangles, dtype=np.int64)
    to_local = lay.input_to_local()
    mine = lay.part[tri[:, 0]] == lay.rank
    local = to_local[tri[mine]]
    counted = sim.comm.sum(np.array([float(np.all(local >= 0, axis=1).sum())]))[0]
    if counted != len(tri):
        raise RuntimeError("a rank lacks the vertices of a triangle it owns")
    sim.ghosts.update(sim.state.x)
    mask = shadow_mask(sim.state.x[:, :2], local, SPECIMEN_RADIUS + 2 * PIXEL, PIXEL)
    union = sim.comm.max(mask.ravel()).reshape(mask.shape)
    return float(union.sum()) * PIXEL ** 2, union


def run(material: dict, base_dir: str, comm, *, resolution: str | float = "standard",
        tolerance: float = 1.0e-3, max_iterations: int = 3000) -> CusickResult:
    """Collective: drape the specimen to rest and measure it; ``resolution``
    names a mesh spacing or gives it in m."""
    t0 = time.perf_counter()
    h = SPACING[resolution] if isinstance(resolution, str) else float(resolution)
    points, triangles = disc(SPECIMEN_RADIUS, CLAMP_RADIUS, h)
    clamped = np.flatnonzero(np.hypot(points[:, 0], points[:, 1]) <= CLAMP_RADIUS * (1 + 1e-9))
    res = CusickResult(h, len(points), float("nan"), 0, 0, float("nan"), False, 0.0)
    with tempfile.TemporaryDirectory(prefix="distcloth-lab-") as tmp:
        # every rank writes the same mesh for itself: no shared file system needed
        path = os.path.join(tmp, "cusick_specimen.obj")
        write_obj(path, points, triangles)
        raw = scene(material, path, clamped, tolerance=tolerance, max_iterations=max_iterations)
        sim, _, err = build_simulation(raw, "lab_cusick", comm, base_dir=base_dir)
    if err:
        res.reason, res.wall = err, time.perf_counter() - t0
        return res
    try:
        spec = sim.cfg.drape
        res.iterations, diag, _, stuck, _ = relax_to_rest(Relaxation(sim, spec), max_iterations)
        res.residual = float(diag["residual"])
        res.converged = drape_converged(diag, spec)
        if not res.converged:
            res.reason = stuck or f"not at rest after {max_iterations} iterations"
        area, union = shadow_area(sim)
        res.drape_coefficient = drape_coefficient(area, SPECIMEN_RADIUS, CLAMP_RADIUS)
        res.nodes = node_count(union, PIXEL, CLAMP_RADIUS)
        res.shadow = union
    except SimulationError as exc:
        res.reason = str(exc)
    finally:
        sim.destroy()
    res.wall = time.perf_counter() - t0
    return res
