"""A result file opened for the tools (export, view): the frames a
``--frames`` argument picks, read one at a time.

Serial (h5py's default driver, no MPI).  Only the datasets every result has
are used: /mesh, /frames/positions and /frames/time, the optional /mesh/uv
and /mesh/uv_index, and /colliders (io/h5read.py reads those).
"""
from __future__ import annotations

import os
import re

import h5py
import numpy as np

from ..config.schema import ConfigError
from .h5read import read_colliders

FRAMES_HELP = ("all | last | N | A:B | A:B:S | a comma list of those (frame indices from 0, "
               "negative from the end, A:B stops before B as in Python)")
_ITEM = re.compile(r"^(-?\d+)?(?::(-?\d+)?)?(?::(-?\d+))?$")


def parse_frames(spec: str, n_frames: int) -> np.ndarray:
    """The sorted unique frame indices ``spec`` names among ``n_frames``
    written frames; ConfigError('--frames', ...) when it is malformed, out of
    range or picks nothing."""
    text = str(spec).strip().lower()
    picked = []
    for item in text.split(","):
        item = item.strip()
        if item == "all":
            picked.append(np.arange(n_frames))
        elif item == "last":
            picked.append(np.arange(n_frames)[-1:])
        elif item and _ITEM.match(item):
            if ":" not in item:
                k = int(item)
                if not -n_frames <= k < n_frames:
                    raise ConfigError("--frames", spec, f"frame indices in 0..{n_frames - 1} "
                                      f"(the file has {n_frames} frames)")
                picked.append(np.array([k % n_frames]))
            else:
                parts = [int(p) if p else None for p in (item.split(":") + [""])[:3]]
                if parts[2] == 0:
                    raise ConfigError("--frames", spec, "a non-zero step in A:B:S")
                picked.append(np.arange(n_frames)[slice(*parts)])
        else:
            raise ConfigError("--frames", spec, FRAMES_HELP)
    frames = np.unique(np.concatenate(picked)) if picked else np.zeros(0, dtype=np.int64)
    if frames.size == 0:
        raise ConfigError("--frames", spec, f"at least one of the file's {n_frames} frames")
    return frames.astype(np.int64)


class ResultFrames:
    """A result file's mesh and its frames, read on demand (a context manager)."""

    def __init__(self, path: str | os.PathLike):
        self.path = os.fspath(path)
        if not os.path.isfile(self.path):
            raise ConfigError("RESULT", self.path, "an existing result file (.h5)")
        try:
            self._file = h5py.File(self.path, "r")
        except (OSError, ValueError) as exc:
            raise ConfigError("RESULT", self.path, f"a readable HDF5 result file ({exc})") from None
        f = self._file
        if f.attrs.get("format") not in ("distcloth-result", b"distcloth-result") \
                or "frames/positions" not in f or "mesh/triangles" not in f:
            f.close()
            raise ConfigError("RESULT", self.path, "a distcloth result file (.h5 written by "
                                                   "distcloth run or drape)")
        self.n_frames = int(f.attrs.get("frames_written", f["frames/time"].shape[0]))
        if self.n_frames == 0:
            f.close()
            raise ConfigError("RESULT", self.path, "a result file with at least one frame")
        self.triangles = f["mesh/triangles"][...]
        self.rest_positions = f["mesh/rest_positions"][...]
        self.time = f["frames/time"][: self.n_frames]
        self.uv = f["mesh/uv"][...] if "mesh/uv" in f else None
        self.uv_index = f["mesh/uv_index"][...] if "mesh/uv_index" in f else None
        scene = f.attrs.get("scene", "")
        self.scene = scene.decode() if isinstance(scene, bytes) else str(scene)

    @property
    def n_vertices(self) -> int:
        return self.rest_positions.shape[0]

    def positions(self, k: int) -> np.ndarray:
        """Frame k's (n, 3) positions, float64, input vertex order."""
        return self._file["frames/positions"][int(k)]

    def colliders(self, frames: np.ndarray) -> dict:
        """The collider surfaces at the picked frames (h5read.read_colliders)."""
        return read_colliders(self.path, frames=[int(k) for k in frames])

    def close(self) -> None:
        self._file.close()

    def __enter__(self) -> "ResultFrames":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

