"""Spring constants from the material (docs/config.md "Material mapping",
Vassilev et al. 2001 §2.2) and spring topology of general triangle meshes.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..config.schema import ConfigError, MaterialSpec
from .meshio import MeshFormatError

# Twice a triangle's area below this times its longest edge squared counts
# as zero: cross products carry rounding of about 1e-16 l^2.
DEGENERATE_RELATIVE_AREA = 1e-12


def membrane_modulus(stretch: float, shear: float) -> float:
    """C = C11 such that C11 - C12^2/C11 = Y with C12 = G: the positive root of
    C^2 - Y C - G^2 = 0."""
    return 0.5 * (stretch + math.sqrt(stretch * stretch + 4.0 * shear * shear))


def flexion_stiffness(bending: float, length):
    """k_f = 4B / L_f^2 (docs/config.md)."""
    return 4.0 * bending / np.square(length)


def grid_spring_constants(material: MaterialSpec, dx: float, dy: float, *,
                          key: str) -> dict[str, float]:
    """Stiffness of each grid spring family (grid.GRID_SPRING_FAMILIES).

    Derivation (infinitesimal strain, interior of the grid).  A spring with rest
    vector d (length L) under a homogeneous strain eps stretches by
    d.eps.d / L and stores k (d.eps.d)^2 / (2 L^2).  Each interior cell
    (area dx dy) holds one spring of every family except shear (two), so
    the energy densities are

      x structural, d = (dx, 0):     1/2 (k_x dx/dy)      e_xx^2
      y structural, d = (0, dy):     1/2 (k_y dy/dx)      e_yy^2
      two diagonals, d = (dx, +-dy), L_d^2 = dx^2 + dy^2, g = 2 k_d dx dy / L_d^2:
          1/2 g (dx/dy)^2 e_xx^2 + 1/2 g (dy/dx)^2 e_yy^2 + g e_xx e_yy + 2 g e_xy^2

    Matching W = 1/2 C (e_xx^2 + e_yy^2) + G e_xx e_yy + 2 G e_xy^2 term by term:

      k_d = G (dx^2 + dy^2) / (2 dx dy)
      k_x = (C - G (dx/dy)^2) dy/dx,   k_y = (C - G (dy/dx)^2) dx/dy

    With C = (Y + sqrt(Y^2 + 4 G^2)) / 2 the uniaxial stiffness is
    C - G^2/C = Y.  On square cells this is docs/config.md's k_d = G,
    k_s = C - G.  It is exact on rectangular cells too; what stays
    approximate is the boundary, where cells lack neighbours.

    The grid's bending is carried by the flexion line elements
    (physics/bending.py, ``FlexionLineTerm``), which store nothing under an
    in-plane affine strain, so the structural springs keep their whole
    stiffness whatever B and the spacing.  The ``flexion_u`` / ``flexion_v``
    constants k_f = 4B / (2 dx)^2 are kept for the flexion pairs' damping
    (c = damping * k) only.
    """
    stretch, shear, bending = material.stretch, material.shear_stiffness, material.bending
    modulus = membrane_modulus(stretch, shear)
    constants = {
        "shear": shear * (dx * dx + dy * dy) / (2.0 * dx * dy),
        "flexion_u": float(flexion_stiffness(bending, 2.0 * dx)),
        "flexion_v": float(flexion_stiffness(bending, 2.0 * dy)),
    }
    for axis, along, across in (("u", dx, dy), ("v", dy, dx)):
        aspect = along / across
        stiffness = (modulus - shear * aspect ** 2) * across / along
        if stiffness <= 0.0:
            # C(G) = G r^2 at G = Y r^2 / (r^4 - 1); only possible for r > 1
            largest = stretch * aspect ** 2 / (aspect ** 4 - 1.0)
            raise ConfigError(f"{key}.shear", shear,
                              f"shear stiffness too large for grid cells {along:g} m long "
                              f"along {axis} and {across:g} m across: the {axis} structural "
                              f"springs would be non-positive; needs G < {largest:.3g} N/m "
                              f"(or squarer cells)")
        constants[f"structural_{axis}"] = stiffness
    return constants


@dataclass
class MeshSprings:
    """Spring topology of a triangle mesh (docs/config.md)."""
    edges: np.ndarray          # (ne, 2) unique edges, smaller index first
    edge_area: np.ndarray      # (ne,) summed area of the 1 or 2 triangles at each edge
    flexion: np.ndarray        # (nf, 2) opposite vertices of each interior edge


def triangle_areas(positions: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    a, b, c = (positions[triangles[:, k]] for k in range(3))
    return 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)


def check_triangle_mesh(positions: np.ndarray, triangles: np.ndarray) -> None:
    """Refuse what a cloth mesh cannot be: no triangles, indices out of range,
    zero-area or repeated triangles, unused vertices.  (Non-manifold edges
    are refused by :func:`mesh_springs`.)"""
    n = positions.shape[0]
    if triangles.shape[0] == 0:
        raise MeshFormatError("no triangles")
    if triangles.min() < 0 or triangles.max() >= n:
        raise MeshFormatError(f"a triangle refers to a vertex that does not exist ({n} vertices)")
    a, b, c = (positions[triangles[:, k]] for k in range(3))
    twice_area = np.linalg.norm(np.cross(b - a, c - a), axis=1)
    longest = np.max(np.stack([np.sum((b - a) ** 2, axis=1), np.sum((c - b) ** 2, axis=1),
                               np.sum((a - c) ** 2, axis=1)]), axis=0)
    degenerate = twice_area <= DEGENERATE_RELATIVE_AREA * longest
    if degenerate.any():
        t = int(np.flatnonzero(degenerate)[0])
        raise MeshFormatError(f"degenerate (zero-area) triangles: {int(degenerate.sum())}, "
                              f"the first is triangle {t} {triangles[t].tolist()}")
    corners = np.sort(triangles, axis=1)
    if np.unique(corners, axis=0).shape[0] != triangles.shape[0]:
        raise MeshFormatError("a triangle appears twice")
    used = np.zeros(n, dtype=bool)
    used[triangles.ravel()] = True
    if not used.all():
        raise MeshFormatError(f"vertices in no triangle: {int((~used).sum())}, "
                              f"the first is vertex {int(np.flatnonzero(~used)[0])} "
                              f"(remove them: pin indices refer to the file's numbering)")


def mesh_springs(positions: np.ndarray, triangles: np.ndarray) -> MeshSprings:
    """Unique edges with their adjacent triangle area, and flexion pairs
    across interior edges (shared by exactly two triangles).  Refuses edges
    shared by more than two triangles (non-manifold) and flexion pairs whose
    ends coincide (a mesh folded onto itself)."""
    n = positions.shape[0]
    # half-edge h = 3 t + k runs from corner k to corner k+1; its opposite
    # vertex is corner k+2
    start = triangles.ravel()
    stop = triangles[:, [1, 2, 0]].ravel()
    opposite = triangles[:, [2, 0, 1]].ravel()
    low, high = np.minimum(start, stop), np.maximum(start, stop)
    keys, edge_of, uses = np.unique(low * n + high, return_inverse=True, return_counts=True)
    if (uses > 2).any():
        e = int(np.flatnonzero(uses > 2)[0])
        raise MeshFormatError(f"non-manifold edge ({int(keys[e] // n)}, {int(keys[e] % n)}) "
                              f"shared by {int(uses[e])} triangles")
    edges = np.stack([keys // n, keys % n], axis=1).astype(np.int64)
    areas = np.repeat(triangle_areas(positions, triangles), 3)
    edge_area = np.bincount(edge_of, weights=areas, minlength=keys.shape[0])
    # the two half-edges of an interior edge are neighbours once sorted by edge
    order = np.argsort(edge_of, kind="stable")
    first_half = np.cumsum(uses) - uses
    interior = np.flatnonzero(uses == 2)
    flexion = np.stack([opposite[order[first_half[interior]]],
                        opposite[order[first_half[interior] + 1]]], axis=1).astype(np.int64)
    span = np.linalg.norm(positions[flexion[:, 1]] - positions[flexion[:, 0]], axis=1)
    if (span == 0.0).any():
        raise MeshFormatError("two triangles at an edge fold onto each other "
                              "(their opposite vertices coincide)")
    return MeshSprings(edges=edges, edge_area=edge_area, flexion=flexion)


def mesh_structural_stiffness(stretch: float, edge_area: np.ndarray, length: np.ndarray):
    """k_e = Y * (sum of adjacent triangle areas) / l_e^2 (docs/config.md).

    On an equilateral lattice of side a every edge has two triangles of area
    sqrt(3) a^2 / 4, so k = sqrt(3) Y / 2, and a triangular lattice of springs
    k has the isotropic 2-D Young's modulus 2 k / sqrt(3) = Y (Poisson 1/3)."""
    return stretch * edge_area / np.square(length)
