"""KES-FB1 shear test (Kawabata 1980): the tensile tester's specimen (20 cm
along the jaws, 5 cm between them) sheared by moving one jaw along its own
line, to a shear angle of 8 degrees; the lab reports the shear force per
length of jaw against the angle and Kawabata's shear stiffness G, the slope
between 0.5 and 2.5 degrees (gf/cm/degree).

The instrument holds the specimen under a small tension (10 gf/cm) so that
it does not buckle; a flat simulated specimen with no gravity stays flat,
so the lab shears it without one.  The material law's answer is simple
shear, x -> (x, y + x tan a): with Green strain (stvk) E_xy = tan a / 2 and
E_xx = tan^2 a / 2 (the fibres across the gap are stretched, the jaws keep
the gap), so the force per length of jaw is P_yx = G tan a + Q11 tan^3 a / 2
(Q11 = E / (1 - nu_weft nu_warp)), fitted over the same angles as the
simulation; with corotated strain it is G tan a to first order.  The free
side edges carry no shear stress, which simple shear would need: their
effect on the 4:1 specimen is measured by the tests (tests/test_lab.py).
Kawabata's hysteresis 2HG needs friction the model does not have.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from . import quasistatic
from .kes_tensile import CELLS, GAUGE, WIDTH, direction_material
from .units import GF_PER_CM

MAX_ANGLE = 8.0                       # degrees
FIT = (0.5, 2.5)                      # degrees: Kawabata's G is the slope here
INCREMENTS = 16


@dataclass
class ShearResult:
    angle: list = field(default_factory=list)        # degrees
    force: list = field(default_factory=list)        # N/m of jaw
    g: float = float("nan")                          # N/m per radian
    g_law: float = float("nan")
    wall: float = 0.0
    reason: str = ""


def scene(material: dict, resolution: str) -> dict:
    n = CELLS[resolution]
    ny = int(round(WIDTH / (GAUGE / n))) + 1
    shift = GAUGE * np.tan(np.radians(np.linspace(0.0, MAX_ANGLE, INCREMENTS + 1)))
    return {
        "scene": "lab_kes_shear",
        "cloth": [{"name": "specimen",
                   "mesh": {"grid": {"size": [GAUGE, WIDTH], "resolution": [n + 1, ny]},
                            "center": [GAUGE / 2, 0.0, 0.0]},
                   "pins": [{"edge": "left"},
                            {"edge": "right",
                             "motion": {"times": quasistatic.keyframes(shift),
                                        "translations": [[0.0, float(d), 0.0]
                                                         for d in shift]}}],
                   "material": direction_material(material, "weft")}],
        "effects": ["membrane", "bending"],
        "time": quasistatic.time_settings(INCREMENTS),
        "solver": quasistatic.SOLVER,
        "output": {"file": "unused.h5", "every": quasistatic.STEP * INCREMENTS,
                   "preview": False, "reactions": True},
    }


def run(material: dict, base_dir: str, comm, *, resolution: str = "standard") -> ShearResult:
    """Collective."""
    t0 = time.perf_counter()
    res = ShearResult()
    raw = scene(material, resolution)
    cfg, res.reason = quasistatic.checked(raw, "lab_kes_shear", base_dir, comm)
    if cfg is None:
        return res
    mat = cfg.cloth[0].material
    rows, res.reason = quasistatic.sweep(raw, "lab_kes_shear", base_dir, comm, INCREMENTS)
    res.angle = [MAX_ANGLE * r["increment"] / INCREMENTS for r in rows]
    res.force = [r["reaction_1_y"] / WIDTH for r in rows]
    a = np.array([0.0] + res.angle)
    res.g = _slope(a, np.array([0.0] + res.force))
    res.g_law = _slope(a, law_force(mat, a))
    if np.isnan(res.g) and not res.reason:
        res.reason = "too few increments between 0.5 and 2.5 degrees"
    res.wall = time.perf_counter() - t0
    return res


def law_force(mat, angle_degrees: np.ndarray) -> np.ndarray:
    """Force per length of jaw (N/m) of the material law in simple shear."""
    t = np.tan(np.radians(angle_degrees))
    if mat.model != "fem":
        return mat.shear_stiffness * t
    e_weft, _, nu_weft, nu_warp, g = mat.orthotropic()
    if mat.strain != "stvk":
        return g * t
    return g * t + e_weft / (1.0 - nu_weft * nu_warp) * t ** 3 / 2.0


def _slope(angle_degrees: np.ndarray, force: np.ndarray) -> float:
    """Kawabata's fit: the slope (per radian) over FIT, NaN without two points."""
    fit = (angle_degrees >= FIT[0] - 1e-9) & (angle_degrees <= FIT[1] + 1e-9)
    if np.count_nonzero(fit) < 2:
        return float("nan")
    return float(np.polyfit(np.radians(angle_degrees[fit]), force[fit], 1)[0])


def kawabata_g(g_per_radian: float) -> float:
    """N/m per radian -> gf/cm/degree."""
    return g_per_radian * math.pi / 180.0 / GF_PER_CM
