"""The Model: everything about a cloth that stays fixed during a run.

Global arrays in *input order* (the order of the scene's pieces and their
vertices), the same on every rank.  Per-rank views (owned + ghost vertices,
local springs) live in :class:`distcloth.parallel.layout.LocalLayout`.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

# spring kinds (Vassilev et al. 2001 §2.2)
STRUCTURAL = 0
SHEAR = 1
FLEXION = 2


@dataclass
class PieceInfo:
    """Where one cloth piece sits in the global arrays."""
    name: str
    vertex_start: int
    vertex_stop: int
    triangle_start: int
    triangle_stop: int
    grid_resolution: tuple[int, int] | None = None   # (nu, nv) for grids


@dataclass
class Model:
    rest_positions: np.ndarray          # (n, 3) float64: initial = rest shape
    triangles: np.ndarray               # (nt, 3) int64
    vertex_mass: np.ndarray             # (n,) kg, lumped from areal density
    vertex_area: np.ndarray             # (n,) m^2 lumped: a quarter of each adjacent grid cell, or a third of each adjacent triangle of a mesh file
    spring_vertices: np.ndarray         # (ns, 2) int64
    spring_rest_length: np.ndarray      # (ns,) m
    spring_stiffness: np.ndarray        # (ns,) N/m
    spring_damping: np.ndarray          # (ns,) N*s/m
    spring_kind: np.ndarray             # (ns,) int8: STRUCTURAL, SHEAR, FLEXION
    pinned: np.ndarray                  # (np,) int64 sorted unique vertex indices
    pieces: list[PieceInfo] = field(default_factory=list)
    initial_positions: np.ndarray | None = None   # (n, 3); None: the rest shape
    initial_velocities: np.ndarray | None = None  # (n, 3); None: zero
    hinge_vertices: np.ndarray | None = None      # (nh, 4) interior-edge hinges (per-hinge bending)
    shell_stencil: np.ndarray | None = None       # (nt, 6) triangle + opposite vertices (shell bending)
    shell_present: np.ndarray | None = None       # (nt, 3) bool: the triangle's hinge i exists
    shell_jump_stencil: np.ndarray | None = None  # (ne, 12) neighbour pairs (curvature-jump penalty)
    flexion_lines: np.ndarray | None = None       # (nf, 3) grid lines (first, middle, last) of the
    #   mass-spring flexion element (physics/bending.py, FlexionLineTerm)
    flexion_hinges: np.ndarray | None = None      # (nh, 4) hinges of mass-spring mesh files (bending
    #   by dihedral angles there; their flexion springs stay for damping)
    twist_cells: np.ndarray | None = None         # (nc, 4) grid cells (i,j), (i+1,j), (i,j+1),
    #   (i+1,j+1): the twist element of the continuum's grid_lines bending
    slide_vertices: np.ndarray | None = None      # (ns,) vertices held only along an axis
    slide_axes: np.ndarray | None = None          # (ns, 3) unit axes
    # garments (distcloth/garment): what a mesh sewn from flat panels needs
    triangle_weft: np.ndarray | None = None       # (nt, 3) each triangle's weft in the rest shape
    triangle_scale: np.ndarray | None = None      # (nt,) membrane stiffness factor (fused layers)
    rest_triangles: np.ndarray | None = None      # (nt, 3, 3) rest corners of each triangle: a
    #   welded garment has no single rest shape (its panels are flat apart, not sewn together)
    hinge_rest: np.ndarray | None = None          # (nh, 4, 3) each hinge unfolded flat at rest
    hinge_scale: np.ndarray | None = None         # (nh,) bending stiffness factor (seams, fused)
    stitch_pairs: np.ndarray | None = None        # (k, 2) vertices a sewing phase pulls together
    stitch_gap: np.ndarray | None = None          # (k,) their distance at the start
    stitch_index: np.ndarray | None = None        # (k,) the pattern stitch of each pair
    same_vertex: np.ndarray | None = None         # (n,) the vertex each one becomes when welded
    seam_lines: np.ndarray | None = None          # (m, 2) welded seam edges (extra springs)
    seam_rest_length: np.ndarray | None = None    # (m,) their rest lengths (shrinkage included)
    seam_stiffness: np.ndarray | None = None      # (m,) N/m
    # texture coordinates of mesh files that have them (scene/uvs.py), per triangle corner
    uv: np.ndarray | None = None                  # (k, 2)
    uv_index: np.ndarray | None = None            # (nt, 3) rows of uv, -1: none
    pattern_vertex: np.ndarray | None = None      # (n_pattern,) simulated vertex of each
    #   pattern vertex (identity before welding)
    # grips and loads (scene/grips.py): each pins entry, each vertex's entry, the loads
    grips: list = field(default_factory=list)
    pin_group: np.ndarray | None = None           # (n,) index into grips, -1: not held
    loads: Any = None                             # scene.grips.Loads, None: none
    # skin-following regions (scene/skin_follow.py): per piece, its region's vertices in
    # pattern numbering (None: the piece has none); None: no piece has one
    follow_regions: list | None = None

    @property
    def moving_grips(self) -> bool:
        return any(g.path is not None for g in self.grips)

    @property
    def num_vertices(self) -> int:
        return self.rest_positions.shape[0]

    @property
    def num_springs(self) -> int:
        return self.spring_vertices.shape[0]

    def per_vertex(self, values) -> np.ndarray:
        """(n,) each vertex's entry of ``values``, one per piece."""
        values = np.asarray(values)
        out = np.zeros(self.num_vertices, dtype=values.dtype)
        for value, info in zip(values, self.pieces):
            out[info.vertex_start:info.vertex_stop] = value
        return out

    def start_positions(self) -> np.ndarray:
        return self.rest_positions if self.initial_positions is None else self.initial_positions

    def start_velocities(self) -> np.ndarray:
        if self.initial_velocities is None:
            return np.zeros_like(self.rest_positions)
        return self.initial_velocities

    def size(self) -> float:
        """The cloth's characteristic size L: the diagonal of its rest bounding box."""
        span = self.rest_positions.max(axis=0) - self.rest_positions.min(axis=0)
        return float(np.linalg.norm(span))

    def matrix_graph(self) -> tuple[np.ndarray, np.ndarray]:
        """Vertex adjacency of the system matrix (every spring, triangle, hinge
        and shell stencil couples its vertices, flexion stencils included) as CSR (xadj,
        adjncy), no self loops."""
        n = self.num_vertices
        # every element stencil couples all its vertex pairs: springs, triangles
        # (membrane elements) and hinges (bending elements)
        pairs = [self.spring_vertices]
        for extra in (self.stitch_pairs, self.seam_lines):
            if extra is not None:
                pairs.append(extra)
        stencils = [self.triangles]
        if self.hinge_vertices is not None:
            stencils.append(self.hinge_vertices)
        if self.shell_stencil is not None:
            stencils.append(self.shell_stencil)
        if self.shell_jump_stencil is not None:
            stencils.append(self.shell_jump_stencil)
        if self.flexion_lines is not None:
            stencils.append(self.flexion_lines)
        if self.flexion_hinges is not None:
            stencils.append(self.flexion_hinges)
        if self.twist_cells is not None:
            stencils.append(self.twist_cells)
        # deduplicated stencil by stencil as undirected keys lo * n + hi, so the
        # peak holds one stencil's pairs (a hinge has 6), not all of them twice
        keys = [_edge_keys(p[:, 0], p[:, 1], n) for p in pairs]
        for el in stencils:
            nb = el.shape[1]
            keys.append(np.unique(np.concatenate(
                [_edge_keys(el[:, a], el[:, b], n) for a in range(nb) for b in range(a + 1, nb)])))
        key = np.unique(np.concatenate(keys))
        del keys
        lo, hi = np.divmod(key, n)
        del key
        # both directions, in row order: rows then columns ascending
        directed = np.concatenate([lo * n + hi, hi * n + lo])
        del lo, hi
        directed.sort()
        rows, cols = np.divmod(directed, n)
        del directed
        xadj = np.zeros(n + 1, dtype=np.int64)
        # bincount, not np.add.at: the latter is slow on 400k-vertex meshes
        np.cumsum(np.bincount(rows, minlength=n), out=xadj[1:])
        return xadj, cols


def _edge_keys(i: np.ndarray, j: np.ndarray, n: int) -> np.ndarray:
    """Undirected keys min * n + max of the vertex pairs (i, j), self pairs dropped."""
    i = np.asarray(i, dtype=np.int64)
    j = np.asarray(j, dtype=np.int64)
    lo, hi = np.minimum(i, j), np.maximum(i, j)
    return (lo * n + hi)[lo != hi]
