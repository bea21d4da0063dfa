"""Single-precision block symmetric Gauss-Seidel, block Jacobi over the ranks.

EG07 tutorial, Part 1 §5.7: the SpMV and the preconditioner are bound by memory
traffic, so storing the matrix in single precision halves the data moved.
Debian's PETSc is double only, so this is a petsc4py Python PC: each rank
keeps a float32 copy of its diagonal block (the owned rows and columns of
the filtered system, the same block PETSc's block Jacobi would take) and
applies one symmetric Gauss-Seidel sweep with 3x3 point blocks, compiled
with numba.  CG itself stays in double precision.

Use it with

    solver: {pc_type: python, pc_python_type: distcloth.linalg.sgs32.SinglePrecisionSGS}

The block values come from ``LinearSystem.set_values``, which composes them
on the matrix (``Mat.setAttr``) so the PC needs no extraction from PETSc.
"""
from __future__ import annotations

import numpy as np
from numba import njit

ATTR = "distcloth_local_blocks"


@njit(cache=True)
def _invert_diagonal(indptr, cols, data, diag_inv):
    n = indptr.shape[0] - 1
    for i in range(n):
        for p in range(indptr[i], indptr[i + 1]):
            if cols[p] == i:
                diag_inv[i] = np.linalg.inv(data[p].astype(np.float64)).astype(np.float32)


@njit(cache=True)
def _sgs_apply(indptr, cols, data, diag_inv, x, y):
    """y = M^-1 x with M = (D + L) D^-1 (D + U): forward then backward block sweep."""
    n = indptr.shape[0] - 1
    w = np.zeros((n, 3), dtype=np.float32)
    r = np.zeros(3, dtype=np.float32)
    for i in range(n):                       # (D + L) w = x
        for a in range(3):
            r[a] = x[i, a]
        for p in range(indptr[i], indptr[i + 1]):
            j = cols[p]
            if j < i:
                for a in range(3):
                    for b in range(3):
                        r[a] -= data[p, a, b] * w[j, b]
        for a in range(3):
            acc = np.float32(0.0)
            for b in range(3):
                acc += diag_inv[i, a, b] * r[b]
            w[i, a] = acc
    for i in range(n - 1, -1, -1):           # (D + U) y = D w, i.e. y = w - D^-1 U y
        for a in range(3):
            r[a] = 0.0
        for p in range(indptr[i], indptr[i + 1]):
            j = cols[p]
            if j > i:
                for a in range(3):
                    for b in range(3):
                        r[a] += data[p, a, b] * y[j, b]
        for a in range(3):
            acc = np.float32(0.0)
            for b in range(3):
                acc += diag_inv[i, a, b] * r[b]
            y[i, a] = w[i, a] - acc


def local_block_float32(indptr, block_cols, data, n_owned):
    """The owned-columns part of this rank's rows as float32 block CSR."""
    keep = block_cols < n_owned
    counts = np.add.reduceat(keep.astype(np.int64), indptr[:-1]) if n_owned else np.zeros(0, np.int64)
    counts[np.diff(indptr) == 0] = 0
    new_indptr = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    return new_indptr, block_cols[keep].astype(np.int64), data[keep].astype(np.float32)


class SinglePrecisionSGS:
    """petsc4py Python PC context (``pc_python_type``)."""

    def setUp(self, pc):
        A, _ = pc.getOperators()
        indptr, block_cols, data, n_owned = A.getAttr(ATTR)
        self.indptr, self.cols, self.data = local_block_float32(indptr, block_cols, data, n_owned)
        self.diag_inv = np.zeros((n_owned, 3, 3), dtype=np.float32)
        _invert_diagonal(self.indptr, self.cols, self.data, self.diag_inv)
        self.n = n_owned

    def apply(self, pc, x, y):
        xs = x.array_r.reshape(-1, 3).astype(np.float32)
        ys = np.zeros_like(xs)
        _sgs_apply(self.indptr, self.cols, self.data, self.diag_inv, xs, ys)
        y.array[:] = ys.ravel()

    def view(self, pc, viewer):
        viewer.printfASCII("  distcloth float32 block symmetric Gauss-Seidel on each rank's block\n")
