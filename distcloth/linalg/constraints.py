"""Pre-filtered constraints (Baraff and Witkin 1998, §5.3).

A constraint on vertex i is a 3x3 projection S_i onto its free directions and
a prescribed velocity change z_i in the constrained ones (a pin: S = 0; a
contact: S = I - n n^T).  Instead of the modified-PCG of Baraff and Witkin we
solve the SPD system

    (S A S + d_i (I - S)) y = S (b - A z),    dv = y + z

which has the same sparsity as A, so the matrix pattern never changes and
any PETSc preconditioner applies.  Only blocks in rows or columns of
constrained vertices are touched.  d_i, the mean of vertex i's diagonal in
A, puts the constrained directions at the scale of the free ones (A is in
units of mass, m + h^2 k, so a 1 there depends on the units and the step):
the solution is the same, the filtered system scales with A, and CG with
block-Jacobi SGS or GAMG takes fewer iterations where contacts hold part of
a vertex (docs/benchmarks.md, "At scale").
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Constraints:
    """Constrained local vertices (owned or ghost), with S and z for each."""
    index: np.ndarray      # (m,) local vertex indices, sorted unique
    S: np.ndarray          # (m, 3, 3)
    z: np.ndarray          # (m, 3) prescribed velocity change

    @staticmethod
    def none():
        return Constraints(np.zeros(0, np.int64), np.zeros((0, 3, 3)), np.zeros((0, 3)))

    def dense_z(self, n_local: int) -> np.ndarray:
        z = np.zeros((n_local, 3))
        z[self.index] = self.z
        return z


def filter_system(pattern, data: np.ndarray, rhs: np.ndarray, cons: Constraints):
    """Return (filtered block values, filtered right-hand side) for the owned rows.

    ``data`` is not modified.  ``rhs`` is (n_owned, 3)."""
    if cons.index.size == 0:
        return data, rhs
    n_owned, n_local = pattern.n_owned, pattern.n_local
    if np.any(cons.z):
        z = cons.dense_z(n_local)
        Az = (pattern.local_matrix(data) @ z.ravel()).reshape(n_owned, 3)
    else:    # pins at rest, resting contacts: no matrix product to build
        Az = 0.0
    slot = np.full(n_local, -1, dtype=np.int64)
    slot[cons.index] = np.arange(cons.index.size)
    out = data.copy()
    rs = slot[pattern.block_rows]
    cs = slot[pattern.block_cols]
    rows_hit = np.nonzero(rs >= 0)[0]
    out[rows_hit] = np.einsum("nij,njk->nik", cons.S[rs[rows_hit]], out[rows_hit])
    cols_hit = np.nonzero(cs >= 0)[0]
    out[cols_hit] = np.einsum("nij,njk->nik", out[cols_hit], cons.S[cs[cols_hit]])
    owned = cons.index[cons.index < n_owned]
    diag = pattern.diag_slots[owned]
    scale = np.einsum("nii->n", data[diag]) / 3.0
    out[diag] += (np.eye(3)[None] - cons.S[slot[owned]]) * scale[:, None, None]
    frhs = rhs - Az
    frhs[owned] = np.einsum("nij,nj->ni", cons.S[slot[owned]], frhs[owned])
    return out, frhs
