"""The run's HDF5 result file, written collectively by all ranks.

Layout (every array in *input* vertex order, whatever the partition)::

    /mesh/triangles            (nt, 3) int64
    /mesh/rest_positions       (n, 3) float64
    /mesh/uv, /mesh/uv_index   (k, 2) float64, (nt, 3) int64: per-corner texture
                               coordinates of a cloth mesh file that had them
    /partition/part            (n,) int32      owning rank of each input vertex
    /config                    scalar UTF-8 string: the resolved configuration
    /frames/positions          (frames, n, 3) float64, chunks (1, min(n, 65536), 3)
    /frames/time, /frames/step (frames,) float64 / int64
    /frames/<field>            per-frame fields the run declares (FrameField):
                               (frames, n[, 3]) per vertex, in input vertex
                               order, or (frames, nt[, 3]) per triangle, in
                               /mesh/triangles order; a run writes velocity
                               (n, 3), contact (n,) int8 and strain (nt,)
    /xdmf/<dataset>/<k:06d>    virtual datasets, row k of each per-frame
                               dataset above (positions, fields, moving
                               colliders; row 0 of a collider that never
                               moves), for the XDMF sidecar: its readers
                               take no HyperSlab (xdmf.py).  No data is
                               stored twice.
    /diagnostics/step, /time   (steps,) int64 / float64
    /diagnostics/<name>        (steps,) float64, one per diagnostic name
    /diagnostics/stage_time/<stage>   (steps,) float64 seconds
    /diagnostics/stage_calls/<stage>  (steps,) int64
    /colliders/<name>/triangles       (m, 3) int64: a collider's surface
    /colliders/<name>/positions       (frames, nv, 3) float64 if it moves (row k
                                      at frame k's time), else (1, nv, 3)
    /garment/pattern_vertex    (n_pattern,) int64: a sewn garment's simulated
                               vertex of each pattern vertex (the panels' meshes
                               in pattern order, before welding)
    /garment/seam_lines        (m, 2) int64: its welded seam edges
    /colliders/<name> attributes: name (the scene's; '/' in it becomes '_' in
    the group name), shape (plane | sphere | capsule | box | mesh), moving
    root attributes: status ('running' | 'completed' |
    'completed_with_warnings' | 'interrupted' | 'failed'), error, error_step,
    warnings, warning_steps, warning_kinds (what a run accepted but the user
    must hear of: one line, its step and its kind per warning; a finished run
    with any ends 'completed_with_warnings'), interrupted_step, interrupted_by (a signal
    name), heartbeat (seconds since the epoch of the last frame or flush:
    a 'running' file whose heartbeat stopped belongs to a killed run),
    resumed_at (steps the run was resumed from), frames_written,
    steps_written, format, format_version, plus the caller's ``attrs``.

Resuming (``resume_step``): the existing file is opened, every frame after
that step and every diagnostics row after it is cut off (a run killed after
its last checkpoint leaves some), the caller's ``attrs`` replace the stored
ones, and the run goes on appending.

Format versions: 1 had no /colliders; 2 adds it (a scene without colliders
has no /colliders group); 3 adds the per-frame fields and the /xdmf views.

Colliders come as objects with ``name``, ``shape``, ``triangles`` (m, 3),
``moving`` and ``vertices(t)`` -> (nv, 3) (collision/surfaces.py makes them);
every rank passes the same ones (colliders are replicated), computes their
vertices and rank 0 writes them.

Collective protocol
-------------------
``comm`` is the communicator wrapper of ``distcloth/parallel/comm.py`` (or
None for a serial run).  Under MPI the file is opened with h5py's ``mpio``
driver on its communicator, and then *every*
method of :class:`ResultWriter` (the constructor, ``write_frame``,
``write_step``, ``record_error``, ``close``) is collective: all ranks call it,
in the same order, with the same scalar arguments (only ``positions_owned``
and the fields' rows differ).  A per-triangle field's row is written by the
rank owning the triangle's first vertex (:func:`triangle_rows`).  HDF5 metadata (dataset creation, resizing, attributes, flush,
close) must be changed identically on every rank or the file is silently
corrupted, so the writer broadcasts rank 0's copy of everything that becomes
metadata (attrs, names, error message) rather than trusting the caller.

Errors: a rank that meets an error must not call ``record_error``/``close``
alone, since the other ranks are elsewhere and the collective would hang.
The caller agrees first (``comm.agree``), then *all* ranks call ``record_error(step, message)`` and
``close()``.  As a context manager, ``__exit__`` closes normally when the
block ends without an exception, and on an exception it does the
record-error-and-close sequence only when that is safe: in a serial run, or
when the exception is collective (a :class:`CollectiveError`, or any
exception with a true ``collective`` attribute, raised on every rank after
such an agreement).  For any other exception it makes no collective call at
all: the file stays as last flushed (status 'running', earlier frames
readable) and the caller is expected to ``comm.abort()``; closing there could
deadlock against ranks that did not raise.
"""
from __future__ import annotations

import os
import time as _time
import warnings
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import h5py
import numpy as np
from h5py import h5d, h5fd, h5p, h5s

from distcloth.io.xdmf import XdmfAttribute, XdmfBody, XdmfSeries, frame_view

FORMAT_NAME = "distcloth-result"
FORMAT_VERSION = 3

# Above this many runs of consecutive input indices, a rank selects its rows
# as points instead of an OR of hyperslabs: HDF5 1.10.8 merges each OR'ed
# hyperslab into the whole span tree, so building R runs costs O(R^2)
# (measured: 4k runs 0.15 s, 8k 0.8 s, 16k 3.5 s, 64k 74 s), whereas a
# point selection is built in O(n_owned).  The selection is built once per
# run, but points make every frame's write about twice as slow (400k
# vertices, 2 ranks: ~70 ms with hyperslabs, ~150 ms with points), so
# hyperslabs stay the choice up to a one-off cost of about a second.
MAX_HYPERSLAB_RUNS = 8192

