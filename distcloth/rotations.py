"""Rotations shared by everything that places geometry (pieces, bodies,
pattern panels): angles in degrees about the fixed axes x, then y, then z."""
from __future__ import annotations

import numpy as np


def rotation_matrix(degrees) -> np.ndarray:
    """R = Rz(c) Ry(b) Rx(a) for angles (a, b, c) in degrees."""
    ax, ay, az = np.radians(np.asarray(degrees, dtype=np.float64))
    cx, sx, cy, sy, cz, sz = np.cos(ax), np.sin(ax), np.cos(ay), np.sin(ay), np.cos(az), np.sin(az)
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cx, -sx], [0.0, sx, cx]])
    ry = np.array([[cy, 0.0, sy], [0.0, 1.0, 0.0], [-sy, 0.0, cy]])
    rz = np.array([[cz, -sz, 0.0], [sz, cz, 0.0], [0.0, 0.0, 1.0]])
    return rz @ ry @ rx


# (x, y, z) -> (x, -z, y): +90 degrees about x, so a y-up file's +y becomes +z.
# Written out rather than rotation_matrix((90, 0, 0)) so the turn is exact
# (cos 90° is 6e-17 in floating point): a turned file keeps its coordinates' bits.
Y_UP_TO_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
