"""The float32 block symmetric Gauss-Seidel against its definition in float64:
y = M^-1 x with M = (D + L) D^-1 (D + U), D the 3x3 block diagonal.
float32 carries ~6e-8 relative precision; through two triangular sweeps on a
diagonally dominant matrix the error stays below 1e-5 relative."""
import numpy as np

from distcloth.linalg.pattern import BlockPattern
from distcloth.linalg.sgs32 import _invert_diagonal, _sgs_apply, local_block_float32


def test_sgs32_matches_definition():
    rng = np.random.default_rng(0)
    n_owned, n_local = 20, 24
    elements = np.array([rng.choice(n_local, 2, replace=False) for _ in range(60)])
    pattern = BlockPattern(n_owned, n_local, [elements])
    data = rng.normal(size=(pattern.nnzb, 3, 3))
    data = data + data.transpose(0, 2, 1)
    data[pattern.diag_slots] += 20 * np.eye(3)
    indptr, cols, d32 = local_block_float32(pattern.indptr, pattern.block_cols, data, n_owned)
    assert np.all(cols < n_owned)                       # ghost columns dropped
    diag_inv = np.zeros((n_owned, 3, 3), np.float32)
    _invert_diagonal(indptr, cols, d32, diag_inv)
    x = rng.normal(size=(n_owned, 3)).astype(np.float32)
    y = np.zeros_like(x)
    _sgs_apply(indptr, cols, d32, diag_inv, x, y)
    A = pattern.local_matrix(data).toarray()[:, : 3 * n_owned]
    D = np.zeros_like(A)
    for i in range(n_owned):
        D[3 * i:3 * i + 3, 3 * i:3 * i + 3] = A[3 * i:3 * i + 3, 3 * i:3 * i + 3]
    L = np.tril(A - D)
    U = np.triu(A - D)
    M = (D + L) @ np.linalg.solve(D, D + U)
    expected = np.linalg.solve(M, x.astype(np.float64).ravel())
    assert np.abs(y.ravel() - expected).max() <= 1e-5 * np.abs(expected).max()
