"""``distcloth export``: a result file's frames as meshes other tools open.

* ``obj``: one Wavefront OBJ per frame (``v`` lines in the simulated vertex
  order, ``vt`` and ``f a/t`` when the scene's mesh file had UVs, per face
  corner as the file gave them; exact float64 coordinates).
* ``ply``: one binary little-endian PLY per frame (double x, y, z; faces as
  ``uchar`` count + ``int`` indices).  PLY has no standard per-corner UVs, so
  none are written.
* ``pc2``: one Blender point cache (the Mesh Cache modifier's PC2 format:
  the 12 bytes ``POINTCACHE2\\0``, int32 version 1, int32 points, float32
  start frame, float32 sample rate, int32 samples, then float32 x, y, z of
  every point of every sample, little-endian), and beside it the rest mesh
  as OBJ, whose vertices are in the same order, to put the modifier on.

Files are written to a temporary name and renamed, so a failure never
leaves half a file; an existing file is refused unless ``overwrite``.
"""
from __future__ import annotations

import itertools
import os
import struct
import tempfile

import numpy as np

from ..config.schema import ConfigError
from .frames import ResultFrames, parse_frames

FORMATS = ("obj", "ply", "pc2")
PC2_MAGIC = b"POINTCACHE2\0"
PC2_HEADER = struct.Struct("<12siiffi")
# Blender's Mesh Cache modifier (Frame mode) shows sample F - its Frame Start
# at scene frame F and ignores the header's start: 0 says the same thing
PC2_START_FRAME = 0.0


def obj_text(vertices: np.ndarray, triangles: np.ndarray, uv: np.ndarray | None = None,
             uv_index: np.ndarray | None = None, header: str = "") -> str:
    """OBJ text of a triangle mesh, with per-corner UVs when given (rows of
    ``uv_index`` that are -1 point at an extra (0, 0) coordinate)."""
    vertices = np.asarray(vertices, dtype=np.float64)
    triangles = np.asarray(triangles, dtype=np.int64)
    comment = "".join(f"# {line}\n" for line in header.splitlines())
    # one C-level %-format per block instead of a Python loop over rows
    v_text = ("v %.17g %.17g %.17g\n" * vertices.shape[0]) % tuple(vertices.ravel())
    if uv is None:
        f_text = ("f %d %d %d\n" * triangles.shape[0]) % tuple((triangles + 1).ravel())
        return comment + v_text + f_text
    uv = np.asarray(uv, dtype=np.float64)
    index = np.asarray(uv_index, dtype=np.int64)
    if (index < 0).any():
        uv = np.vstack([uv, np.zeros((1, 2))])
        index = np.where(index < 0, uv.shape[0] - 1, index)
    vt_text = ("vt %.17g %.17g\n" * uv.shape[0]) % tuple(uv.ravel())
    corners = np.stack([triangles + 1, index + 1], axis=2)       # (nt, 3, 2)
    f_text = ("f %d/%d %d/%d %d/%d\n" * triangles.shape[0]) % tuple(corners.ravel())
    return comment + v_text + vt_text + f_text


def ply_bytes(vertices: np.ndarray, triangles: np.ndarray, comment: str = "") -> bytes:
    """A binary little-endian PLY of a triangle mesh."""
    vertices = np.ascontiguousarray(vertices, dtype="<f8")
    faces = np.zeros(triangles.shape[0], dtype=[("n", "u1"), ("i", "<i4", (3,))])
    faces["n"] = 3
    faces["i"] = triangles
    lines = ["ply", "format binary_little_endian 1.0"]
    lines += [f"comment {c}" for c in comment.splitlines()]
    lines += [f"element vertex {vertices.shape[0]}", "property double x",
              "property double y", "property double z",
              f"element face {triangles.shape[0]}", "property list uchar int vertex_indices",
              "end_header"]
    return ("\n".join(lines) + "\n").encode("ascii") + vertices.tobytes() + faces.tobytes()


def pc2_header(n_points: int, n_samples: int, start: float = PC2_START_FRAME,
               sample_rate: float = 1.0) -> bytes:
    return PC2_HEADER.pack(PC2_MAGIC, 1, int(n_points), float(start), float(sample_rate),
                           int(n_samples))


