"""Checkpoint files: what a run needs to go on, written atomically.

A checkpoint is a small HDF5 file beside the result, ``<result stem>.checkpoint.h5``::

    attrs: format ('distcloth-checkpoint'), format_version, result (the
           result file's name, in the same directory), step, time, ranks,
           plus the caller's scalars
    /config             the resolved configuration (YAML text)
    /arrays/<name>      the caller's arrays, every per-vertex one in *input*
                        vertex order (so any rank count can read it back)

It is written by one process (rank 0, after the state was gathered) into a
temporary file in the same directory, flushed to disk, then renamed over
the previous checkpoint: a run killed while writing leaves the previous
checkpoint whole.  No MPI here: the caller gathers and agrees.
"""
from __future__ import annotations

import os
from typing import Any, Mapping

import h5py
import numpy as np

FORMAT_NAME = "distcloth-checkpoint"
FORMAT_VERSION = 1
SUFFIX = ".checkpoint.h5"


def checkpoint_path(result_path: str) -> str:
    """The checkpoint file of a result file."""
    return os.path.splitext(os.path.abspath(result_path))[0] + SUFFIX


def write_checkpoint(path: str, config_text: str, attrs: Mapping[str, Any],
                     arrays: Mapping[str, np.ndarray]) -> None:
    """Write the checkpoint at ``path`` atomically (temporary file, fsync, rename)."""
    path = os.path.abspath(path)
    tmp = f"{path}.tmp{os.getpid()}"
    try:
        with h5py.File(tmp, "w") as f:
            f.attrs["format"] = FORMAT_NAME
            f.attrs["format_version"] = np.int64(FORMAT_VERSION)
            for key, value in attrs.items():
                f.attrs[key] = value
            f.create_dataset("config", data=np.array(config_text.encode("utf-8")))
            for name, value in arrays.items():
                f.create_dataset(f"arrays/{name}", data=np.asarray(value))
        with open(tmp, "rb") as stream:      # the data on disk before the name points at it
            os.fsync(stream.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def is_checkpoint(path: str) -> bool:
    """Whether ``path`` is a checkpoint file (rather than a result file)."""
    try:
        with h5py.File(path, "r") as f:
            return f.attrs.get("format") == FORMAT_NAME
    except OSError:
        return False


def read_checkpoint(path: str) -> tuple[dict[str, Any], str, dict[str, np.ndarray]]:
    """(attrs, config text, arrays) of a checkpoint; OSError or ValueError if it is not one."""
    with h5py.File(path, "r") as f:
        if f.attrs.get("format") != FORMAT_NAME:
            raise ValueError("not a distcloth checkpoint file")
        attrs = {k: _plain(v) for k, v in f.attrs.items()}
        text = f["config"][()]
        arrays = {name: ds[()] for name, ds in f["arrays"].items()} if "arrays" in f else {}
    return attrs, text.decode("utf-8") if isinstance(text, bytes) else str(text), arrays


def _plain(value: Any) -> Any:
    if isinstance(value, bytes):
        return value.decode("utf-8")
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    return value
