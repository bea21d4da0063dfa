"""Mass-spring forces with exact Jacobians (Vassilev et al. 2001 §2.2, Eq. 2).

Spring s joins local vertices i, j with rest length l0, stiffness k and
damping c.  With d = x_i - x_j, l = |d|, u = d / l:

    f_i = -k (l - l0) u  -  c (u . (v_i - v_j)) u ,   f_j = -f_i

    df_i/dx_i = -H,  H = k u u^T + k (1 - l0/l) (I - u u^T)
    df_i/dv_i = -c u u^T

The geometric term k (1 - l0/l)(I - u u^T) is negative for a compressed
spring, making H indefinite; for the system matrix it is clamped at zero
(Choi and Ko 2002) so the assembled matrix stays symmetric positive definite.
The damping force also depends on x through u; that d f_damp/dx term is not
symmetric and is dropped from the matrix, as Baraff and Witkin (1998) do.
``clamp=False`` gives the exact Hessian, used by the finite-difference tests.

Kernels take local arrays (owned vertices then ghosts) and write forces on
every local row; the caller keeps the owned rows.  Each spring's energy is
weighted by ``weight`` (the fraction of its ends this rank owns, 1 or 1/2) so
the ranks' sums add up to the global energy exactly once.
"""
from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def spring_forces(x, v, springs, rest, k, c, weight, clamp, want_jac,
                  force, hess, unit, strain_kind_mask):
    """Accumulate spring forces into ``force`` (n_local, 3).

    With ``want_jac`` fills ``hess`` (ns, 3, 3) with H and ``unit`` (ns, 3)
    with u.  Returns (weighted elastic energy, largest engineering strain over
    springs with ``strain_kind_mask`` set)."""
    energy = 0.0
    max_strain = 0.0
    ns = springs.shape[0]
    for s in range(ns):
        i = springs[s, 0]
        j = springs[s, 1]
        d0 = x[i, 0] - x[j, 0]
        d1 = x[i, 1] - x[j, 1]
        d2 = x[i, 2] - x[j, 2]
        length = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        inv = 1.0 / length
        u0 = d0 * inv
        u1 = d1 * inv
        u2 = d2 * inv
        ext = length - rest[s]
        energy += 0.5 * k[s] * ext * ext * weight[s]
        if strain_kind_mask[s]:
            strain = ext / rest[s]
            if strain > max_strain:
                max_strain = strain
        vr = (u0 * (v[i, 0] - v[j, 0]) + u1 * (v[i, 1] - v[j, 1])
              + u2 * (v[i, 2] - v[j, 2]))
        mag = -k[s] * ext - c[s] * vr
        force[i, 0] += mag * u0
        force[i, 1] += mag * u1
        force[i, 2] += mag * u2
        force[j, 0] -= mag * u0
        force[j, 1] -= mag * u1
        force[j, 2] -= mag * u2
        if want_jac:
            geo = k[s] * (1.0 - rest[s] * inv)
            if clamp and geo < 0.0:
                geo = 0.0
            axial = k[s] - geo
            unit[s, 0] = u0
            unit[s, 1] = u1
            unit[s, 2] = u2
            for a in range(3):
                for b in range(3):
                    hess[s, a, b] = axial * unit[s, a] * unit[s, b]
                hess[s, a, a] += geo
    return energy, max_strain


@njit(cache=True)
def spring_discrete_gradient(x0, x1, springs, rest, k, force):
    """Accumulate the elastic spring force of a step from x0 to x1 into ``force``:
    f_i = -k (lbar - l0) / lbar * (d0 + d1)/2, lbar = (|d0| + |d1|)/2, the
    discrete gradient of 1/2 k (l - l0)^2 (Gonzalez 1996; Simo and Tarnow 1992):
    since |d1| - |d0| = (d0 + d1) . (d1 - d0) / (|d0| + |d1|), f_i . (d1 - d0)
    = -(U1 - U0) exactly."""
    for s in range(springs.shape[0]):
        i = springs[s, 0]
        j = springs[s, 1]
        a0 = x0[i, 0] - x0[j, 0]
        a1 = x0[i, 1] - x0[j, 1]
        a2 = x0[i, 2] - x0[j, 2]
        b0 = x1[i, 0] - x1[j, 0]
        b1 = x1[i, 1] - x1[j, 1]
        b2 = x1[i, 2] - x1[j, 2]
        lbar = 0.5 * (np.sqrt(a0 * a0 + a1 * a1 + a2 * a2) + np.sqrt(b0 * b0 + b1 * b1 + b2 * b2))
        mag = -0.5 * k[s] * (lbar - rest[s]) / lbar
        f0 = mag * (a0 + b0)
        f1 = mag * (a1 + b1)
        f2 = mag * (a2 + b2)
        force[i, 0] += f0
        force[i, 1] += f1
        force[i, 2] += f2
        force[j, 0] -= f0
        force[j, 1] -= f1
        force[j, 2] -= f2


@njit(cache=True)
def spring_stiffness_product(springs, hess, w, out):
    """out += (df/dx) w for the springs' Hessian blocks: (df/dx w)_i = -H (w_i - w_j)."""
    for s in range(springs.shape[0]):
        i = springs[s, 0]
        j = springs[s, 1]
        for a in range(3):
            acc = 0.0
            for b in range(3):
                acc += hess[s, a, b] * (w[i, b] - w[j, b])
            out[i, a] -= acc
            out[j, a] += acc


@njit(cache=True)
def add_spring_blocks(hess, unit, c, alpha, beta, slots, data):
    """System blocks of A = gamma M - beta df/dv - alpha df/dx for springs.

    W = alpha H + beta c u u^T goes to (i,i) and (j,j) with +, (i,j), (j,i)
    with -.  ``slots`` (ns, 4) hold the value-array positions of the blocks
    (ii, ij, ji, jj), -1 where the row is a ghost (kept by its owner)."""
    for s in range(hess.shape[0]):
        cs = beta * c[s]
        for q in range(4):
            slot = slots[s, q]
            if slot < 0:
                continue
            sign = 1.0 if (q == 0 or q == 3) else -1.0
            for a in range(3):
                for b in range(3):
                    data[slot, a, b] += sign * (alpha * hess[s, a, b]
                                                + cs * unit[s, a] * unit[s, b])


def spring_energy_only(x, springs, rest, k, weight):
    """Weighted elastic energy, vectorised (for diagnostics after a step)."""
    d = x[springs[:, 0]] - x[springs[:, 1]]
    ext = np.sqrt(np.einsum("ij,ij->i", d, d)) - rest
    return 0.5 * float(np.sum(k * ext * ext * weight))
