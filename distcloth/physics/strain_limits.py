"""Strain limiting kernels: one Jacobi pass of each limiter over the springs.

Both limiters act on the membrane springs (structural and shear) of the
model, each with its bound: the largest engineering strain l / l0 - 1 it
allows.  Kernels take local arrays (owned vertices, then ghosts, ghosts
valid) and return per-vertex corrections on every local row; the caller
keeps the owned rows, averages them over the springs that touched each
vertex (Jacobi with averaging) and refreshes the ghosts between passes.
The result does not depend on how the cloth is partitioned: every owned
vertex's correction comes from the same springs and the same values on any
number of ranks, up to the order of a floating-point sum.

``provot_pass``: Provot 1995 (cited by Vassilev et al. 2001 §3.1), the
position correction of over-stretched springs.  A spring longer than
(1 + bound) l0 is shortened to that length, its two ends moving along it
in inverse proportion to their masses (a vertex that must not move has
inverse mass 0 and the other end moves the whole way); Provot moves both
ends equally, which is the same for the equal masses of his grid, and the
mass weighting keeps the correction from moving the cloth's centre of mass.

``velocity_pass``: Vassilev et al. 2001 §3.2, the velocity directional
modification.  For a spring over its bound whose ends separate (u . (v2 -
v1) > 0, u from p1 to p2), with alpha the angle between u and the
directional vector v_dir = v_grav + v_object (Eq. 6):

* |cos alpha| < 0.3: both tangential velocities u . v become their average
  (Eq. 5; mass-weighted here, Eq. 5 for equal masses);
* otherwise the rear point (p1 if cos alpha > 0, else p2) takes the front
  point's tangential velocity, so that it "catches up".

Anchors keep priority: a pinned or contact-constrained vertex never
changes, and a spring with such an end moves only its other end, to the
anchor's tangential velocity, whatever the rule says.  A vertex held by
several anchors takes the one velocity change that meets all their targets
(their directions' least-squares solution), not their average, and ignores
the rule's changes of its other springs in that pass.
"""
from __future__ import annotations

import numpy as np
from numba import njit

COS_PERPENDICULAR = 0.3   # Vassilev et al. 2001 §3.2: |cos alpha| below this is "perpendicular"


def spring_strain(x: np.ndarray, springs: np.ndarray, rest: np.ndarray) -> np.ndarray:
    """(m,) engineering strain l / l0 - 1 of each spring."""
    d = x[springs[:, 1]] - x[springs[:, 0]]
    return np.sqrt(np.einsum("ij,ij->i", d, d)) / rest - 1.0


def _accumulate(n: int, rows: np.ndarray, values: np.ndarray) -> np.ndarray:
    """(n, 3): the values (k, 3) summed into their rows (bincount: no np.add.at)."""
    out = np.empty((n, 3))
    for c in range(3):
        out[:, c] = np.bincount(rows, weights=values[:, c], minlength=n)
    return out


def provot_pass(x, springs, rest, limit, inv_mass):
    """One Jacobi pass of Provot's correction.

    ``rest`` (m,): rest lengths l0; ``limit`` (m,): the largest length
    (1 + bound) l0 of each spring; ``inv_mass`` (n,): 0 for a vertex that
    must not move.  Returns (correction sum (n, 3), number of corrections
    (n,), springs corrected, the largest strain above its bound before the
    pass, over every spring: the passes' stopping test, from the same
    lengths)."""
    n = x.shape[0]
    i, j = springs[:, 0], springs[:, 1]
    d = x[j] - x[i]
    length = np.sqrt(np.einsum("ij,ij->i", d, d))
    worst = float(((length - limit) / rest).max(initial=-np.inf))
    wi, wj = inv_mass[i], inv_mass[j]
    w = wi + wj
    act = (length > limit) & (w > 0.0)
    if not np.any(act):
        return np.zeros((n, 3)), np.zeros(n), 0, worst
    i, j, wi, wj, w = i[act], j[act], wi[act], wj[act], w[act]
    # the excess along the spring, shared by inverse mass: p1 moves towards p2
    step = ((length[act] - limit[act]) / length[act])[:, None] * d[act]
    rows = np.concatenate([i, j])
    moves = np.concatenate([(wi / w)[:, None] * step, -(wj / w)[:, None] * step])
    moving = np.concatenate([wi, wj]) > 0.0
    corr = _accumulate(n, rows[moving], moves[moving])
    count = np.bincount(rows[moving], minlength=n).astype(np.float64)
    return corr, count, int(act.sum()), worst