# Frames chunked one frame at a time, <= 64k vertices (1.5 MiB) per chunk.
FRAME_CHUNK_VERTICES = 65536
# Per-step diagnostics are buffered in memory and appended in blocks.
DEFAULT_STEP_BUFFER = 1024
# The per-step tables are resized (a collective call each) this many rows
# ahead of the steps written, and cut to them at close.
STEP_TABLE_GROWTH = 1024

# The sidecar is rewritten whole (xdmf.py: its collections cannot be appended
# to in place), 3 us a frame it lists: 15 ms at 5,000 frames, 45 s of a run
# that writes 5,000 frames if rewritten at every one.  So after a frame it is
# rewritten while it lists at most this many frames, and beyond that only
# once the time since the last rewrite is XDMF_TIME_RATIO times that
# rewrite's own: at most 1/XDMF_TIME_RATIO of the wall time, the frames of
# that much time behind (close, a recorded error and a resume rewrite it).
XDMF_EVERY_FRAME_BELOW = 64
XDMF_TIME_RATIO = 20.0

_RESERVED_ATTRS = frozenset(
    {"status", "error", "error_step", "frames_written", "steps_written",
     "format", "format_version", "interrupted_step", "interrupted_by", "heartbeat",
     "resumed_at", "warnings", "warning_steps", "warning_kinds"})
# the statuses of a run that reached its end
FINISHED = ("completed", "completed_with_warnings")
_RESERVED_DIAGNOSTICS = frozenset({"step", "time", "stage_time", "stage_calls"})
_RESERVED_FIELDS = frozenset({"positions", "time", "step", "position", "rank"})
# XDMF NumberType and Precision of the dtypes a field may have
_XDMF_TYPES = {"f8": ("Float", 8), "f4": ("Float", 4), "i8": ("Int", 8), "i4": ("Int", 4),
               "i1": ("Int", 1)}


@dataclass(frozen=True)
class FrameField:
    """A per-frame field written beside the positions: one row per vertex
    (``on="vertex"``, rows in the rank's ``owned_input`` order like the
    positions) or per triangle (``on="triangle"``, rows in the increasing
    order of :func:`triangle_rows`), ``components`` 1 or 3 values each."""
    name: str
    on: str = "vertex"              # vertex | triangle
    components: int = 1
    dtype: str = "f8"               # a key of _XDMF_TYPES

    def check(self) -> "FrameField":
        _check_name("field", self.name)
        if self.name in _RESERVED_FIELDS:
            raise ValueError(f"field name {self.name!r} is reserved")
        if self.on not in ("vertex", "triangle") or self.components not in (1, 3) \
                or np.dtype(self.dtype).str[1:] not in _XDMF_TYPES:
            raise ValueError(f"field {self.name!r}: on vertex|triangle, 1 or 3 components, "
                             f"dtype one of {sorted(_XDMF_TYPES)}")
        return self


def triangle_rows(triangles: np.ndarray, part: np.ndarray, rank: int) -> np.ndarray:
    """The triangles (indices, increasing) whose per-triangle field rows
    ``rank`` writes: those whose first vertex it owns."""
    return np.flatnonzero(np.asarray(part)[np.asarray(triangles)[:, 0]] == rank)


class CollectiveError(RuntimeError):
    """An error every rank has agreed on and raises together.

    Raising it on all ranks inside ``with ResultWriter(...)`` makes
    ``__exit__`` record it (status 'failed') and close the file collectively.
    """

    collective = True

    def __init__(self, message: str, step: int = -1):
        super().__init__(message)
        self.step = int(step)


class ResumeRefused(ValueError):
    """The result file a run was to go on in does not fit it (another run's
    file, its rows short of the resume step): raised on every rank alike,
    before anything in the file changed."""


class _SerialComm:
    """Stand-in for the communicator wrapper of a serial run (comm=None)."""
    rank = 0
    size = 1
    mpi_comm = None

    @staticmethod
    def broadcast(obj, root=0):
        return obj

    @staticmethod
    def synchronize():
        pass

    @staticmethod
    def agree(error):
        return None if error is None else (0, error)


def _resume_problem(f, step: int, n_vertices: int, diagnostic_names, field_names,
                    colliders) -> tuple[str | None, int, int]:
    """(what keeps the open result ``f`` from going on after ``step``, or None;
    the frames and step rows to keep).  Read only: a file refused is left as
    it was.  ``colliders``: (name, group) of the resumed run's bodies."""
    if f.attrs.get("format") != FORMAT_NAME or "frames/positions" not in f:
        return "is not a distcloth result file", 0, 0
    if f["frames/positions"].shape[1] != n_vertices:
        return (f"has {f['frames/positions'].shape[1]} vertices, the resumed run "
                f"{n_vertices}"), 0, 0
    missing = [k for k in ("step", *diagnostic_names) if f"diagnostics/{k}" not in f]
    if missing:
        return f"has no diagnostics {missing}", 0, 0
    missing = [k for k in field_names if f"frames/{k}" not in f]
    if missing:
        return f"has no per-frame fields {missing} (an older format)", 0, 0
    missing = [name for name, group in colliders if f"colliders/{group}" not in f]
    if missing:
        return f"has no collider {missing[0]!r}", 0, 0
    nf = min(int(f.attrs.get("frames_written", 0)), f["frames/step"].shape[0])
    ns = min(int(f.attrs.get("steps_written", 0)), f["diagnostics/step"].shape[0])
    keep_f = int(np.searchsorted(f["frames/step"][:nf], step, side="right"))
    steps = f["diagnostics/step"][:ns]
    keep_s = int(np.searchsorted(steps, step, side="right"))
    if keep_s and steps[keep_s - 1] != step:
        return (f"lacks the diagnostics of steps {int(steps[keep_s - 1]) + 1} to {step}: it "
                f"does not belong to this checkpoint"), keep_f, keep_s
    return None, keep_f, keep_s


def _text(value) -> str:
    return value.decode() if isinstance(value, bytes) else str(value)


