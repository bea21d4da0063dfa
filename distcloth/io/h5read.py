"""Read a result file back (serially: tests, previews, tools).

Opens with h5py's default driver, which works with both of Debian's h5py
builds, so it can run on one rank of an MPI job.  Arrays are cut to the
``frames_written`` / ``steps_written`` attributes: a crash between growing a
dataset and writing it leaves a last row that was never filled.
"""
from __future__ import annotations

import os
from typing import Any

import h5py
import numpy as np


def _plain(value: Any) -> Any:
    """HDF5 attribute value -> plain Python (bytes decoded, numpy scalars unwrapped)."""
    if isinstance(value, bytes):
        return value.decode("utf-8")
    if isinstance(value, np.ndarray):
        if value.dtype.kind in "OS":
            return [_plain(v) for v in value.tolist()]
        return value
    if isinstance(value, np.generic):
        return value.item()
    return value


def read_attrs(path: str | os.PathLike) -> dict[str, Any]:
    """Just the root attributes (status, error, frames_written, ...)."""
    with h5py.File(path, "r") as f:
        return {k: _plain(v) for k, v in f.attrs.items()}


def read_result(path: str | os.PathLike, *, positions: bool = True,
                frames: slice | list[int] | None = None) -> dict[str, Any]:
    """Everything in a result file as numpy arrays and plain Python values.

    Keys: ``attrs`` (dict), ``config`` (str), ``triangles``, ``rest_positions``,
    ``part``, ``time`` and ``step`` (per frame), ``positions`` (frames, n, 3)
    unless ``positions=False`` (then None), ``diagnostics`` (name -> array,
    including ``step`` and ``time``), ``stage_time`` and ``stage_calls``
    (stage -> array), ``frames_written``, ``steps_written``, ``colliders``
    (see :func:`read_colliders`; empty for files without colliders).
    ``frames`` picks frames (indices into the written ones) to load.
    """
    with h5py.File(path, "r") as f:
        attrs = {k: _plain(v) for k, v in f.attrs.items()}
        nf = int(attrs.get("frames_written", f["frames/time"].shape[0]))
        ns = int(attrs.get("steps_written", f["diagnostics/step"].shape[0]))
        idx = np.arange(nf)
        if frames is not None:
            idx = idx[frames]
        out: dict[str, Any] = {
            "attrs": attrs,
            "config": _plain(f["config"][()]),
            "triangles": f["mesh/triangles"][...],
            "rest_positions": f["mesh/rest_positions"][...],
            "part": f["partition/part"][...],
            "time": f["frames/time"][:nf][idx],
            "step": f["frames/step"][:nf][idx],
            "frames_written": nf,
            "steps_written": ns,
            "positions": None,
        }
        if positions:
            pos = f["frames/positions"]
            # one frame at a time: h5py fancy indexing needs increasing indices
            out["positions"] = (np.stack([pos[int(k)] for k in idx]) if idx.size
                                else np.zeros((0,) + pos.shape[1:]))
        out["colliders"] = _colliders(f, idx)
        diag = f["diagnostics"]
        out["diagnostics"] = {k: v[:ns] for k, v in diag.items() if isinstance(v, h5py.Dataset)}
        out["stage_time"] = {k: v[:ns] for k, v in diag["stage_time"].items()}
        out["stage_calls"] = {k: v[:ns] for k, v in diag["stage_calls"].items()}
    return out


def read_colliders(path: str | os.PathLike, *,
                   frames: slice | list[int] | None = None) -> dict[str, dict[str, Any]]:
    """The collider surfaces of a result file, by the scene's collider name:
    ``triangles`` (m, 3), ``positions`` (one row per picked frame if
    ``moving``, else the single row of a body that never moves: (1, nv, 3)),
    ``moving`` and ``shape``.  Files of format 1 and scenes without colliders
    give {}."""
    with h5py.File(path, "r") as f:
        nf = int(_plain(f.attrs.get("frames_written", f["frames/time"].shape[0])))
        idx = np.arange(nf)
        return _colliders(f, idx if frames is None else idx[frames])


def _colliders(f: h5py.File, idx: np.ndarray) -> dict[str, dict[str, Any]]:
    out: dict[str, dict[str, Any]] = {}
    for group, g in f.get("colliders", {}).items():
        moving = bool(_plain(g.attrs["moving"]))
        pos = g["positions"]
        if moving:
            # one row at a time: h5py fancy indexing needs increasing indices
            rows = (np.stack([pos[int(k)] for k in idx]) if idx.size
                    else np.zeros((0,) + pos.shape[1:]))
        else:
            rows = pos[...]
        out[str(_plain(g.attrs.get("name", group)))] = {
            "triangles": g["triangles"][...], "positions": rows, "moving": moving,
            "shape": str(_plain(g.attrs.get("shape", "mesh")))}
    return out
