"""Generate configs/meshes/torso.obj: a closed mannequin-like torso for the
"cloth dropped on a static mesh body" scenes (Vassilev et al. 2001 §4 drape cloth on
a body; this is a stand-in body, not a scan).

Construction (no unions, so watertight by construction): a stack of
elliptical rings z -> (semi-axis a(z) across the shoulders along x,
semi-axis b(z) front-to-back along y) through key cross-sections of hips,
waist, chest, shoulders and neck, interpolated monotonically (PCHIP) along
the profile's arc length so the rings are evenly spaced also where the
shoulders roll over into the neck; the bottom (hips) and top (neck) are
closed by shallow elliptical domes ending at a pole vertex.  Triangles are
wound counter-clockwise seen from outside (outward normals).

Units metres, z up; the hips rest on z = 0, the neck ends at z = HEIGHT = 0.70
(heights of the key sections are scaled by 0.70/0.735 to get there); the
body is centred on the z axis.

    .venv/bin/python scripts/make_body_mesh.py [output.obj]
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from scipy.interpolate import PchipInterpolator

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from distcloth.scene.meshio import write_obj  # noqa: E402

# (z, a, b): height, half width (x), half depth (y), metres
KEY_SECTIONS = np.array([
    [0.000, 0.160, 0.115],   # bottom of the hips (start of the bottom dome)
    [0.080, 0.180, 0.130],   # hips
    [0.160, 0.165, 0.118],
    [0.250, 0.140, 0.100],   # waist
    [0.340, 0.155, 0.110],
    [0.420, 0.170, 0.120],   # chest
    [0.500, 0.190, 0.115],
    [0.555, 0.205, 0.105],   # shoulders
    [0.590, 0.175, 0.092],
    [0.615, 0.110, 0.075],   # top of the shoulders rolling over
    [0.630, 0.068, 0.062],   # neck base
    [0.680, 0.058, 0.056],   # neck
])
NECK_TOP = 0.700   # top of the neck before the final scaling
HEIGHT = 0.700     # hips (bottom pole) to neck (top pole), metres
N_AROUND = 48      # vertices per ring
N_RINGS = 36       # side rings from hips to neck
N_DOME = 4         # extra rings in each end dome


def profile_rings() -> np.ndarray:
    """(rings, 3) rows (z, a, b) from the bottom pole to the top pole (poles
    have a = b = 0)."""
    z, a, b = KEY_SECTIONS.T
    # arc length of the (z, a) profile as the parameter: even ring spacing
    s = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(z), np.diff(a)))])
    u = np.linspace(0.0, s[-1], N_RINGS)
    side = np.stack([PchipInterpolator(s, c)(u) for c in (z, a, b)], axis=1)
    # end domes: quarter ellipses of the given heights below/above the end rings
    phi = np.linspace(0.0, 0.5 * np.pi, N_DOME + 2)[1:]       # excludes the end ring itself
    bottom_h, top_h = 0.035, NECK_TOP - side[-1, 0]
    z0, a0, b0 = side[0]
    bottom = np.stack([z0 - bottom_h * np.sin(phi), a0 * np.cos(phi), b0 * np.cos(phi)], axis=1)
    z1, a1, b1 = side[-1]
    top = np.stack([z1 + top_h * np.sin(phi), a1 * np.cos(phi), b1 * np.cos(phi)], axis=1)
    rings = np.concatenate([bottom[::-1], side, top])
    rings[:, 0] -= rings[0, 0]                                # hips rest on z = 0
    rings[:, 0] *= HEIGHT / rings[-1, 0]
    rings[0, 1:] = rings[-1, 1:] = 0.0
    return rings


def build_mesh() -> tuple[np.ndarray, np.ndarray]:
    rings = profile_rings()
    inner = rings[1:-1]                                       # true rings (not poles)
    theta = 2.0 * np.pi * np.arange(N_AROUND) / N_AROUND
    ring_xyz = np.stack([inner[:, 1, None] * np.cos(theta)[None, :],
                         inner[:, 2, None] * np.sin(theta)[None, :],
                         np.repeat(inner[:, 0, None], N_AROUND, axis=1)], axis=2)
    n_rings = inner.shape[0]
    vertices = np.concatenate([[[0.0, 0.0, rings[0, 0]]], ring_xyz.reshape(-1, 3),
                               [[0.0, 0.0, rings[-1, 0]]]])
    bottom_pole, top_pole = 0, vertices.shape[0] - 1

    def idx(r, k):
        return 1 + r * N_AROUND + (k % N_AROUND)

    k = np.arange(N_AROUND)
    tris = [np.stack([np.full(N_AROUND, bottom_pole), idx(0, k + 1), idx(0, k)], axis=1)]
    for r in range(n_rings - 1):
        # theta runs counter-clockwise about +z and rings go up: (theta, up) is outward
        tris.append(np.stack([idx(r, k), idx(r, k + 1), idx(r + 1, k + 1)], axis=1))
        tris.append(np.stack([idx(r, k), idx(r + 1, k + 1), idx(r + 1, k)], axis=1))
    tris.append(np.stack([idx(n_rings - 1, k), idx(n_rings - 1, k + 1),
                          np.full(N_AROUND, top_pole)], axis=1))
    return vertices, np.concatenate(tris).astype(np.int64)


def check_closed(vertices: np.ndarray, triangles: np.ndarray) -> float:
    """Every directed edge once and its reverse once (watertight, consistently
    oriented); returns the signed volume (> 0: outward normals)."""
    edges = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
    keys = edges[:, 0] * vertices.shape[0] + edges[:, 1]
    reverse = edges[:, 1] * vertices.shape[0] + edges[:, 0]
    if np.unique(keys).shape[0] != keys.shape[0] or not np.isin(reverse, keys).all():
        raise RuntimeError("mesh is not watertight and consistently oriented")
    a, b, c = (vertices[triangles[:, i]] for i in range(3))
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def main(argv: list[str]) -> None:
    out = Path(argv[0]) if argv else ROOT / "configs" / "meshes" / "torso.obj"
    vertices, triangles = build_mesh()
    volume = check_closed(vertices, triangles)
    if not volume > 0:
        raise RuntimeError("mesh is inside out")
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    header = (f"Mannequin-like torso, hips to neck {hi[2] - lo[2]:.3f} m tall, z up, centred on the z axis,\n"
              f"hips resting on z = 0; closed, watertight, outward oriented "
              f"({vertices.shape[0]} vertices, {triangles.shape[0]} triangles, volume "
              f"{volume * 1e3:.2f} litres).\n"
              f"Generated by scripts/make_body_mesh.py; public domain (also usable under the "
              f"project's MIT licence).")
    write_obj(str(out), vertices, triangles, header=header)
    print(f"wrote {out}: {vertices.shape[0]} vertices, {triangles.shape[0]} triangles, "
          f"bbox {lo.round(3).tolist()} .. {hi.round(3).tolist()}, volume {volume:.5f} m^3")


if __name__ == "__main__":
    main(sys.argv[1:])