def velocity_pass(x, v, springs, limit, mass, anchored, vdir, tolerance,
                  perpendicular_cos=COS_PERPENDICULAR):
    """One Jacobi pass of the velocity directional modification.

    ``anchored`` (n,) bool: pins and contact vertices, which keep their
    velocity; ``vdir`` (m, 3): the directional vector of each spring;
    ``tolerance`` (m,): the separation speed along each spring (m/s) below
    which it is left alone; ``perpendicular_cos``: the |cos alpha| below
    which Eq. 5 applies (inf: always, the rule for static bodies).  Returns (velocity change (n, 3), springs
    modified)."""
    n = x.shape[0]
    i, j = springs[:, 0], springs[:, 1]
    d = x[j] - x[i]
    length = np.sqrt(np.einsum("ij,ij->i", d, d))
    u = d / length[:, None]
    s1 = np.einsum("ij,ij->i", v[i], u)
    s2 = np.einsum("ij,ij->i", v[j], u)
    ai, aj = anchored[i], anchored[j]
    act = (length > limit) & (s2 - s1 > tolerance) & ~(ai & aj)
    if not np.any(act):
        return np.zeros((n, 3)), 0
    i, j, u, s1, s2, ai, aj = i[act], j[act], u[act], s1[act], s2[act], ai[act], aj[act]
    dirn = vdir[act]
    dnorm = np.sqrt(np.einsum("ij,ij->i", dirn, dirn))
    cos = np.einsum("ij,ij->i", u, dirn) / np.where(dnorm > 0.0, dnorm, 1.0)
    mi, mj = mass[i], mass[j]
    average = (mi * s1 + mj * s2) / (mi + mj)
    # the rule's target tangential velocity and which ends take it
    perpendicular = np.abs(cos) < perpendicular_cos
    rear_is_1 = cos > 0.0
    target = np.where(perpendicular, average, np.where(rear_is_1, s2, s1))
    move1 = perpendicular | rear_is_1
    move2 = perpendicular | ~rear_is_1
    # an anchored end holds: the other end takes its velocity, with priority
    priority = ai | aj
    target = np.where(ai, s1, np.where(aj, s2, target))
    move1 = np.where(priority, ~ai, move1)
    move2 = np.where(priority, ~aj, move2)
    rows = np.concatenate([i[move1], j[move2]])
    dirs = np.concatenate([u[move1], u[move2]])
    change = np.concatenate([(target - s1)[move1], (target - s2)[move2]])
    prio = np.concatenate([priority[move1], priority[move2]])
    # a vertex held by an anchor takes only the changes of its held springs, all
    # at once (the velocity change that gives each its target); the others
    # average the rule's changes
    has_priority = np.bincount(rows[prio], minlength=n) > 0
    regular = ~prio & ~has_priority[rows]
    dv = _accumulate(n, rows[regular], change[regular][:, None] * dirs[regular])
    dv /= np.maximum(np.bincount(rows[regular], minlength=n), 1)[:, None]
    order = np.argsort(rows[prio], kind="stable")
    _held_changes(rows[prio][order], dirs[prio][order], change[prio][order], dv)
    return dv, int(act.sum())


@njit(cache=True)
def _held_changes(rows, dirs, change, dv):
    """For each run of equal ``rows``: the smallest velocity change w with
    dirs_e . w = change_e for every entry e of the run (least squares when
    they conflict), written to dv[row]."""
    k0 = 0
    m = rows.shape[0]
    while k0 < m:
        k1 = k0
        while k1 < m and rows[k1] == rows[k0]:
            k1 += 1
        U = dirs[k0:k1]
        gram = U @ U.T
        # directions within a few degrees of each other count as one (their
        # least-squares compromise), not as a near-singular system
        lam = np.linalg.pinv(gram, 1e-2) @ change[k0:k1]
        dv[rows[k0]] = U.T @ lam
        k0 = k1


def spring_classes(rest_positions, springs, shear_kind, weft) -> np.ndarray:
    """(m,) 0 weft, 1 warp, 2 shear for each membrane spring: shear springs
    by kind; a structural spring by the angle of its rest direction to the
    weft direction of its piece (``weft`` (m, 3)): within 22.5 degrees weft,
    within 22.5 degrees of perpendicular warp, otherwise shear (the
    diagonal edges of a triangle mesh)."""
    d = rest_positions[springs[:, 1]] - rest_positions[springs[:, 0]]
    d = d / np.linalg.norm(d, axis=1)[:, None]
    w = weft / np.linalg.norm(weft, axis=1)[:, None]
    c = np.abs(np.einsum("ij,ij->i", d, w))
    cls = np.where(c >= np.cos(np.pi / 8), 0, np.where(c <= np.sin(np.pi / 8), 1, 2))
    return np.where(shear_kind, 2, cls).astype(np.int8)