def _check_name(kind: str, name: str) -> str:
    if not isinstance(name, str) or not name or "/" in name or name in (".", ".."):
        raise ValueError(f"{kind} name {name!r} must be a non-empty string without '/'")
    return name


def _attr_value(key: str, value: Any):
    """Convert a caller attribute to something h5py stores portably."""
    if isinstance(value, (str, bool, int, float, np.generic)):
        return value
    if isinstance(value, (list, tuple, np.ndarray)):
        arr = np.asarray(value)
        if arr.ndim == 1 and arr.dtype.kind in "biuf":
            return arr
        if arr.ndim == 1 and arr.dtype.kind == "U":
            return np.array(list(arr), dtype=h5py.string_dtype())
    raise TypeError(
        f"attribute {key!r}: {type(value).__name__} not storable; use a string, "
        "a number, a bool or a 1-D list of numbers or of strings")


def _group_names(names: Sequence[str]) -> list[str]:
    """HDF5 group names for collider names: '/' would nest groups and '.' or
    '..' name none, so they become '_'; a name made equal to an earlier one
    gets a suffix."""
    out: list[str] = []
    for name in names:
        group = name.replace("/", "_")
        if group in ("", ".", ".."):
            group = "_" * max(1, len(group))
        base, i = group, 1
        while group in out:
            group, i = f"{base}_{i}", i + 1
        out.append(group)
    return out


def _surface(vertices, triangles, name: str) -> tuple[np.ndarray, np.ndarray]:
    """A collider's vertices (nv, 3) float64 and triangles (m, 3) int64, checked."""
    x = np.ascontiguousarray(vertices, dtype=np.float64)
    tri = np.ascontiguousarray(triangles, dtype=np.int64)
    if x.ndim != 2 or x.shape[1] != 3 or x.shape[0] == 0:
        raise ValueError(f"collider {name!r}: vertices must be (nv, 3) with nv > 0, got {x.shape}")
    if tri.ndim != 2 or tri.shape[1] != 3 or (
            tri.size and (tri.min() < 0 or tri.max() >= x.shape[0])):
        raise ValueError(f"collider {name!r}: triangles must be (m, 3) indices of its vertices")
    return x, tri