def read_pc2(path: str | os.PathLike) -> dict:
    """A PC2 file: ``start``, ``sample_rate``, ``positions`` (samples, n, 3)
    float32; ValueError when the file is not one."""
    with open(path, "rb") as handle:
        data = handle.read()
    if len(data) < PC2_HEADER.size:
        raise ValueError("shorter than a PC2 header")
    magic, version, n, start, rate, samples = PC2_HEADER.unpack_from(data)
    if magic != PC2_MAGIC or version != 1:
        raise ValueError(f"not a PC2 file (magic {magic!r}, version {version})")
    body = np.frombuffer(data, dtype="<f4", offset=PC2_HEADER.size)
    if body.size != samples * n * 3:
        raise ValueError(f"{body.size} floats after the header, {samples} x {n} x 3 expected")
    return {"start": start, "sample_rate": rate, "positions": body.reshape(samples, n, 3)}


def export_paths(result: str, fmt: str, frames: np.ndarray, output: str | None) -> list[str]:
    """The files an export writes, one per frame for obj/ply (the last of
    them the rest mesh for pc2: [cache, rest OBJ]); ConfigError('--output')
    when ``output`` cannot name them."""
    stem = os.path.splitext(os.path.basename(result))[0]
    if fmt == "pc2":
        cache = output or os.path.join(os.path.dirname(result), stem + ".pc2")
        if not cache.lower().endswith(".pc2"):
            raise ConfigError("--output", output, "a file name ending in .pc2")
        return [cache, os.path.splitext(cache)[0] + "_rest.obj"]
    if output is not None and output.lower().endswith("." + fmt):
        if frames.size != 1:
            raise ConfigError("--output", output, f"a directory: {frames.size} frames picked "
                                                  f"(a .{fmt} file takes exactly one)")
        return [output]
    folder = output or os.path.join(os.path.dirname(result), f"{stem}_{fmt}")
    if os.path.exists(folder) and not os.path.isdir(folder):
        raise ConfigError("--output", output, "a directory (or, for one frame, a ."
                                              f"{fmt} file name)")
    return [os.path.join(folder, f"{stem}_{k:04d}.{fmt}") for k in frames]


def check_writable(paths: list[str], overwrite: bool) -> None:
    """Refuse before anything is written: existing files (unless overwrite),
    directories in the way, parents that cannot be created or written."""
    for path in paths:
        if os.path.isdir(path):
            raise ConfigError("--output", path, "a file name, not a directory")
        if os.path.exists(path) and not overwrite:
            raise ConfigError("--output", path, "a file that does not exist yet "
                                                "(--overwrite replaces it)")
        parent = _existing_parent(os.path.dirname(os.path.abspath(path)))
        if not os.path.isdir(parent) or not os.access(parent, os.W_OK | os.X_OK):
            raise ConfigError("--output", path, f"a place this user can write ({parent} is not "
                                                "a writable directory)")


def _existing_parent(path: str) -> str:
    while not os.path.exists(path):
        path = os.path.dirname(path)
    return path


def write_atomic(path: str, chunks) -> None:
    """Write the byte strings ``chunks`` to ``path`` through a temporary file
    in the same directory, renamed at the end."""
    folder = os.path.dirname(os.path.abspath(path))
    os.makedirs(folder, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=".distcloth-", dir=folder)
    try:
        with os.fdopen(fd, "wb") as handle:
            for chunk in chunks:
                handle.write(chunk)
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException:
        os.unlink(tmp)
        raise


def export(result: str, fmt: str, frames_spec: str = "all", output: str | None = None,
           overwrite: bool = False) -> list[str]:
    """Write the picked frames of a result file as ``fmt``; returns the paths
    written.  ConfigError for anything wrong with the arguments, raised
    before any file is written."""
    if fmt not in FORMATS:
        raise ConfigError("--format", fmt, " | ".join(FORMATS))
    with ResultFrames(result) as res:
        frames = parse_frames(frames_spec, res.n_frames)
        paths = export_paths(result, fmt, frames, output)
        check_writable(paths, overwrite)
        header = f"distcloth {res.scene}: {os.path.basename(result)}"
        if fmt == "pc2":
            rest = obj_text(res.rest_positions, res.triangles, res.uv, res.uv_index,
                            header=f"{header}, rest mesh for {os.path.basename(paths[0])}")
            # a frame at a time: the cache can be larger than memory
            write_atomic(paths[0], itertools.chain(
                [pc2_header(res.n_vertices, frames.size)],
                (res.positions(k).astype("<f4").tobytes() for k in frames)))
            write_atomic(paths[1], [rest.encode("ascii")])
            return paths
        for k, path in zip(frames, paths):
            note = f"{header}, frame {k} at t = {res.time[k]:.6g} s"
            if fmt == "obj":
                data = obj_text(res.positions(k), res.triangles, res.uv, res.uv_index,
                                header=note).encode("ascii")
            else:
                data = ply_bytes(res.positions(k), res.triangles, comment=note)
            write_atomic(path, [data])
    return paths
