"""Assembly of the implicit system's block values and the constrained solve.

The matrix of every implicit scheme is A = gamma M - beta df/dv - alpha df/dx
on the owned rows (Baraff and Witkin 1998 §4); each force term adds its own
blocks at the value positions it was given once (``ForceTerm.bind``), so a
step only writes values into the fixed pattern (EG07 tutorial, Part 1 §5.7).
"""
from __future__ import annotations

import numpy as np

from .constraints import Constraints, filter_system
from .log_events import logged


def assemble_blocks(pattern, mass_owned: np.ndarray, terms, alpha: float, beta: float,
                    gamma: float = 1.0) -> np.ndarray:
    """Block values (nnzb, 3, 3) of A = gamma M - beta df/dv - alpha df/dx."""
    data = pattern.new_values()
    m = gamma * mass_owned
    ds = pattern.diag_slots
    for a in range(3):
        data[ds, a, a] += m
    for t in terms:
        if t.has_jacobian:
            t.add_to_system(data, alpha, beta)
    return data


def gershgorin_bound(pattern, stiffness: np.ndarray, mass_owned: np.ndarray) -> float:
    """Gershgorin bound of lambda_max(M^-1 K) over this rank's scalar rows from
    the blocks of K: max_i sum_j |K_ij| / m_i."""
    rows = np.abs(stiffness).sum(axis=2)                 # (nnzb, 3) scalar-row sums per block
    rowsum = np.zeros((pattern.n_owned, 3))
    for a in range(3):
        rowsum[:, a] = np.bincount(pattern.block_rows, weights=rows[:, a],
                                   minlength=pattern.n_owned)
    return float(np.max(rowsum.max(axis=1) / mass_owned, initial=0.0))


def solve_constrained(system, pattern, data: np.ndarray, rhs: np.ndarray, cons: Constraints,
                      guess: np.ndarray | None = None):
    """dv on the owned rows solving A dv = rhs under the constraints (pre-filtered
    CG: constraints.py), starting from the velocity change ``guess`` if given,
    and the solve's information."""
    with logged("solve:filter"):
        fdata, frhs = filter_system(pattern, data, rhs, cons)
    with logged("solve:set_values"):
        system.set_values(fdata)
    owned = cons.index < pattern.n_owned
    y0 = None
    if guess is not None:                 # the filtered unknown is dv - z
        y0 = guess.copy()
        y0[cons.index[owned]] -= cons.z[owned]
    y, info = system.solve(frhs, y0)
    y[cons.index[owned]] += cons.z[owned]
    return y, info


def constraint_impulses(pattern, data: np.ndarray, rhs: np.ndarray, dv_local: np.ndarray):
    """A dv - b on the owned rows (``dv_local``: the solution with its ghost
    rows): zero, up to the solver's tolerance, where the system was solved; at
    a constrained vertex the impulse its constraint added to the momentum
    balance M dv = h f + impulse (Baraff and Witkin 1998 §5.3: the constraint
    force is what the filtered rows leave out)."""
    return (pattern.local_matrix(data) @ dv_local.ravel()).reshape(-1, 3) - rhs
