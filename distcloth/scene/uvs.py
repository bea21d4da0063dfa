"""Texture coordinates of an OBJ cloth mesh, kept for the exports.

An OBJ file gives UVs per face corner (``f a/t b/t c/t``): a vertex on a UV
seam has one texture coordinate on each side.  They are kept that way, as a
table of coordinates and one index per triangle corner, so welding or
renumbering vertices never touches them.  Polygons are fan-triangulated the
same way as their vertex indices (scene/meshio.py).

Only OBJ files carry them (PLY has no standard per-corner UVs); a file whose
faces do not all have a texture coordinate has none.  The result file stores
them as ``/mesh/uv`` and ``/mesh/uv_index`` (io/h5writer.py).
"""
from __future__ import annotations

import re

import numpy as np

from ..config.schema import ConfigError
from .meshio import fan_triangulate

_COMMENT = re.compile(r"#[^\n]*")
_TEXCOORD = re.compile(r"^[ \t]*vt[ \t]+([^\n]*)", re.M)
_FACE = re.compile(r"^[ \t]*f[ \t]+([^\n]*)", re.M)
_KIND = re.compile(r"^[ \t]*(vt|f)[ \t]", re.M)
# a face corner 'a', 'a/t', 'a//n', 'a/t/n': group 1 is t ('' when absent)
_CORNER = re.compile(r"(?<!\S)[+-]?\d+(?:/([+-]?\d*))?(?:/\S*)?")


def read_obj_uvs(text: str) -> tuple[np.ndarray, np.ndarray] | None:
    """``(uv (k, 2) float64, uv_index (nt, 3) int64)`` of OBJ text, triangle
    corners in the order of :func:`distcloth.scene.meshio.read_obj_text`'s
    triangles; None when the file has no texture coordinates on every face.
    Raises ValueError for a texture index that does not exist."""
    text = _COMMENT.sub("", text.replace("\\\r\n", " ").replace("\\\n", " "))
    coord_lines = _TEXCOORD.findall(text)
    face_lines = _FACE.findall(text)
    if not coord_lines or not face_lines:
        return None
    uv = _texcoords(coord_lines)
    # '0/0' between lines: texture index 0 does not exist, so it marks a line start
    tokens = np.array(_CORNER.findall("0/0 " + " 0/0 ".join(face_lines)), dtype=str)
    if (tokens == "").any():
        return None
    starts = np.flatnonzero(tokens == "0")
    if starts.shape[0] != len(face_lines):
        raise ValueError("texture index 0 (OBJ indices start at 1)")
    counts = np.diff(np.append(starts, tokens.shape[0])) - 1
    tokens = np.delete(tokens, starts)
    flat = tokens.astype(np.int64)
    # negative indices count back from the last 'vt' before the face line
    kinds = np.array(_KIND.findall(text))
    before = np.cumsum(kinds == "vt")[kinds == "f"]
    flat = np.where(flat > 0, flat - 1, np.repeat(before, counts) + flat)
    if ((flat < 0) | (flat >= uv.shape[0])).any():
        raise ValueError(f"a face refers to a texture coordinate that does not exist "
                         f"({uv.shape[0]} 'vt' lines)")
    return uv, fan_triangulate(flat, counts)


def _texcoords(lines: list[str]) -> np.ndarray:
    """(k, 2) u, v of 'vt u [v [w]]' lines ('inf' between lines marks a line start)."""
    try:
        values = np.array(("inf " + " inf ".join(lines)).split(), dtype=np.float64)
    except ValueError as exc:
        raise ValueError(f"bad texture coordinate: {exc}") from None
    starts = np.flatnonzero(np.isinf(values))
    if starts.shape[0] != len(lines):
        raise ValueError("a texture coordinate is not finite")
    counts = np.diff(np.append(starts, values.shape[0])) - 1
    if (counts < 2).any():
        raise ValueError("a 'vt' line has fewer than 2 numbers")
    uv = values[starts[:, None] + np.arange(1, 3)[None, :]]
    if not np.isfinite(uv).all():
        raise ValueError("a texture coordinate is not finite")
    return uv


def scene_uvs(cfg, pieces) -> tuple[np.ndarray, np.ndarray] | None:
    """The UVs of a scene's cloth: ``(uv, uv_index)`` over the model's
    triangles (-1 on the triangles of pieces without UVs), or None when no
    piece has any.  ``pieces`` are the model's PieceInfo, in ``cfg.cloth``
    order."""
    tables, indices, found = [], [], False
    offset = 0
    for p, (spec, info) in enumerate(zip(cfg.cloth, pieces)):
        n_tri = info.triangle_stop - info.triangle_start
        got = None
        if spec.mesh.file is not None and not _is_ply(spec.mesh.file):
            with open(spec.mesh.file, "rb") as handle:
                data = handle.read()
            try:
                got = read_obj_uvs(data.decode("utf-8", errors="replace"))
            except ValueError as exc:
                raise ConfigError(f"cloth.{p}.mesh.file", spec.mesh.file,
                                  f"an OBJ file with valid texture coordinates: {exc}") from None
        if got is not None and got[1].shape[0] == n_tri:
            tables.append(got[0])
            indices.append(got[1] + offset)
            offset += got[0].shape[0]
            found = True
        else:
            indices.append(np.full((n_tri, 3), -1, dtype=np.int64))
    if not found:
        return None
    return np.concatenate(tables), np.concatenate(indices)


def _is_ply(path: str) -> bool:
    with open(path, "rb") as handle:
        return handle.read(3) == b"ply"
