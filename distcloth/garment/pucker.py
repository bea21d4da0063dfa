"""Seam pucker: the waves a shrunk seam raises along itself (EG07 tutorial,
Part 2 §1: a seam sewn shorter than the fabric it joins makes the fabric
buckle along it).  The benchmark is two rectangles sewn along a straight
seam, lying in a plane without gravity; ``seam_waves`` measures the
out-of-plane waves along the seam line.
"""
from __future__ import annotations

import numpy as np


def pucker_pattern(length: float = 0.3, width: float = 0.12) -> dict:
    """Two rectangles ``length`` along the seam, ``width`` across, touching
    along the seam (compact form, metres)."""
    rect = [[0.0, 0.0], [width, 0.0], [width, length], [0.0, length]]
    return {"units_in_meter": 1, "panels": {
        "left": {"vertices": rect},
        "right": {"vertices": rect, "translation": [width, 0.0, 0.0]}},
        "seams": [["left:1", "right:3"]]}


def pucker_scene(pattern_file: str, shrinkage: float, output: str, *, edge: float = 0.01,
                 end: float = 1.0, stretch: float = 20.0) -> dict:
    """The scene: no gravity, FE cotton-like membrane, dihedral bending, a
    seam strip ``stretch`` times the fabric's modulus shortened by
    ``shrinkage``; a 0.1 mm seeded noise breaks the flat start's symmetry."""
    return {
        "scene": f"pucker_{shrinkage:g}",
        "cloth": [{"name": "panels",
                   "mesh": {"pattern": pattern_file, "edge_length": edge, "up_axis": "z"},
                   "material": {"model": "fem", "density": 0.15, "stretch": 500.0,
                                "bending": 1e-5, "damping": 0.002, "bending_model": "dihedral"},
                   "thickness": 0.001, "start_noise": {"amplitude": 1e-4, "seed": 1}}],
        "effects": ["membrane", "bending", "damping"],
        "time": {"end": end, "step": 0.005, "integrator": "backward_euler"},
        "garment": {"seams": {"shrinkage": shrinkage, "stretch": stretch}},
        "output": {"file": output, "every": end, "preview": False}}


def seam_waves(positions: np.ndarray, seam: np.ndarray) -> tuple[float, float, int]:
    """(amplitude, wavelength, half-waves) of the out-of-plane (z) profile
    along the seam vertices ``seam`` (ordered along the seam): amplitude half
    the peak-to-peak of z less its straight-line trend, wavelength twice the
    mean distance between sign changes (inf without one)."""
    p = positions[seam]
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p[:, :2], axis=0), axis=1))])
    z = p[:, 2] - np.polyval(np.polyfit(s, p[:, 2], 1), s)
    amplitude = 0.5 * float(z.max() - z.min())
    change = np.flatnonzero(np.sign(z[1:]) * np.sign(z[:-1]) < 0)
    if change.size < 2:
        return amplitude, float("inf"), int(change.size)
    # the zero crossings by linear interpolation
    at = s[change] + (s[change + 1] - s[change]) * z[change] / (z[change] - z[change + 1])
    return amplitude, 2.0 * float(np.mean(np.diff(at))), int(change.size)
