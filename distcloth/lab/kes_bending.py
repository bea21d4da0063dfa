"""KES-FB2 pure bending (Kawabata 1980): a specimen held by two jaws 1 cm
apart is bent to curvatures up to 2.5 /cm, the moving jaw travelling on the
circle that keeps the curvature uniform; the lab reports the moment per
width against the curvature and Kawabata's bending rigidity B, the slope
between 0.5 and 1.5 /cm (gf cm^2/cm).

Each jaw holds two vertex columns, h/2 each side of its line, so it fixes
the slope there (held on and behind the line, the strip would bend as if
clamped h/2 behind each jaw, lengthening the bent part by h: B 1/(1 + h/l)
too low; the Peirce test has the same clamp, peirce.py), and the moving jaw
is placed on the arc of curvature K with its tangent turned by K l.
Between jaws that hold the ends of a circular arc the equilibrium of a
uniform strip is that arc, under a constant moment M = B K per width
(pure bending, no shear force): the closed-form answer.  The moment comes
from the energy the strip stores, M = dE/dK / (width * l), by central
differences over the sweep (the instrument measures the jaw's torque; the
two agree for an elastic specimen).  Gravity is off: the instrument holds
the specimen upright so that its weight does not bend it.  The width is 2 cm
rather than 20 (per-width quantities do not depend on it).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from . import quasistatic

GAP = 0.01                         # m between the jaws
WIDTH = 0.02                       # m
MAX_CURVATURE = 250.0              # 1/m (2.5 /cm)
FIT = (50.0, 150.0)                # 1/m: Kawabata's B is the slope here
CELLS = {"coarse": 8, "standard": 16}
INCREMENTS = 25


@dataclass
class BendingResult:
    curvature: list = field(default_factory=list)    # 1/m
    moment: list = field(default_factory=list)       # N m / m
    b: float = float("nan")                          # N m
    b_law: float = float("nan")
    wall: float = 0.0
    reason: str = ""


def jaw_path(curvatures: np.ndarray) -> tuple[list, list]:
    """Translations and rotation vectors of the moving jaw (its line at x = GAP
    in the flat specimen, turning about y) that put it at the end of the arc
    of curvature K starting flat at x = 0, bending towards +z."""
    K = np.asarray(curvatures, dtype=np.float64)
    angle = K * GAP
    safe = np.where(K > 0.0, K, 1.0)
    x = np.where(K > 0.0, np.sin(angle) / safe, GAP)
    z = np.where(K > 0.0, (1.0 - np.cos(angle)) / safe, 0.0)
    translations = [[float(a - GAP), 0.0, float(b)] for a, b in zip(x, z)]
    rotations = [[0.0, float(-a), 0.0] for a in angle]     # x towards +z: about -y
    return translations, rotations


def scene(material: dict, resolution: str) -> dict:
    n = CELLS[resolution]
    h = GAP / n
    ny = max(3, int(round(WIDTH / h)) + 1)
    # columns at -h/2 + k h, k = 0 .. n + 1: two held by each jaw
    K = np.linspace(0.0, MAX_CURVATURE, INCREMENTS + 1)
    translations, rotations = jaw_path(K)
    return {
        "scene": "lab_kes_bending",
        "cloth": [{"name": "specimen",
                   "mesh": {"grid": {"size": [GAP + h, WIDTH], "resolution": [n + 2, ny],
                                     "pattern": "alternating"},
                            "center": [GAP / 2, 0.0, 0.0]},
                   "pins": [{"box": {"min": [-1.0, -1.0, -1.0], "max": [h / 2 + 1e-9, 1.0, 1.0]}},
                            {"box": {"min": [GAP - h / 2 - 1e-9, -1.0, -1.0],
                                     "max": [1.0, 1.0, 1.0]},
                             "motion": {"times": quasistatic.keyframes(K),
                                        "translations": translations, "rotations": rotations,
                                        "center": [GAP, 0.0, 0.0]}}],
                   "material": dict(material)}],
        "effects": ["membrane", "bending"],
        "time": quasistatic.time_settings(INCREMENTS),
        "solver": quasistatic.SOLVER,
        "output": {"file": "unused.h5", "every": quasistatic.STEP * INCREMENTS,
                   "preview": False},
    }


def run(material: dict, base_dir: str, comm, *, resolution: str = "standard") -> BendingResult:
    """Collective."""
    t0 = time.perf_counter()
    res = BendingResult()
    raw = scene(material, resolution)
    cfg, res.reason = quasistatic.checked(raw, "lab_kes_bending", base_dir, comm)
    if cfg is None:
        return res
    res.b_law = cfg.cloth[0].material.bending
    rows, res.reason = quasistatic.sweep(raw, "lab_kes_bending", base_dir, comm, INCREMENTS)
    K = np.array([0.0] + [MAX_CURVATURE * r["increment"] / INCREMENTS for r in rows])
    E = np.array([0.0] + [r["elastic_energy"] for r in rows])
    if len(K) >= 3:
        M = np.gradient(E, K) / (WIDTH * GAP)
        res.curvature, res.moment = K.tolist(), M.tolist()
        fit = (K >= FIT[0] - 1e-9) & (K <= FIT[1] + 1e-9)
        if np.count_nonzero(fit) >= 2:
            res.b = float(np.polyfit(K[fit], M[fit], 1)[0])
    res.wall = time.perf_counter() - t0
    return res
