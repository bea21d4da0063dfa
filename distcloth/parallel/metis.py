"""Thin ctypes binding to METIS 5 k-way graph partitioning (EG07 tutorial, Part 1 §5.4;
Karypis and Kumar 1998).

Only ``METIS_PartGraphKway`` is bound.  Debian's libmetis is built with
IDXTYPEWIDTH 32 and REALTYPEWIDTH 32 (/usr/include/metis.h), so idx_t is int32.
"""
from __future__ import annotations

import ctypes
import ctypes.util
import functools

import numpy as np

_FALLBACK_LIBRARY = "/usr/lib/x86_64-linux-gnu/libmetis.so.5"

# From /usr/include/metis.h (METIS 5.1.0).
METIS_NOPTIONS = 40
METIS_OPTION_SEED = 8          # position in the moptions_et enum
METIS_OPTION_UFACTOR = 16
METIS_OPTION_NUMBERING = 17
METIS_OK = 1
_METIS_STATUS_NAMES = {
    -2: "METIS_ERROR_INPUT",
    -3: "METIS_ERROR_MEMORY",
    -4: "METIS_ERROR",
}

_IDX = np.int32
_idx_p = ctypes.POINTER(ctypes.c_int32)


@functools.lru_cache(maxsize=1)
def _library() -> ctypes.CDLL:
    """Load libmetis once; lazily, so importing this module never fails."""
    name = ctypes.util.find_library("metis") or _FALLBACK_LIBRARY
    lib = ctypes.CDLL(name)
    lib.METIS_SetDefaultOptions.argtypes = [_idx_p]
    lib.METIS_SetDefaultOptions.restype = ctypes.c_int
    # nvtxs, ncon, xadj, adjncy, vwgt, vsize, adjwgt, nparts, tpwgts, ubvec,
    # options, edgecut, part
    lib.METIS_PartGraphKway.argtypes = [
        _idx_p, _idx_p, _idx_p, _idx_p, _idx_p, _idx_p, _idx_p, _idx_p,
        ctypes.c_void_p, ctypes.c_void_p, _idx_p, _idx_p, _idx_p,
    ]
    lib.METIS_PartGraphKway.restype = ctypes.c_int
    return lib


def _check(status: int, what: str) -> None:
    if status != METIS_OK:
        name = _METIS_STATUS_NAMES.get(status, f"unknown status {status}")
        raise RuntimeError(f"{what} failed: {name}")


def _idx_array(values, name: str) -> np.ndarray:
    values = np.asarray(values)
    if values.size and (values.min() < 0 or values.max() > np.iinfo(_IDX).max):
        raise ValueError(f"{name} does not fit METIS's 32-bit idx_t")
    return np.ascontiguousarray(values, dtype=_IDX)


def _ptr(array: np.ndarray):
    return array.ctypes.data_as(_idx_p)


def part_graph_kway(xadj, adjncy, nparts: int, seed: int = 0,
                    ufactor: int | None = None) -> tuple[np.ndarray, int]:
    """Partition the undirected graph in CSR form (xadj, adjncy; symmetric, no
    self loops, 0-based) into ``nparts`` parts with METIS's multilevel k-way
    scheme, minimising the edge cut.

    ``seed`` makes the result deterministic; ``ufactor`` is the allowed load
    imbalance in thousandths (None: METIS's k-way default, 30 = 3 %).
    Returns (part, edge_cut): the (n,) int32 part of every vertex and the
    number of edges whose ends lie in different parts.
    """
    nparts = int(nparts)
    if nparts < 1:
        raise ValueError(f"nparts must be >= 1, got {nparts}")
    xadj = _idx_array(xadj, "xadj")
    adjncy = _idx_array(adjncy, "adjncy")
    n = xadj.shape[0] - 1
    # METIS trusts its input and crashes on a bad graph: check it here (O(nnz)).
    if (n < 0 or xadj[0] != 0 or xadj[-1] != adjncy.shape[0]
            or np.any(np.diff(xadj) < 0)
            or (adjncy.size and adjncy.max() >= n)):
        raise ValueError("xadj/adjncy are not a 0-based CSR graph")
    if nparts > max(n, 1):
        # METIS then returns fewer, lopsided parts rather than an error
        raise ValueError(f"cannot split {n} vertices into {nparts} non-empty parts")
    if nparts == 1 or n == 0:
        return np.zeros(n, dtype=np.int32), 0

    lib = _library()
    options = np.empty(METIS_NOPTIONS, dtype=_IDX)
    _check(lib.METIS_SetDefaultOptions(_ptr(options)), "METIS_SetDefaultOptions")
    options[METIS_OPTION_SEED] = seed
    options[METIS_OPTION_NUMBERING] = 0
    if ufactor is not None:
        options[METIS_OPTION_UFACTOR] = ufactor

    nvtxs = ctypes.c_int32(n)
    ncon = ctypes.c_int32(1)
    c_nparts = ctypes.c_int32(nparts)
    edge_cut = ctypes.c_int32(0)
    part = np.zeros(n, dtype=_IDX)
    status = lib.METIS_PartGraphKway(
        ctypes.byref(nvtxs), ctypes.byref(ncon), _ptr(xadj), _ptr(adjncy),
        None, None, None, ctypes.byref(c_nparts), None, None,
        _ptr(options), ctypes.byref(edge_cut), _ptr(part))
    _check(status, "METIS_PartGraphKway")
    return part, int(edge_cut.value)
