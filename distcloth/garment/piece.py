"""A sewing pattern as one cloth piece: its panels meshed, placed in the
scene's frame, each triangle's grain, and the pairs its stitches sew."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..rotations import Y_UP_TO_Z_UP
from .mesh import GarmentMesh, mesh_pattern
from .pattern import load_pattern


@dataclass
class PatternPiece:
    mesh: GarmentMesh
    positions: np.ndarray          # (n, 3) placed in the scene
    triangles: np.ndarray          # (nt, 3)
    triangle_weft: np.ndarray      # (nt, 3) unit, in the placed panel's plane
    triangle_panel: np.ndarray     # (nt,) index of the panel of each triangle
    stitch_pairs: np.ndarray       # (k, 2) vertices sewn together (a dart's tip to itself)
    stitch_index: np.ndarray       # (k,) the stitch of each pair
    stitches: tuple[np.ndarray, ...]   # per stitch: its (k_i, 2) pairs in seam order


def frame_of(up_axis: str) -> np.ndarray:
    """The rotation taking the pattern's frame to the scene's (z up): a y-up
    pattern (GarmentCode's frame) is turned as a y-up mesh collider is."""
    return Y_UP_TO_Z_UP if up_axis == "y" else np.eye(3)


def pattern_piece(path: str, edge_length: float, up_axis: str = "y",
                  translation=(0.0, 0.0, 0.0)) -> PatternPiece:
    """Read and mesh a pattern file and place it: the pattern's own
    placement, turned z-up if the pattern is y-up, then moved by
    ``translation``.  Raises PatternError / MeshError."""
    mesh = mesh_pattern(load_pattern(path), edge_length)
    turn = frame_of(up_axis)
    positions = mesh.positions @ turn.T + np.asarray(translation, dtype=np.float64)
    triangles = mesh.triangles.astype(np.int64)
    counts = [p.triangles.shape[0] for p in mesh.panels]
    triangle_panel = np.repeat(np.arange(len(counts)), counts)
    # the grain is a direction of the panel's 2D frame: the panel's rotation
    # takes it into 3D (translations do not move directions)
    grain = np.stack([p.panel.rotation @ np.array([p.panel.grain[0], p.panel.grain[1], 0.0])
                      for p in mesh.panels]) @ turn.T
    stitches = tuple(np.asarray(s.pairs, dtype=np.int64) for s in mesh.seams)
    pairs = np.concatenate(stitches) if stitches else np.zeros((0, 2), np.int64)
    index = (np.concatenate([np.full(s.shape[0], i) for i, s in enumerate(stitches)])
             if stitches else np.zeros(0, np.int64))
    return PatternPiece(mesh, positions, triangles, grain[triangle_panel], triangle_panel,
                        pairs, index.astype(np.int64), stitches)
