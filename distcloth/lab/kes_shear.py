"""KES-FB1 shear test (Kawabata 1980): the tensile tester's specimen (20 cm
along the jaws, 5 cm between them) sheared by moving one jaw along its own
line, to a shear angle of 8 degrees; the lab reports the shear force per
length of jaw against the angle and Kawabata's shear stiffness G, the slope
between 0.5 and 2.5 degrees (gf/cm/degree).

The instrument holds the specimen under a small tension (10 gf/cm) so that
it does not buckle; a flat simulated specimen with no gravity stays flat,
so the lab shears it without one.  The material law's answer is simple
shear, force per length G_law * tan(angle) for small angles.  The jaws'
simple shear leaves a shear stress on the free side edges that a real
specimen cannot carry: the ends relax, and the measured G is a few per
cent below G_law for the 4:1 specimen (the test in tests/test_lab.py
bounds it).  Kawabata's hysteresis 2HG needs friction the model does not
have.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from ..config.load import config_from_dict
from ..inprocess import agreed
from . import quasistatic
from .kes_tensile import CELLS, GAUGE, WIDTH, _direction_material
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
                   "material": _direction_material(material, "weft")}],
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
    cfg, err = agreed(comm, lambda: config_from_dict(raw, base_dir, "lab_kes_shear"))
    if err:
        res.reason, res.wall = err, time.perf_counter() - t0
        return res
    mat = cfg.cloth[0].material
    res.g_law = mat.orthotropic()[4] if mat.model == "fem" else mat.shear_stiffness
    rows, res.reason = quasistatic.sweep(raw, "lab_kes_shear", base_dir, comm, INCREMENTS)
    res.angle = [MAX_ANGLE * r["increment"] / INCREMENTS for r in rows]
    res.force = [r["reaction_1_y"] / WIDTH for r in rows]
    a = np.array([0.0] + res.angle)
    f = np.array([0.0] + res.force)
    fit = (a >= FIT[0] - 1e-9) & (a <= FIT[1] + 1e-9)
    if np.count_nonzero(fit) >= 2:
        res.g = float(np.polyfit(np.radians(a[fit]), f[fit], 1)[0])
    elif not res.reason:
        res.reason = "too few increments between 0.5 and 2.5 degrees"
    res.wall = time.perf_counter() - t0
    return res


def kawabata_g(g_per_radian: float) -> float:
    """N/m per radian -> gf/cm/degree."""
    return g_per_radian * math.pi / 180.0 / GF_PER_CM
