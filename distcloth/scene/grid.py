"""Rectangular grid cloth: vertices, triangles and mass-spring topology.

Vertex (i, j) (i along u = local x, j along v = local y) has index
``j * nu + i``; local coordinates are centred at the origin in the z = 0
plane.  Spring families follow Vassilev et al. 2001 §2.2: structural springs join grid
neighbours, shear springs both diagonals of every quad, flexion springs
vertices two apart along rows and columns.
"""
from __future__ import annotations

import numpy as np

from ..config.schema import GRID_PATTERNS

# spring families of a grid, in the order build_model concatenates them
GRID_SPRING_FAMILIES = ("structural_u", "structural_v", "shear", "flexion_u", "flexion_v")


def grid_spacing(size, resolution) -> tuple[float, float]:
    """(dx, dy): distance between neighbouring vertices along u and v."""
    return size[0] / (resolution[0] - 1), size[1] / (resolution[1] - 1)


def grid_vertices(size, resolution) -> np.ndarray:
    """(nu*nv, 3) local positions, centred at the origin, z = 0."""
    nu, nv = resolution
    u = np.linspace(-0.5 * size[0], 0.5 * size[0], nu)
    v = np.linspace(-0.5 * size[1], 0.5 * size[1], nv)
    positions = np.zeros((nv, nu, 3))
    positions[:, :, 0] = u[None, :]
    positions[:, :, 1] = v[:, None]
    return positions.reshape(-1, 3)


def grid_vertex_area(size, resolution) -> np.ndarray:
    """(nu*nv,) a quarter of each adjacent cell: dx dy inside, half on edges,
    a quarter at corners."""
    dx, dy = grid_spacing(size, resolution)
    along_u = np.full(resolution[0], dx)
    along_v = np.full(resolution[1], dy)
    along_u[[0, -1]] *= 0.5
    along_v[[0, -1]] *= 0.5
    return np.outer(along_v, along_u).ravel()


def _quad_corners(resolution):
    """Corner indices a=(i,j), b=(i+1,j), c=(i+1,j+1), d=(i,j+1) of every quad,
    and the quad's checkerboard parity (i + j) % 2."""
    nu, nv = resolution
    i, j = np.meshgrid(np.arange(nu - 1), np.arange(nv - 1))
    i, j = i.ravel(), j.ravel()
    a = j * nu + i
    return a, a + 1, a + nu + 1, a + nu, (i + j) % 2


def grid_triangles(resolution, pattern: str) -> np.ndarray:
    """Two counter-clockwise (normal +z in local coordinates) triangles per quad.

    ``regular`` cuts every quad along its a-c diagonal; ``alternating`` uses
    b-d instead on odd (i + j), so the diagonals form a checkerboard of
    diamonds and the mesh has no preferred shear direction."""
    if pattern not in GRID_PATTERNS:
        raise ValueError(f"unknown grid pattern {pattern!r}")
    a, b, c, d, parity = _quad_corners(resolution)
    first = np.stack([a, b, c], axis=1)      # diagonal a-c
    second = np.stack([a, c, d], axis=1)
    if pattern == "alternating":
        flip = (parity == 1)[:, None]
        first = np.where(flip, np.stack([a, b, d], axis=1), first)    # diagonal b-d
        second = np.where(flip, np.stack([b, c, d], axis=1), second)
    # quad q gives triangles 2q and 2q+1
    return np.stack([first, second], axis=1).reshape(-1, 3).astype(np.int64)


def grid_springs(resolution) -> dict[str, np.ndarray]:
    """Spring end pairs (m, 2) of each family in GRID_SPRING_FAMILIES."""
    nu, nv = resolution
    index = np.arange(nu * nv, dtype=np.int64).reshape(nv, nu)   # index[j, i]
    lines = grid_flexion_lines(resolution)

    def pairs(first, second):
        return np.stack([first.ravel(), second.ravel()], axis=1)

    return {
        "structural_u": pairs(index[:, :-1], index[:, 1:]),
        "structural_v": pairs(index[:-1, :], index[1:, :]),
        "shear": np.concatenate([pairs(index[:-1, :-1], index[1:, 1:]),     # a-c
                                 pairs(index[:-1, 1:], index[1:, :-1])]),   # b-d
        **dict(zip(("flexion_u", "flexion_v"), np.split(lines[:, [0, 2]], [nv * (nu - 2)]))),
    }


def grid_flexion_lines(resolution) -> np.ndarray:
    """(m, 3) (first, middle, last) of every three consecutive vertices along
    u, then along v: the flexion springs of ``grid_springs`` with their middle
    vertex, in the same order (the mass-spring bending stencils)."""
    nu, nv = resolution
    index = np.arange(nu * nv, dtype=np.int64).reshape(nv, nu)

    def lines(a, m, b):
        return np.stack([a.ravel(), m.ravel(), b.ravel()], axis=1)

    return np.concatenate([lines(index[:, :-2], index[:, 1:-1], index[:, 2:]),
                           lines(index[:-2, :], index[1:-1, :], index[2:, :])])


def grid_twist_cells(resolution) -> np.ndarray:
    """(m, 4) corners (i, j), (i + 1, j), (i, j + 1), (i + 1, j + 1) of every
    cell: the stencil of the mixed second difference x_uv (the twist
    element of the ``grid_lines`` bending)."""
    nu, nv = resolution
    index = np.arange(nu * nv, dtype=np.int64).reshape(nv, nu)
    return np.stack([index[:-1, :-1].ravel(), index[:-1, 1:].ravel(),
                     index[1:, :-1].ravel(), index[1:, 1:].ravel()], axis=1)


def grid_edge_vertices(resolution, edge: str) -> np.ndarray:
    """Indices of the vertices on one edge of the grid (before rotation)."""
    nu, nv = resolution
    index = np.arange(nu * nv, dtype=np.int64).reshape(nv, nu)
    rows = {"bottom": index[0, :], "top": index[nv - 1, :],
            "left": index[:, 0], "right": index[:, nu - 1]}
    return rows[edge].copy()


def grid_corner_vertex(resolution, corner: str) -> int:
    nu, nv = resolution
    vertical, horizontal = corner.split("_")
    i = 0 if horizontal == "left" else nu - 1
    j = 0 if vertical == "bottom" else nv - 1
    return j * nu + i
