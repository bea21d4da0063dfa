"""Pre-filtered constraints: (S A S + d (I - S)) y = S (b - A z), dv = y + z.

The defining properties (Baraff and Witkin 1998, §5.3): the constrained
components take the prescribed change, (I - S) dv = (I - S) z, and the free
components satisfy the equations, S (A dv - b) = 0.  Checked with dense
algebra on a random SPD block system, for pins (S = 0), plane contacts
(S = I - n n^T) and a mix, with some constrained vertices being ghosts;
and the filtered system scales with A (d, each vertex's mean diagonal).
"""
import numpy as np
import pytest

from distcloth.linalg.constraints import Constraints, filter_system
from distcloth.linalg.pattern import BlockPattern


def random_system(rng, n_owned, n_local, ne=30):
    elements = np.array([rng.choice(n_local, 2, replace=False) for _ in range(ne)])
    pattern = BlockPattern(n_owned, n_local, [elements])
    # a symmetric positive definite matrix on all local vertices, restricted to owned rows
    B = rng.normal(size=(3 * n_local, 3 * n_local))
    mask = np.zeros((n_local, n_local), bool)
    mask[np.arange(n_local), np.arange(n_local)] = True
    mask[elements[:, 0], elements[:, 1]] = True
    mask[elements[:, 1], elements[:, 0]] = True
    full = np.kron(mask, np.ones((3, 3))) * (B + B.T)
    full += np.eye(3 * n_local) * (np.abs(full).sum(axis=1).max() + 1.0)
    data = full.reshape(n_local, 3, n_local, 3).transpose(0, 2, 1, 3)[
        pattern.block_rows, pattern.block_cols].copy()
    return pattern, data, full


def projections(rng, kinds):
    S = []
    for kind in kinds:
        if kind == "pin":
            S.append(np.zeros((3, 3)))
        else:
            nrm = rng.normal(size=3)
            nrm /= np.linalg.norm(nrm)
            S.append(np.eye(3) - np.outer(nrm, nrm))
    return np.array(S)


@pytest.mark.parametrize("kinds", [["pin"] * 3, ["plane"] * 3, ["pin", "plane", "plane", "pin"]])
def test_filtered_solve_properties(kinds):
    rng = np.random.default_rng(len(kinds))
    n_owned, n_local = 10, 13                 # vertices 10..12 are ghosts
    pattern, data, full = random_system(rng, n_owned, n_local)
    idx = np.sort(rng.choice(n_local, len(kinds), replace=False))
    idx[-1] = n_local - 1                     # at least one constrained ghost
    idx = np.unique(idx)
    cons = Constraints(idx, projections(rng, kinds[: idx.size]), rng.normal(size=(idx.size, 3)))
    b = rng.normal(size=(n_owned, 3))
    fdata, frhs = filter_system(pattern, data, b, cons)
    # the filtered matrix restricted to owned rows/columns is what the solver sees;
    # ghost columns of the filtered matrix meet y = 0 in constrained ghost directions
    Af = pattern.local_matrix(fdata).toarray()[:, : 3 * n_owned]
    assert np.allclose(Af, Af.T, atol=1e-12)                    # still symmetric
    assert np.linalg.eigvalsh(Af).min() > 0                     # still positive definite
    y = np.linalg.solve(Af, frhs.ravel()).reshape(n_owned, 3)
    z_local = cons.dense_z(n_local)
    dv = y + z_local[:n_owned]
    S_local = np.tile(np.eye(3), (n_local, 1, 1))
    S_local[idx] = cons.S
    # ghosts carry their own constraint (owned by another rank): y = 0 there, dv = z
    dv_local = np.vstack([dv, z_local[n_owned:]])
    A = full[: 3 * n_owned]
    residual = (A @ dv_local.ravel()).reshape(n_owned, 3) - b
    free = np.einsum("nij,nj->ni", S_local[:n_owned], residual)
    assert np.abs(free).max() <= 1e-10 * np.abs(b).max()
    fixed = np.einsum("nij,nj->ni", np.eye(3) - S_local[:n_owned], dv - z_local[:n_owned])
    assert np.abs(fixed).max() <= 1e-12


def test_the_filtered_system_scales_with_the_matrix():
    # A in other units (or at another step) is c A: the filtered matrix must be
    # c times the filtered one, so its conditioning does not depend on them (a
    # unit block in the constrained directions did); the right-hand side as well
    rng = np.random.default_rng(3)
    n_owned, n_local = 10, 13
    pattern, data, _ = random_system(rng, n_owned, n_local)
    idx = np.array([1, 4, 7, 12])
    cons = Constraints(idx, projections(rng, ["pin", "plane", "plane", "plane"]),
                       rng.normal(size=(idx.size, 3)))
    b = rng.normal(size=(n_owned, 3))
    fdata, frhs = filter_system(pattern, data, b, cons)
    for c in (1e-6, 1e3):
        cdata, crhs = filter_system(pattern, c * data, c * b, cons)
        np.testing.assert_allclose(cdata, c * fdata, rtol=1e-12, atol=0.0)
        np.testing.assert_allclose(crhs, c * frhs, rtol=1e-12, atol=1e-300)
    # a pinned vertex's block is its mean diagonal times the identity
    pin = pattern.diag_slots[1]
    np.testing.assert_allclose(fdata[pin], np.trace(data[pin]) / 3.0 * np.eye(3), rtol=1e-12)


def test_no_constraints_is_identity():
    rng = np.random.default_rng(9)
    pattern, data, _ = random_system(rng, 6, 6)
    b = rng.normal(size=(6, 3))
    fdata, frhs = filter_system(pattern, data, b, Constraints.none())
    assert fdata is data and frhs is b