def _runs(sorted_idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Starts and lengths of the runs of consecutive integers in a sorted array."""
    if sorted_idx.size == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    breaks = np.flatnonzero(np.diff(sorted_idx) != 1) + 1
    first = np.concatenate([[0], breaks])
    last = np.concatenate([breaks, [sorted_idx.size]])
    return sorted_idx[first], last - first


class _RowSelection:
    """File selection of this rank's rows of a (frames, n[, 3]) dataset such
    as /frames/positions, built once.

    The selection is made for frame 0 on a dataspace of extent (1, n[, 3]);
    per frame it is copied, the extent grown to the dataset's and shifted by
    H5Soffset_simple.  HDF5 1.10.8 keeps a selection through
    H5Sset_extent_simple and applies the offset in (collective) I/O, so the
    expensive part is never repeated per frame.
    """

    def __init__(self, sorted_owned: np.ndarray, n: int, width: int = 3):
        self.n = n
        self.row = (width,) if width > 1 else ()     # a row's trailing dims
        starts, counts = _runs(sorted_owned)
        self.n_runs = int(starts.size)
        self.kind = "none" if starts.size == 0 else (
            "hyperslab" if starts.size <= MAX_HYPERSLAB_RUNS else "points")
        zeros = (0,) * len(self.row)
        space = h5s.create_simple((1, n) + self.row, (h5s.UNLIMITED, n) + self.row)
        if self.kind == "none":
            space.select_none()   # a rank owning nothing still joins the collective write
        elif self.kind == "hyperslab":
            op = h5s.SELECT_SET
            for s, c in zip(starts.tolist(), counts.tolist()):
                space.select_hyperslab((0, s) + zeros, (1, c) + self.row, op=op)
                op = h5s.SELECT_OR
        else:
            m, w = sorted_owned.size, max(1, width)
            coords = np.zeros((w * m, 2 + len(self.row)), dtype=np.uint64)
            coords[:, 1] = np.repeat(sorted_owned, w)
            if self.row:
                coords[:, 2] = np.tile(np.arange(w, dtype=np.uint64), m)
            space.select_elements(coords)
        self._template = space

    def for_frame(self, k: int, n_frames: int):
        space = self._template.copy()
        space.set_extent_simple((n_frames, self.n) + self.row, (h5s.UNLIMITED, self.n) + self.row)
        space.offset_simple((k, 0) + (0,) * len(self.row))
        return space


class ResultWriter:
    """Collective writer of one run's result file; see the module docstring."""

    def __init__(self, path: str | os.PathLike, comm, *,
                 rest_positions: np.ndarray, triangles: np.ndarray,
                 owned_input: np.ndarray, part: np.ndarray,
                 config_text: str, attrs: Mapping[str, Any],
                 stage_names: Sequence[str], diagnostic_names: Sequence[str],
                 colliders: Sequence[Any] = (), step_buffer: int = DEFAULT_STEP_BUFFER,
                 arrays: Mapping[str, np.ndarray] | None = None,
                 fields: Sequence[FrameField] = (), resume_step: int | None = None):
        self.path = os.path.abspath(os.fspath(path))
        self._comm = _SerialComm() if comm is None else comm
        self.rank, self.size = int(self._comm.rank), int(self._comm.size)
        self._mpio = comm is not None and bool(h5py.get_config().mpi)
        if comm is not None and self.size > 1 and not self._mpio:
            raise RuntimeError(
                "ResultWriter: a communicator of size > 1 needs h5py's MPI build, "
                "which Debian loads only under mpiexec (or with H5PY_ALWAYS_USE_MPI=1)")

        rest_positions = np.ascontiguousarray(rest_positions, dtype=np.float64)
        triangles = np.ascontiguousarray(triangles, dtype=np.int64)
        part = np.ascontiguousarray(part, dtype=np.int32)
        owned_input = np.asarray(owned_input, dtype=np.int64)
        n = rest_positions.shape[0]
        if rest_positions.shape != (n, 3) or n == 0:
            raise ValueError(f"rest_positions must be (n, 3) with n > 0, got {rest_positions.shape}")
        if triangles.ndim != 2 or triangles.shape[1] != 3:
            raise ValueError(f"triangles must be (nt, 3), got {triangles.shape}")
        if part.shape != (n,):
            raise ValueError(f"part must be ({n},), got {part.shape}")
        # The rows this rank writes must be exactly those ``part`` gives it,
        # or frames would get holes or two writers per row.
        order = np.argsort(owned_input, kind="stable")
        sorted_owned = owned_input[order]
        if not np.array_equal(sorted_owned, np.flatnonzero(part == self.rank)):
            raise ValueError(f"rank {self.rank}: owned_input disagrees with part == {self.rank}")

        # Every rank evaluates the colliders (they are replicated, so a bad
        # one fails everywhere alike); rank 0's arrays are the ones written.
        colliders = list(colliders)
        first = [_surface(c.vertices(0.0), c.triangles, c.name) for c in colliders]
        bodies = [(str(c.name), str(c.shape), bool(c.moving), x.shape[0], tri.shape[0])
                  for c, (x, tri) in zip(colliders, first)]

        # Everything that becomes HDF5 metadata must be identical on all
        # ranks: take rank 0's copy.
        config_text, attrs, stage_names, diagnostic_names, bodies, fields = self._comm.broadcast(
            (str(config_text), dict(attrs), list(stage_names), list(diagnostic_names), bodies,
             [FrameField(f.name, f.on, int(f.components), np.dtype(f.dtype).str[1:])
              for f in fields]), root=0)
        if len(bodies) != len(colliders):
            raise ValueError(f"rank {self.rank}: {len(colliders)} colliders, rank 0 has "
                             f"{len(bodies)}; every rank must pass the same ones")
        for name in stage_names:
            _check_name("stage", name)
        for name in diagnostic_names:
            _check_name("diagnostic", name)
            if name in _RESERVED_DIAGNOSTICS:
                raise ValueError(f"diagnostic name {name!r} is reserved")
        if len(set(stage_names)) != len(stage_names) or len(set(diagnostic_names)) != len(diagnostic_names):
            raise ValueError("stage and diagnostic names must be unique")
        fields = [f.check() for f in fields]
        if len({f.name for f in fields}) != len(fields):
            raise ValueError("field names must be unique")
        bad = _RESERVED_ATTRS.intersection(attrs)
        if bad:
            raise ValueError(f"attrs {sorted(bad)} are reserved for the writer")
        attrs = {k: _attr_value(k, v) for k, v in attrs.items()}

        self.n_vertices, self.n_triangles = n, triangles.shape[0]
        self.stage_names = tuple(stage_names)
        self.diagnostic_names = tuple(diagnostic_names)
        self._order = order                 # owned (local) order -> sorted input order
        self.n_owned = owned_input.size
        self._selection = _RowSelection(sorted_owned, n)
        self.fields = tuple(fields)
        self.owned_triangles = triangle_rows(triangles, part, self.rank)
        # this rank's rows of each field's dataset: (rows owned, rows in all, row width)
        self._field_rows = {f.name: (self.owned_triangles, self.n_triangles) if f.on == "triangle"
                            else (sorted_owned, n) for f in self.fields}
        self._field_selection = {f.name: _RowSelection(*self._field_rows[f.name], f.components)
                                 for f in self.fields}
        self._times: list[float] = []
        self._xdmf: XdmfSeries | None = None    # rank 0's sidecar
        self._xdmf_rewritten = (0.0, 0.0)       # its last rewrite: (ended at, took) s
        self.frames_written = 0
        self.steps_written = 0
        self._closed = False
        self._error_recorded = False
        self._error_status = "failed"
        stem = os.path.splitext(self.path)[0]
        self.xdmf_path = stem + ".xdmf"

        if self._mpio:
            self._dxpl = h5p.create(h5p.DATASET_XFER)
            self._dxpl.set_dxpl_mpio(h5fd.MPIO_COLLECTIVE)
            self._dxpl_own = h5p.create(h5p.DATASET_XFER)
            self._dxpl_own.set_dxpl_mpio(h5fd.MPIO_INDEPENDENT)
        else:
            self._dxpl = self._dxpl_own = None

        parent = os.path.dirname(self.path)
        if self.rank == 0:
            os.makedirs(parent, exist_ok=True)
        self._comm.synchronize()   # the directory exists before anyone opens
        mode = "w" if resume_step is None else "r+"
        if self._mpio:
            self._file = h5py.File(self.path, mode, driver="mpio", comm=self._comm.mpi_comm)
        else:
            self._file = h5py.File(self.path, mode)
        if resume_step is not None:
            self._reopen(int(resume_step), attrs, part, colliders, bodies, step_buffer, config_text)
            return
        f = self._file

        f.attrs["format"] = FORMAT_NAME
        f.attrs["format_version"] = np.int64(FORMAT_VERSION)
        for key, value in attrs.items():
            f.attrs[key] = value
        f.attrs["status"] = "running"
        f.attrs["error"] = ""
        f.attrs["error_step"] = np.int64(-1)
        f.attrs["frames_written"] = np.int64(0)
        f.attrs["steps_written"] = np.int64(0)
        f.attrs["resumed_at"] = np.zeros(0, dtype=np.int64)
        self._beat()

        # Static arrays: identical on all ranks, so rank 0 writes them all.
        tri_ds = f.create_dataset("mesh/triangles", shape=triangles.shape, dtype=np.int64)
        self._write_root(tri_ds, triangles)
        rest_ds = f.create_dataset("mesh/rest_positions", shape=(n, 3), dtype=np.float64)
        self._write_root(rest_ds, rest_positions)
        part_ds = f.create_dataset("partition/part", shape=(n,), dtype=np.int32)
        self._write_root(part_ds, part)
        f["partition"].attrs["ranks"] = np.int64(self.size)
        for name, value in sorted((arrays or {}).items()):
            # static arrays the run adds (a garment's vertex map), identical on every rank
            value = np.ascontiguousarray(value)
            ds = f.create_dataset(name, shape=value.shape, dtype=value.dtype)
            if value.size:
                self._write_root(ds, value)
        self._write_config(config_text)

        chunk_v = min(n, FRAME_CHUNK_VERTICES)
        self._positions = f.create_dataset(
            "frames/positions", shape=(0, n, 3), maxshape=(None, n, 3),
            chunks=(1, chunk_v, 3), dtype=np.float64)
        self._frame_time = f.create_dataset(
            "frames/time", shape=(0,), maxshape=(None,), chunks=(256,), dtype=np.float64)
        self._frame_step = f.create_dataset(
            "frames/step", shape=(0,), maxshape=(None,), chunks=(256,), dtype=np.int64)
        self._field_ds = {}
        for fld in self.fields:
            rows = self._field_rows[fld.name][1]
            row = (3,) if fld.components == 3 else ()
            self._field_ds[fld.name] = f.create_dataset(
                f"frames/{fld.name}", shape=(0, rows) + row, maxshape=(None, rows) + row,
                chunks=(1, max(1, min(rows, FRAME_CHUNK_VERTICES))) + row, dtype=fld.dtype)

        self._step_tables_open(step_buffer, create=True)

        # Collider surfaces: triangles once; positions once for a body that
        # never moves, else a row per frame (write_frame).
        self._moving: list[tuple[Any, h5py.Dataset]] = []
        self._xdmf_bodies: list[XdmfBody] = []
        for c, (x, tri), (name, shape, moving, nv, m), group in zip(
                colliders, first, bodies, _group_names([b[0] for b in bodies])):
            g = f.create_group(f"colliders/{group}")
            g.attrs["name"] = name
            g.attrs["shape"] = shape
            g.attrs["moving"] = np.bool_(moving)
            self._write_root(g.create_dataset("triangles", shape=(m, 3), dtype=np.int64), tri)
            if moving:
                ds = g.create_dataset("positions", shape=(0, nv, 3), maxshape=(None, nv, 3),
                                      chunks=(1, min(nv, FRAME_CHUNK_VERTICES), 3),
                                      dtype=np.float64)
                self._moving.append((c, ds))
            else:
                ds = g.create_dataset("positions", shape=(1, nv, 3), dtype=np.float64)
                self._write_root(ds, x[None])
                self._make_view(ds, 0)
            self._xdmf_bodies.append(XdmfBody(name, f"/colliders/{group}", nv, m, moving))
        f.flush()

    def _step_tables_open(self, step_buffer: int, create: bool) -> None:
        """The per-step tables: name -> (dataset, in-memory buffer column)."""
        f = self._file
        self._buf_len = max(1, int(step_buffer))
        chunk_s = (min(self._buf_len, 1024),)
        self._step_tables: list[tuple[h5py.Dataset, np.ndarray]] = []

        def table(name, dtype, fill):
            if create:
                ds = f.create_dataset(name, shape=(0,), maxshape=(None,), chunks=chunk_s,
                                      dtype=dtype)
            else:
                ds = f[name]
            buf = np.full(self._buf_len, fill, dtype=dtype)
            self._step_tables.append((ds, buf))
            return buf

        self._b_step = table("diagnostics/step", np.int64, -1)
        self._b_time = table("diagnostics/time", np.float64, np.nan)
        self._b_diag = {k: table(f"diagnostics/{k}", np.float64, np.nan) for k in self.diagnostic_names}
        self._b_stime = {k: table(f"diagnostics/stage_time/{k}", np.float64, np.nan) for k in self.stage_names}
        self._b_scalls = {k: table(f"diagnostics/stage_calls/{k}", np.int64, 0) for k in self.stage_names}
        f.require_group("diagnostics/stage_time")
        f.require_group("diagnostics/stage_calls")
        self._n_buffered = 0
        # rows the tables have room for (STEP_TABLE_GROWTH beyond the steps
        # written, cut back at close; readers cut them to steps_written)
        self._step_rows = self._step_tables[0][0].shape[0]

    def _reopen(self, step: int, attrs, part, colliders, bodies, step_buffer,
                config_text: str) -> None:
        """Go on writing an existing result after ``step``: later frames and
        diagnostics rows are cut off (collective: every rank reads the same
        file and resizes alike)."""
        f = self._file
        groups = _group_names([b[0] for b in bodies])
        try:
            problem, keep_f, keep_s = _resume_problem(
                f, step, self.n_vertices, self.diagnostic_names,
                [fld.name for fld in self.fields],
                [(b[0], group) for b, group in zip(bodies, groups)])
        except (OSError, KeyError, ValueError) as exc:
            problem, keep_f, keep_s = f"cannot be read ({exc})", 0, 0
        # every rank reads the same file, but one that failed to must not leave
        # the others cutting it: agreed before anything is changed
        agreed = self._comm.agree(None if problem is None else f"{self.path} {problem}")
        if agreed is not None:
            f.close()       # collective: every rank refuses alike
            raise ResumeRefused(agreed[1])

        def cut(name, obj):
            if isinstance(obj, h5py.Dataset) and obj.maxshape and obj.maxshape[0] is None:
                obj.resize(keep_s if name.startswith("diagnostics/") else keep_f, axis=0)

        # every rank has read the old rows before any cuts: shrinking a chunked
        # dataset rewrites its last chunk, and a rank still reading met a chunk
        # rewritten from stale rows (three ranks, the diagnostics of a resumed
        # file read back as zeros past the first flush's rows)
        self._comm.synchronize()
        f.visititems(cut)
        self._field_ds = {fld.name: f[f"frames/{fld.name}"] for fld in self.fields}
        # the per-frame views of the frames cut off go too: they are made again
        views = [ds.name for ds in [f["frames/positions"], *self._field_ds.values()]]
        views += [f"/colliders/{g}/positions" for g in f.get("colliders", {})
                  if f[f"colliders/{g}/positions"].maxshape[0] is None]
        for name in views:
            group = f.get(frame_view(name, 0).rsplit("/", 1)[0])
            for key in [] if group is None else [key for key in group if int(key) >= keep_f]:
                del group[key]
        for key, value in attrs.items():
            f.attrs[key] = value
        self._write_root(f["partition/part"], np.ascontiguousarray(part, dtype=np.int32))
        del f["config"]        # the resumed run's (time.end may have grown)
        self._write_config(config_text)
        f["partition"].attrs["ranks"] = np.int64(self.size)
        resumed = [int(s) for s in np.atleast_1d(f.attrs.get("resumed_at", np.zeros(0, np.int64)))]
        f.attrs["resumed_at"] = np.array(resumed + [step], dtype=np.int64)
        f.attrs["status"] = "running"
        f.attrs["error"] = ""
        f.attrs["error_step"] = np.int64(-1)
        for key in ("interrupted_step", "interrupted_by"):
            if key in f.attrs:
                del f.attrs[key]
        # a warning of a step cut off is met again (or not) by the resumed run
        self._set_warnings([w for w in self.warnings() if w[0] <= step])
        self._positions = f["frames/positions"]
        self._frame_time = f["frames/time"]
        self._frame_step = f["frames/step"]
        self._times = [float(t) for t in self._frame_time[:keep_f]]
        self.frames_written, self.steps_written = keep_f, keep_s
        f.attrs["frames_written"] = np.int64(keep_f)
        f.attrs["steps_written"] = np.int64(keep_s)
        self._step_tables_open(step_buffer, create=False)
        self._moving, self._xdmf_bodies = [], []
        for c, (name, shape, moving, nv, m), group in zip(colliders, bodies, groups):
            if moving:
                self._moving.append((c, f[f"colliders/{group}/positions"]))
            self._xdmf_bodies.append(XdmfBody(name, f"/colliders/{group}", nv, m, moving))
        self._beat()
        f.flush()
        self._write_xdmf()

    def _write_config(self, config_text: str) -> None:
        text = config_text.encode("utf-8")
        # Fixed-length string: parallel HDF5 1.10 cannot write variable-length data.
        cfg = self._file.create_dataset("config", shape=(),
                                        dtype=h5py.string_dtype("utf-8", max(1, len(text))))
        self._write_root(cfg, np.array(text, dtype=f"S{max(1, len(text))}"), mtype=cfg.id.get_type())

    def _beat(self) -> None:
        """The heartbeat attribute: rank 0's clock (attributes must be equal everywhere)."""
        self._file.attrs["heartbeat"] = float(self._comm.broadcast(_time.time(), root=0))

    # ------------------------------------------------------------ low level

    def _write(self, dset: h5py.Dataset, mspace, fspace, data: np.ndarray, mtype=None,
               dxpl=None) -> None:
        dxpl = self._dxpl if dxpl is None else dxpl
        if dxpl is None:
            dset.id.write(mspace, fspace, data, mtype=mtype)
        else:
            dset.id.write(mspace, fspace, data, mtype=mtype, dxpl=dxpl)

    def _write_root(self, dset: h5py.Dataset, data: np.ndarray, start: int = 0, mtype=None,
                    alone: bool = False) -> None:
        """Write of ``data`` into dset[start:start+len] by rank 0 only:
        collective, the other ranks joining with empty selections (a
        collective transfer needs every rank, and one writer avoids n-fold
        redundant I/O), or ``alone`` with independent MPI-IO, the other ranks
        doing nothing (raw data into space already allocated).
        """
        if alone and self.rank != 0:
            return
        data = np.require(data, requirements="C")   # (ascontiguousarray makes 0-d arrays 1-d)
        fspace = dset.id.get_space()
        mspace = h5s.create(h5s.SCALAR) if data.ndim == 0 else h5s.create_simple(data.shape)
        if self.rank != 0:
            fspace.select_none()
            mspace.select_none()
        elif data.ndim > 0:
            count = data.shape
            fspace.select_hyperslab((start,) + (0,) * (data.ndim - 1), count)
        self._write(dset, mspace, fspace, data, mtype=mtype,
                    dxpl=self._dxpl_own if alone else None)

    def _size_step_tables(self, rows: int) -> None:
        """Collective: every per-step table resized to ``rows``, once rank 0's
        rows are written (a shrink rewrites the last chunk, as in _reopen) and
        before it writes more."""
        self._comm.synchronize()
        for ds, _ in self._step_tables:
            ds.resize(rows, axis=0)
        self._step_rows = rows
        self._comm.synchronize()

    def _flush_steps(self) -> None:
        """Append the buffered steps to every per-step table (collective).

        The tables grow by STEP_TABLE_GROWTH rows at a time and rank 0 writes
        the rows alone (independent MPI-IO): a collective resize and write of
        every table at every flush cost ~70 us a table on two ranks, 5.6 ms a
        frame for the 78 tables of the hanging square at 41², half of its
        frame's output (docs/benchmarks.md, "A frame's output")."""
        # rank 0's count (it writes the rows): after a write that failed on some
        # ranks only, the others may hold one step more, and the resize must agree
        m = int(self._comm.broadcast(self._n_buffered, root=0))
        if m == 0:
            return
        start = self.steps_written
        if start + m > self._step_rows:
            self._size_step_tables(start + m + STEP_TABLE_GROWTH)
        for ds, buf in self._step_tables:
            self._write_root(ds, buf[:m], start=start, alone=True)
        self.steps_written += m
        self._file.attrs["steps_written"] = np.int64(self.steps_written)
        self._n_buffered = 0
        for _, buf in self._step_tables:   # reset so a missing value reads as NaN/0
            buf[:] = -1 if buf is self._b_step else (np.nan if buf.dtype.kind == "f" else 0)

    def _write_xdmf(self, frame: bool = False) -> None:
        """Rank 0 rewrites the sidecar; after a ``frame``, only when it is due
        (XDMF_EVERY_FRAME_BELOW).  A failure only warns: raising on rank 0
        alone would leave the other ranks waiting in the next collective."""
        if self.rank != 0:
            return
        started = _time.perf_counter()
        ended, took = self._xdmf_rewritten
        if (frame and self.frames_written > XDMF_EVERY_FRAME_BELOW
                and started - ended < XDMF_TIME_RATIO * took):
            return
        try:
            if self._xdmf is None:
                self._xdmf = XdmfSeries(os.path.basename(self.path), self.n_vertices,
                                        self.n_triangles, self._xdmf_attributes(),
                                        self._xdmf_bodies)
            for t in self._times[len(self._xdmf):]:
                self._xdmf.append(t)
            self._xdmf.write(self.xdmf_path)
            now = _time.perf_counter()
            self._xdmf_rewritten = (now, now - started)
        except OSError as err:
            warnings.warn(f"could not write {self.xdmf_path}: {err}", RuntimeWarning)

    def _xdmf_attributes(self) -> list[XdmfAttribute]:
        out = [XdmfAttribute("rank", "/partition/part", (self.n_vertices,),
                             number_type="Int", precision=4)]
        for fld in self.fields:
            number_type, precision = _XDMF_TYPES[fld.dtype]
            rows = self._field_rows[fld.name][1]
            out.append(XdmfAttribute(
                fld.name, f"/frames/{fld.name}", (rows, 3) if fld.components == 3 else (rows,),
                center="Cell" if fld.on == "triangle" else "Node",
                attribute_type="Vector" if fld.components == 3 else "Scalar",
                number_type=number_type, precision=precision, per_frame=True))
        return out

    def _make_view(self, ds: h5py.Dataset, k: int) -> None:
        """Collective: the virtual dataset that is row k of ``ds`` (xdmf.frame_view)."""
        # HDF5's own calls: h5py's VirtualLayout spent most of a view's time in
        # Python (0.7-0.85 ms against 0.33 a view at 41² on two ranks)
        source = h5s.create_simple(ds.shape)
        source.select_hyperslab((k,) + (0,) * (ds.ndim - 1), (1,) + ds.shape[1:])
        view = h5s.create_simple(ds.shape[1:])
        dcpl = h5p.create(h5p.DATASET_CREATE)
        dcpl.set_virtual(view, b".", ds.name.encode("utf-8"), source)
        group, name = frame_view(ds.name, k).rsplit("/", 1)
        h5d.create(self._file.require_group(group).id, name.encode("utf-8"), ds.id.get_type(),
                   view, dcpl=dcpl)

    def _write_rows(self, ds: h5py.Dataset, selection: "_RowSelection", k: int,
                    rows: np.ndarray) -> None:
        """Collective: this rank's rows (sorted like its selection) of frame k."""
        fspace = selection.for_frame(k, k + 1)
        mspace = h5s.create_simple(rows.shape)
        if rows.shape[0] == 0:
            mspace.select_none()
        self._write(ds, mspace, fspace, np.ascontiguousarray(rows))

    def _require_open(self) -> None:
        if self._closed:
            raise RuntimeError("ResultWriter is closed")

    # ------------------------------------------------------------ public API

    def write_frame(self, step: int, time: float, positions_owned: np.ndarray,
                    body_time: float | None = None,
                    fields: Mapping[str, np.ndarray] | None = None) -> None:
        """Collective: append one frame; each rank writes its own rows.

        ``positions_owned`` is (n_owned, 3) in this rank's ``owned_input``
        order; ``fields`` has a value for every declared field: per vertex
        in the same order, per triangle in ``owned_triangles`` order.  Moving colliders get a row each, their surface at
        ``body_time`` (default ``time``; a drape's frame 'time' is its
        iteration).  Buffered steps are written first, and the file is
        flushed and the XDMF sidecar rewritten afterwards, so a crash later
        leaves this frame readable.
        """
        self._require_open()
        data = np.asarray(positions_owned, dtype=np.float64)
        if data.shape != (self.n_owned, 3):
            raise ValueError(f"positions_owned must be ({self.n_owned}, 3), got {data.shape}")
        fields = dict(fields or {})
        if set(fields) != {f.name for f in self.fields}:
            raise ValueError(f"fields {sorted(fields)} given, {[f.name for f in self.fields]} declared")
        field_rows = {}
        for fld in self.fields:
            owned = self._field_rows[fld.name][0]
            want = (owned.size, 3) if fld.components == 3 else (owned.size,)
            value = np.asarray(fields[fld.name], dtype=fld.dtype)
            if value.shape != want:
                raise ValueError(f"field {fld.name!r} must be {want}, got {value.shape}")
            # rows sorted by input index, like the positions
            field_rows[fld.name] = value[self._order] if fld.on == "vertex" else value
        self._flush_steps()
        k = self.frames_written
        self._positions.resize(k + 1, axis=0)
        self._frame_time.resize(k + 1, axis=0)
        self._frame_step.resize(k + 1, axis=0)
        # Rows sorted by input index, matching the order the selection
        # enumerates file elements in.
        self._write_rows(self._positions, self._selection, k, data[self._order])
        for fld in self.fields:
            ds = self._field_ds[fld.name]
            ds.resize(k + 1, axis=0)
            self._write_rows(ds, self._field_selection[fld.name], k, field_rows[fld.name])
        self._write_root(self._frame_time, np.array([time], np.float64), start=k)
        self._write_root(self._frame_step, np.array([step], np.int64), start=k)
        t_body = float(time if body_time is None else body_time)
        for c, ds in self._moving:
            x, _ = _surface(c.vertices(t_body), c.triangles, c.name)
            if x.shape[0] != ds.shape[1]:
                raise ValueError(f"collider {c.name!r}: {x.shape[0]} vertices at t = {t_body:g}, "
                                 f"{ds.shape[1]} at t = 0")
            ds.resize(k + 1, axis=0)
            self._write_root(ds, x[None], start=k)
        for ds in [self._positions, *self._field_ds.values(), *(ds for _, ds in self._moving)]:
            self._make_view(ds, k)
        self.frames_written = k + 1
        self._times.append(float(time))
        self._file.attrs["frames_written"] = np.int64(self.frames_written)
        self._beat()
        self._file.flush()
        self._write_xdmf(frame=True)

    def write_step(self, step: int, time: float, diagnostics: Mapping[str, float],
                   stage_time: Mapping[str, float] | None = None,
                   stage_calls: Mapping[str, int] | None = None) -> None:
        """Collective: record one step's diagnostics (the same values on all ranks).

        Values are buffered and appended at the next frame, at close, on
        ``record_error`` or when the buffer is full.  Names not given at
        construction raise KeyError; names left out are stored as NaN
        (calls: 0).
        """
        self._require_open()
        stage_time = stage_time or {}
        stage_calls = stage_calls or {}
        for given, known, what in ((diagnostics, self._b_diag, "diagnostic"),
                                   (stage_time, self._b_stime, "stage"),
                                   (stage_calls, self._b_scalls, "stage")):
            unknown = set(given) - set(known)
            if unknown:
                raise KeyError(f"unknown {what} names {sorted(unknown)}; declared: {sorted(known)}")
        i = self._n_buffered
        self._b_step[i] = step
        self._b_time[i] = time
        for name, value in diagnostics.items():
            self._b_diag[name][i] = value
        for name, value in stage_time.items():
            self._b_stime[name][i] = value
        for name, value in stage_calls.items():
            self._b_scalls[name][i] = value
        self._n_buffered = i + 1
        if self._n_buffered == self._buf_len:
            self._flush_steps()

    def record_error(self, step: int, message: str, status: str = "failed") -> None:
        """Collective: mark the run ended by an error at ``step`` with ``status``
        ('failed', or a drape's 'no_rest_state'; rank 0's arguments are used)."""
        self._require_open()
        step, message = self._comm.broadcast((int(step), str(message)), root=0)
        self._flush_steps()
        f = self._file
        f.attrs["status"] = str(status)
        self._error_status = str(status)
        f.attrs["error"] = message
        f.attrs["error_step"] = np.int64(step)
        self._error_recorded = True
        f.flush()
        self._write_xdmf()

    def warnings(self) -> list[tuple[int, str, str]]:
        """(step, kind, message) of each warning recorded so far."""
        a = self._file.attrs
        steps = [int(s) for s in np.atleast_1d(a.get("warning_steps", np.zeros(0, np.int64)))]
        kinds = [_text(k) for k in np.atleast_1d(a.get("warning_kinds", []))]
        lines = [_text(m) for m in np.atleast_1d(a.get("warnings", []))]
        return list(zip(steps, kinds, lines))

    def _set_warnings(self, warnings) -> None:
        a = self._file.attrs
        a["warning_steps"] = np.array([w[0] for w in warnings], dtype=np.int64)
        a["warning_kinds"] = np.array([w[1] for w in warnings], dtype=h5py.string_dtype())
        a["warnings"] = np.array([w[2] for w in warnings], dtype=h5py.string_dtype())

    def record_warning(self, step: int, kind: str, message: str) -> None:
        """Collective: a warning of the run (rank 0's arguments are used); the
        first of each kind is kept (a resumed run may meet it again)."""
        self._require_open()
        step, kind, message = self._comm.broadcast((int(step), str(kind), str(message)), root=0)
        known = self.warnings()
        if any(k == kind for _, k, _ in known):
            return
        self._set_warnings(known + [(step, kind, message)])
        self._file.flush()

    def flush(self) -> None:
        """Collective: write the buffered steps and flush the file (before a
        checkpoint, so the file holds every step up to it)."""
        self._require_open()
        self._flush_steps()
        self._beat()
        self._file.flush()

    def record_interrupt(self, step: int, signal_name: str) -> None:
        """Collective: the run stopped on a signal after ``step``; close then
        sets status 'interrupted' (rank 0's arguments are used)."""
        self._require_open()
        step, signal_name = self._comm.broadcast((int(step), str(signal_name)), root=0)
        self._file.attrs["interrupted_step"] = np.int64(step)
        self._file.attrs["interrupted_by"] = signal_name

    def close(self, status: str = "completed") -> str:
        """Collective: write the remaining steps, set the final status, close;
        returns the status written.

        A recorded error keeps its status ('failed', or the one it was
        recorded with) whatever ``status`` says; a completed run with warnings
        is 'completed_with_warnings'.  Calling close twice is harmless.
        """
        if self._closed:
            return self._final_status
        self._flush_steps()
        if self._step_rows != self.steps_written:
            self._size_step_tables(self.steps_written)
        self._beat()
        if status == "completed" and self.warnings():
            status = "completed_with_warnings"
        self._final_status = self._error_status if self._error_recorded else str(status)
        self._file.attrs["status"] = self._final_status
        self._file.attrs["frames_written"] = np.int64(self.frames_written)
        self._file.attrs["steps_written"] = np.int64(self.steps_written)
        self._file.close()
        self._closed = True
        self._write_xdmf()
        return self._final_status

    @property
    def closed(self) -> bool:
        return self._closed

    @property
    def selection_kind(self) -> str:
        """How this rank selects its frame rows: 'hyperslab', 'points' or 'none'."""
        return self._selection.kind

    @property
    def selection_runs(self) -> int:
        return self._selection.n_runs

    def __enter__(self) -> "ResultWriter":
        return self

    def __exit__(self, exc_type, exc, tb) -> bool:
        if self._closed:
            return False
        if exc is None:
            self.close()
        elif self.size == 1 or getattr(exc, "collective", False):
            if not self._error_recorded:       # keep an error the caller already recorded
                step = getattr(exc, "step", -1)
                self.record_error(step if isinstance(step, int) else -1, f"{exc_type.__name__}: {exc}")
            self.close("failed")
        # else: an exception on some ranks only; no collective call is safe
        # here (see the module docstring).  The file keeps its last flush.
        return False
