"""Pinned vertices of one piece from its PinSpec list, and the vertex selectors
that pins and loads share (docs/config.md)."""
from __future__ import annotations

import numpy as np

from ..config.schema import ConfigError, PinSpec
from .grid import grid_corner_vertex, grid_edge_vertices


def select_pins(pins, positions: np.ndarray, grid_resolution, key: str) -> np.ndarray:
    """Sorted unique piece-local indices pinned by ``pins``.

    ``positions``: the piece's placed (world) rest positions; ``grid_resolution``:
    (nu, nv) for grids, None for file meshes; ``key``: ``cloth.<p>.pins``."""
    chosen = [np.zeros(0, dtype=np.int64)]
    for k, pin in enumerate(pins):
        if pin.axis is not None:          # sliding pins: select_pin_axes
            continue
        chosen.append(select_one(pin, positions, grid_resolution, f"{key}.{k}"))
    return np.unique(np.concatenate(chosen))


def select_pin_axes(pins, positions, grid_resolution, key: str):
    """(indices, unit axes) of the sliding pins (``axis``); a vertex also fully
    pinned, or sliding along two directions, is left to the full pins."""
    idx, axes = [np.zeros(0, dtype=np.int64)], [np.zeros((0, 3))]
    for k, pin in enumerate(pins):
        if pin.axis is None:
            continue
        sel = select_one(pin, positions, grid_resolution, f"{key}.{k}")
        a = np.asarray(pin.axis, float) / np.linalg.norm(pin.axis)
        idx.append(sel)
        axes.append(np.tile(a, (sel.shape[0], 1)))
    return np.concatenate(idx), np.concatenate(axes)


def select_one(pin: PinSpec, positions, grid_resolution, key: str) -> np.ndarray:
    """The piece-local vertices one selector (a pin or a load) chooses."""
    n = positions.shape[0]
    if pin.edge is not None or pin.corner is not None:
        what = "edge" if pin.edge is not None else "corner"
        if grid_resolution is None:
            raise ConfigError(f"{key}.{what}", getattr(pin, what),
                              "edge and corner pins need a grid mesh; use indices or box")
        if pin.edge is not None:
            return grid_edge_vertices(grid_resolution, pin.edge)
        return np.array([grid_corner_vertex(grid_resolution, pin.corner)], dtype=np.int64)
    if pin.indices is not None:
        indices = np.asarray(pin.indices, dtype=np.int64).reshape(-1)
        bad = (indices < 0) | (indices >= n)
        if bad.any():
            raise ConfigError(f"{key}.indices", list(pin.indices),
                              f"vertex indices of this piece, 0 <= i < {n}")
        return indices
    if pin.box_min is not None and pin.box_max is not None:
        low, high = np.asarray(pin.box_min), np.asarray(pin.box_max)
        inside = np.flatnonzero(np.all((positions >= low) & (positions <= high), axis=1))
        if inside.shape[0] == 0:
            lo, hi = positions.min(axis=0), positions.max(axis=0)
            raise ConfigError(f"{key}.box", {"min": list(pin.box_min), "max": list(pin.box_max)},
                              f"a box holding at least one vertex; the piece spans "
                              f"{np.round(lo, 6).tolist()} to {np.round(hi, 6).tolist()}")
        return inside.astype(np.int64)
    raise ConfigError(key, pin, "one of edge, corner, indices, box")
