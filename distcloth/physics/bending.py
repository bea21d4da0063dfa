"""Bending on hinge stencils: isometric quadratic bending and dihedral-angle bending.

The EG07 tutorial, Part 1 §4.3 (Fig. 11 b, c), surveys the bending models for triangle
meshes whose basic element is a *hinge*: two triangles sharing an edge.  Two
of them are implemented here:

* the isometric quadratic model of Bergou et al. 2006 (the same family as
  the linear bending of Volino and Magnenat-Thalmann 2006, Fig. 11 c): the
  energy is a fixed quadratic form of the positions, forces are linear and
  the Jacobian is constant;
* the dihedral-angle model of Bridson et al. 2003 (Fig. 11 b), with the
  energy quadratic in the angle as in discrete shells (Grinspun et al. 2003;
  also Baraff and Witkin 1998).

Hinge layout
------------
A hinge is a row (i0, i1, i2, i3): the interior edge x0 -> x1, triangle A =
(x0, x1, x2) in its own winding order and triangle B = (x1, x0, x3), i.e. the
neighbour that runs the edge the other way (consistent orientation).  With
e = x1 - x0 the (unnormalised, length = 2 area) normals are

    nA = e x (x2 - x0),      nB = (x3 - x0) x e,

which coincide for a flat, consistently oriented pair.  The signed dihedral
angle is

    theta = atan2( ((nB x nA) . e) / |e| ,  nA . nB )  in (-pi, pi],

zero when flat and **positive when the two triangles fold towards the side
their normals point to** (the surface is concave seen from its normal side,
e.g. a sheet with normals +z rolled around an axis lying above it).

Energies (B is the bending stiffness in N.m, bars denote the rest shape)
------------------------------------------------------------------------
Both models share one per-hinge constant, the weight of the hinge's
"diamond" area  Ae = (Abar_A + Abar_B) / 3  (discrete shells):

    dihedral:   E_h = C_HINGE * B * |ebar|^2 / (Abar_A + Abar_B) * (theta - theta0)^2
    isometric:  E_h = C_HINGE * B / (Abar_A + Abar_B) * |sum_a k_a x_a|^2
                    = 1/2 x^T Q_h x,   Q_h = (2 C_HINGE B / (Abar_A + Abar_B)) k k^T (x) I3

with k the cotangent stencil below.  For a small bend |sum k_a x_a| = |e| theta
+ O(theta^2) (the jump of the normal derivative of the position across the
edge, times |e|), so the two models agree to leading order.

The constant.  Bergou et al. write Q_h = 3/(A_A+A_B) k k^T, i.e. C_HINGE = 3/2,
which reproduces 1/2 B int (k1+k2)^2 dA on a *sphere*.  On a *cylinder*
(k1 = 1/R, k2 = 0) the hinge sum does not see the mean curvature alone: on
regular meshes (equilateral in any direction, or the split-square grid bent
along a grid axis) sum_h 3 |e|^2 theta^2/(A_A+A_B) tends to 3 (1/R)^2 area,
three times the continuum int (k1+k2)^2 dA.  (Split grid bent along an axis:
only the edges parallel to the cylinder axis bend, each by theta = h/R, h the
wing height; on an equilateral mesh bent across an edge direction some
hinges even get theta < 0.)  This is a known mesh-dependence (
of hinge energies; Grinspun et al. 2006, "Computing discrete shape operators
on general meshes").  Cloth bending rigidity B is measured in pure
cylindrical bending (Kawabata, moment per unit width per unit curvature), so
we calibrate on the cylinder:

    C_HINGE = 1/2   so that   E ~= 1/2 B (1/R)^2 area   for a cylindrical bend,

tested in tests/test_bending.py for both models.  (With this constant a
spherical bend of a regular equilateral mesh gets 1/3 of
1/2 B int (k1+k2)^2 dA, checked numerically.)

Cotangent stencil (Bergou et al. 2006; Wardetzky et al. 2007)
--------------------------------------------------------------
With alpha0, alpha1 the rest angles of triangle A at x0, x1 and beta0, beta1
those of triangle B at x0, x1:

    k = [cot alpha1 + cot beta1,  cot alpha0 + cot beta0,
         -cot alpha0 - cot alpha1,  -cot beta0 - cot beta1].

Derivation: for a piecewise-linear function f on the flat rest hinge,
sum_a k_a f_a = -|e| [df/dn] (jump of the normal derivative across the edge):
the hat function of x2 has gradient of size 1/h_A normal to the edge, and
|e|/h_A = cot alpha0 + cot alpha1; the edge vertices follow from
sum_a k_a = 0 (constants) and linear precision (sum_a k_a x_a = 0 for any
flat hinge, exactly).  Bergou's notation, e0 = x1 - x0, e1 = x2 - x0,
e2 = x3 - x0, e3 = x2 - x1, e4 = x3 - x1, c_ij = cot angle(e_i, e_j), gives
k = [c03 + c04, c01 + c02, -c01 - c03, -c02 - c04], the same vector.

Consequences (tested): Q annihilates translations, and for a flat rest
shape the rest positions and every rigid motion of them (linear precision),
so a flat sheet has zero energy and zero force at rest.

Limitation: the isometric model assumes a **flat rest shape** (Bergou et
al.'s derivation).  For a curved rest shape, 1/2 x^T Q x is not zero at rest
and the rest shape is not an equilibrium; subtracting x^T Q xbar is not
rotation invariant, so it is not done.  ``IsometricBendingTerm.rest_energy``
reports the energy of the rest shape so callers can check flatness.

Forces and Jacobians
--------------------
isometric:  f_a = -(2 C B / (A_A + A_B)) k_a s,  s = sum_b k_b x_b;
            df/dx = -Q, constant, exact.
dihedral:   f_a = -2 kb (theta - theta0) grad_a theta  with  kb the prefactor
            above and the gradient of Bridson et al. 2003:

    grad_2 theta = |e| nA / |nA|^2,   grad_3 theta = |e| nB / |nB|^2,
    grad_0 theta = -(1 - tA) grad_2 - (1 - tB) grad_3,
    grad_1 theta = -tA grad_2 - tB grad_3,
    tA = (x2 - x0).e / |e|^2,  tB = (x3 - x0).e / |e|^2.

The system matrix of the dihedral term uses the **Gauss-Newton Hessian**
H = 2 kb (grad theta)(grad theta)^T (symmetric positive semi-definite); the
dropped part 2 kb (theta - theta0) Hess(theta) vanishes at theta = theta0,
where H is exact.  ``stiffness_product`` applies the same H.
``hessian="exact"`` gives the full Hessian 2 kb (grad grad^T + (theta - theta0)
Hess theta) instead (chain rule on the gradient formulas, see
``hinge_angle_hessian``; finite-difference tested), recomputed on the fly.

All kernels take local arrays (owned vertices first, then ghosts), write
forces on every local row (the caller keeps the owned ones) and weight each
hinge's energy by ``weight`` (the fraction the caller says this rank owns),
exactly as the spring kernels do.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .base import ForceTerm

C_HINGE = 0.5
"""Per-hinge energy constant (see module docstring): cylinder-calibrated."""


# --------------------------------------------------------------------------
# topology and rest geometry (vectorised numpy)
# --------------------------------------------------------------------------

def hinges(triangles) -> np.ndarray:
    """Hinges (ne, 4) int64 of a consistently oriented triangle mesh.

    One row (i0, i1, i2, i3) per edge shared by exactly two triangles: the
    edge i0 -> i1 as it runs in the first triangle (lowest triangle index),
    i2 that triangle's third vertex, i3 the other triangle's third vertex.
    Boundary edges (one triangle) and non-manifold edges (three or more)
    get no hinge.  Raises ValueError if the two triangles of an edge run it
    the same way (inconsistent orientation: the signed angle and the rest
    angle would be meaningless).  Rows are sorted by edge key (min, max)."""
    tri = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    if tri.shape[0] == 0:
        return np.zeros((0, 4), dtype=np.int64)
    src = tri.ravel()                         # directed edges (a,b), (b,c), (c,a)
    dst = tri[:, [1, 2, 0]].ravel()
    opp = tri[:, [2, 0, 1]].ravel()           # the vertex opposite each edge
    n = int(tri.max()) + 1
    key = np.minimum(src, dst) * n + np.maximum(src, dst)
    order = np.argsort(key, kind="stable")    # stable: lower triangle first
    ks = key[order]
    starts = np.flatnonzero(np.concatenate([[True], ks[1:] != ks[:-1]]))
    counts = np.diff(np.concatenate([starts, [ks.shape[0]]]))
    two = starts[counts == 2]
    first, second = order[two], order[two + 1]
    if np.any(src[second] != dst[first]):
        raise ValueError("hinges: triangles are not consistently oriented")
    return np.stack([src[first], dst[first], opp[first], opp[second]], axis=1)


def hinge_angles(x, hinge) -> np.ndarray:
    """Signed dihedral angles (ne,) of the hinges at positions x."""
    x = np.ascontiguousarray(x, dtype=np.float64).reshape(-1, 3)
    hinge = np.ascontiguousarray(hinge, dtype=np.int64).reshape(-1, 4)
    out = np.empty(hinge.shape[0])
    _hinge_angles(x, hinge, out)
    return out


def _unwrapped(theta, near):
    """Arrays: ``theta`` moved by multiples of 2 pi to within pi of ``near``
    (angle_near, vectorised)."""
    return theta - 2.0 * np.pi * np.floor((theta - near) / (2.0 * np.pi) + 0.5)


def _cot(u, v):
    return np.einsum("ij,ij->i", u, v) / np.linalg.norm(np.cross(u, v), axis=1)


def hinge_rest_geometry(x_rest, hinge):
    """Rest data per hinge: (|ebar|^2, Abar_A + Abar_B, k (ne, 4) cotangent stencil)."""
    x = np.asarray(x_rest, dtype=np.float64)
    x0, x1, x2, x3 = (x[hinge[:, a]] for a in range(4))
    e = x1 - x0
    area = 0.5 * (np.linalg.norm(np.cross(e, x2 - x0), axis=1)
                  + np.linalg.norm(np.cross(x3 - x0, e), axis=1))
    ca0 = _cot(x1 - x0, x2 - x0)      # triangle A at x0
    ca1 = _cot(x0 - x1, x2 - x1)      # triangle A at x1
    cb0 = _cot(x1 - x0, x3 - x0)      # triangle B at x0
    cb1 = _cot(x0 - x1, x3 - x1)      # triangle B at x1
    k = np.stack([ca1 + cb1, ca0 + cb0, -ca0 - ca1, -cb0 - cb1], axis=1)
    return np.einsum("ij,ij->i", e, e), area, k


def _per_hinge(value, ne):
    return np.ascontiguousarray(np.broadcast_to(np.asarray(value, dtype=np.float64), (ne,)))


# --------------------------------------------------------------------------
# isometric kernels
# --------------------------------------------------------------------------

@njit(cache=True)
def isometric_forces(x, hinge, kvec, coef, weight, force):
    """force += -Q x per hinge, Q_h = coef_h k k^T (x) I3.  Returns the weighted
    energy sum_h weight_h * 1/2 coef_h |sum_a k_a x_a|^2."""
    energy = 0.0
    for h in range(hinge.shape[0]):
        s0 = 0.0
        s1 = 0.0
        s2 = 0.0
        for a in range(4):
            i = hinge[h, a]
            s0 += kvec[h, a] * x[i, 0]
            s1 += kvec[h, a] * x[i, 1]
            s2 += kvec[h, a] * x[i, 2]
        c = coef[h]
        energy += 0.5 * c * (s0 * s0 + s1 * s1 + s2 * s2) * weight[h]
        for a in range(4):
            i = hinge[h, a]
            m = c * kvec[h, a]
            force[i, 0] -= m * s0
            force[i, 1] -= m * s1
            force[i, 2] -= m * s2
    return energy


@njit(cache=True)
def isometric_stiffness_product(hinge, kvec, coef, w, out):
    """out += (df/dx) w = -Q w."""
    for h in range(hinge.shape[0]):
        s0 = 0.0
        s1 = 0.0
        s2 = 0.0
        for a in range(4):
            i = hinge[h, a]
            s0 += kvec[h, a] * w[i, 0]
            s1 += kvec[h, a] * w[i, 1]
            s2 += kvec[h, a] * w[i, 2]
        for a in range(4):
            i = hinge[h, a]
            m = coef[h] * kvec[h, a]
            out[i, 0] -= m * s0
            out[i, 1] -= m * s1
            out[i, 2] -= m * s2


@njit(cache=True)
def add_isometric_blocks(kvec, coef, alpha, slots, data):
    """data[slot(a,b)] += alpha coef k_a k_b I3 (slots (ne, 16) row-major, -1 skipped)."""
    for h in range(kvec.shape[0]):
        for a in range(4):
            for b in range(4):
                slot = slots[h, 4 * a + b]
                if slot < 0:
                    continue
                val = alpha * coef[h] * kvec[h, a] * kvec[h, b]
                data[slot, 0, 0] += val
                data[slot, 1, 1] += val
                data[slot, 2, 2] += val


# --------------------------------------------------------------------------
# dihedral kernels
# --------------------------------------------------------------------------

@njit(cache=True)
def hinge_angle_gradient(x, i0, i1, i2, i3, g):
    """Signed dihedral angle of one hinge; writes d theta / d x_a into g (4, 3)."""
    ex = x[i1, 0] - x[i0, 0]
    ey = x[i1, 1] - x[i0, 1]
    ez = x[i1, 2] - x[i0, 2]
    ax = x[i2, 0] - x[i0, 0]
    ay = x[i2, 1] - x[i0, 1]
    az = x[i2, 2] - x[i0, 2]
    bx = x[i3, 0] - x[i0, 0]
    by = x[i3, 1] - x[i0, 1]
    bz = x[i3, 2] - x[i0, 2]
    # nA = e x a,  nB = b x e
    nax = ey * az - ez * ay
    nay = ez * ax - ex * az
    naz = ex * ay - ey * ax
    nbx = by * ez - bz * ey
    nby = bz * ex - bx * ez
    nbz = bx * ey - by * ex
    le2 = ex * ex + ey * ey + ez * ez
    le = np.sqrt(le2)
    # (nB x nA) . e / |e|  and  nA . nB
    cx = nby * naz - nbz * nay
    cy = nbz * nax - nbx * naz
    cz = nbx * nay - nby * nax
    sn = (cx * ex + cy * ey + cz * ez) / le
    cs = nax * nbx + nay * nby + naz * nbz
    theta = np.arctan2(sn, cs)
    fa = le / (nax * nax + nay * nay + naz * naz)
    fb = le / (nbx * nbx + nby * nby + nbz * nbz)
    ta = (ax * ex + ay * ey + az * ez) / le2
    tb = (bx * ex + by * ey + bz * ez) / le2
    g[2, 0] = fa * nax
    g[2, 1] = fa * nay
    g[2, 2] = fa * naz
    g[3, 0] = fb * nbx
    g[3, 1] = fb * nby
    g[3, 2] = fb * nbz
    for c in range(3):
        g[0, c] = -(1.0 - ta) * g[2, c] - (1.0 - tb) * g[3, c]
        g[1, c] = -ta * g[2, c] - tb * g[3, c]
    return theta


@njit(cache=True)
def _hinge_angles(x, hinge, out):
    # the force kernel's angle, to the last bit (its gradient, written to a
    # scratch, costs little beside numpy's temporaries)
    g = np.empty((4, 3))
    for h in range(hinge.shape[0]):
        out[h] = hinge_angle_gradient(x, hinge[h, 0], hinge[h, 1], hinge[h, 2], hinge[h, 3], g)


@njit(cache=True)
def dihedral_energy(x, hinge, theta0, kb, weight, branch):
    """sum_h weight_h kb_h (theta_h - theta0_h)^2, each angle taken within pi
    of ``branch`` (as dihedral_forces) if it has one entry per hinge."""
    energy = 0.0
    follow = branch.shape[0] == hinge.shape[0]
    g = np.empty((4, 3))
    for h in range(hinge.shape[0]):
        theta = hinge_angle_gradient(x, hinge[h, 0], hinge[h, 1], hinge[h, 2], hinge[h, 3], g)
        if follow:
            theta = angle_near(theta, branch[h])
        d = theta - theta0[h]
        energy += kb[h] * d * d * weight[h]
    return energy


@njit(cache=True)
def angle_near(theta, near):
    """``theta`` moved by a multiple of 2 pi to within pi of ``near``."""
    return theta - 2.0 * np.pi * np.floor((theta - near) / (2.0 * np.pi) + 0.5)


@njit(cache=True)
def dihedral_forces(x, hinge, theta0, kb, weight, force, grad, coef, branch):
    """force += -2 kb (theta - theta0) grad theta per hinge.

    Fills grad (ne, 4, 3) with grad theta and coef (ne,) with 2 kb, the
    Gauss-Newton Hessian being coef grad grad^T.  ``branch`` (ne,) or empty:
    each angle is taken within pi of it (a fold pressed flat that passes
    +-pi goes on past it instead of jumping by 2 pi).  Returns
    (weighted energy sum_h weight_h kb_h (theta_h - theta0_h)^2, max |theta - theta0|)."""
    energy = 0.0
    worst = 0.0
    follow = branch.shape[0] == hinge.shape[0]
    for h in range(hinge.shape[0]):
        g = grad[h]
        theta = hinge_angle_gradient(x, hinge[h, 0], hinge[h, 1], hinge[h, 2], hinge[h, 3], g)
        if follow:
            theta = angle_near(theta, branch[h])
        d = theta - theta0[h]
        if abs(d) > worst:
            worst = abs(d)
        energy += kb[h] * d * d * weight[h]
        coef[h] = 2.0 * kb[h]
        m = 2.0 * kb[h] * d
        for a in range(4):
            i = hinge[h, a]
            force[i, 0] -= m * g[a, 0]
            force[i, 1] -= m * g[a, 1]
            force[i, 2] -= m * g[a, 2]
    return energy, worst


@njit(cache=True)
def dihedral_discrete_gradient(x0, x1, xm, hinge, theta0, kb, force, branch):
    """force += the dihedral bending force of a step from x0 to x1 (xm their
    midpoint): -kb (d0 + d1) gbar per hinge, d = theta - theta0, with gbar a
    discrete gradient of theta (Gonzalez 1996): gbar = g_m + (theta1 - theta0
    - g_m . r) r / |r|^2, g_m = grad theta at xm, r = x1 - x0 on the hinge's
    four vertices less its mean (a translation: g_m . r = g_m . (x1 - x0) and
    gbar keeps summing to zero).  gbar . (x1 - x0) = theta1 - theta0, so the
    force's work is -(U1 - U0) exactly; gbar - g_m = O(|r|^2).  ``branch``
    (ne,) or empty: both angles taken within pi of it, as in dihedral_forces."""
    g = np.empty((4, 3))
    follow = branch.shape[0] == hinge.shape[0]
    r = np.empty((4, 3))
    for h in range(hinge.shape[0]):
        i0 = hinge[h, 0]
        i1 = hinge[h, 1]
        i2 = hinge[h, 2]
        i3 = hinge[h, 3]
        t0 = hinge_angle_gradient(x0, i0, i1, i2, i3, g)
        t1 = hinge_angle_gradient(x1, i0, i1, i2, i3, g)
        if follow:
            t0 = angle_near(t0, branch[h])
            t1 = angle_near(t1, branch[h])
        hinge_angle_gradient(xm, i0, i1, i2, i3, g)
        rr = 0.0
        gr = 0.0
        le2 = 0.0
        for c in range(3):
            mean = 0.0
            for a in range(4):
                mean += x1[hinge[h, a], c] - x0[hinge[h, a], c]
            mean *= 0.25
            for a in range(4):
                r[a, c] = x1[hinge[h, a], c] - x0[hinge[h, a], c] - mean
                rr += r[a, c] * r[a, c]
                gr += g[a, c] * r[a, c]
            de = xm[i1, c] - xm[i0, c]
            le2 += de * de
        # below a move of 1e-10 of the hinge's edge the correction is round-off
        corr = (t1 - t0 - gr) / rr if rr > 1e-20 * le2 else 0.0
        m = kb[h] * (t0 + t1 - 2.0 * theta0[h])
        for a in range(4):
            i = hinge[h, a]
            for c in range(3):
                force[i, c] -= m * (g[a, c] + corr * r[a, c])


@njit(cache=True)
def gauss_newton_stiffness_product(hinge, grad, coef, w, out):
    """out -= coef (grad . w) grad per hinge (out += df/dx w, Gauss-Newton)."""
    for h in range(hinge.shape[0]):
        s = 0.0
        for a in range(4):
            i = hinge[h, a]
            s += grad[h, a, 0] * w[i, 0] + grad[h, a, 1] * w[i, 1] + grad[h, a, 2] * w[i, 2]
        m = coef[h] * s
        for a in range(4):
            i = hinge[h, a]
            out[i, 0] -= m * grad[h, a, 0]
            out[i, 1] -= m * grad[h, a, 1]
            out[i, 2] -= m * grad[h, a, 2]


@njit(cache=True)
def add_gauss_newton_blocks(grad, coef, alpha, slots, data):
    """data[slot(a,b)] += alpha coef grad_a grad_b^T (slots (ne, 16), -1 skipped)."""
    for h in range(grad.shape[0]):
        m = alpha * coef[h]
        for a in range(4):
            for b in range(4):
                slot = slots[h, 4 * a + b]
                if slot < 0:
                    continue
                for p in range(3):
                    for q in range(3):
                        data[slot, p, q] += m * grad[h, a, p] * grad[h, b, q]


@njit(cache=True)
def _skew(v0, v1, v2, S):
    """S w = v x w."""
    S[0, 0] = 0.0
    S[0, 1] = -v2
    S[0, 2] = v1
    S[1, 0] = v2
    S[1, 1] = 0.0
    S[1, 2] = -v0
    S[2, 0] = -v1
    S[2, 1] = v0
    S[2, 2] = 0.0


@njit(cache=True)
def _normal_derivative(n, P):
    """P = d(n / |n|^2)/dn = (I - 2 n n^T / |n|^2) / |n|^2."""
    n2 = n[0] * n[0] + n[1] * n[1] + n[2] * n[2]
    for p in range(3):
        for q in range(3):
            P[p, q] = -2.0 * n[p] * n[q] / (n2 * n2)
        P[p, p] += 1.0 / n2


@njit(cache=True)
def hinge_angle_hessian(x, i0, i1, i2, i3, g, Hth, V, M, Dg, dt):
    """Signed angle of one hinge, its gradient into g (4, 3) and its exact
    Hessian into Hth (12, 12) (rows/cols: vertex a, component p -> 3a + p).

    Chain rule on the gradient formulas (module docstring) in the edge
    variables e = x1 - x0, a = x2 - x0, b = x3 - x0:
      d(le uA)/de = uA e^T/le - le PA [a]x,  d(le uA)/da = le PA [e]x,
      d(le uB)/de = uB e^T/le + le PB [b]x,  d(le uB)/db = -le PB [e]x,
      dtA/de = a/le^2 - 2 (a.e) e/le^4,  dtA/da = e/le^2  (tB likewise with b),
    with uA = nA/|nA|^2, PA = d uA / d nA; then x1 <- d/de, x2 <- d/da,
    x3 <- d/db, x0 <- -(d/de + d/da + d/db).
    Scratch: V (8, 3), M (5, 3, 3), Dg (4, 3, 3, 3), dt (2, 3, 3)."""
    theta = hinge_angle_gradient(x, i0, i1, i2, i3, g)
    for c in range(3):
        V[0, c] = x[i1, c] - x[i0, c]      # e
        V[1, c] = x[i2, c] - x[i0, c]      # a
        V[2, c] = x[i3, c] - x[i0, c]      # b
    e = V[0]
    a = V[1]
    b = V[2]
    V[3, 0] = e[1] * a[2] - e[2] * a[1]    # nA = e x a
    V[3, 1] = e[2] * a[0] - e[0] * a[2]
    V[3, 2] = e[0] * a[1] - e[1] * a[0]
    V[4, 0] = b[1] * e[2] - b[2] * e[1]    # nB = b x e
    V[4, 1] = b[2] * e[0] - b[0] * e[2]
    V[4, 2] = b[0] * e[1] - b[1] * e[0]
    le2 = e[0] * e[0] + e[1] * e[1] + e[2] * e[2]
    le = np.sqrt(le2)
    nA2 = V[3, 0] ** 2 + V[3, 1] ** 2 + V[3, 2] ** 2
    nB2 = V[4, 0] ** 2 + V[4, 1] ** 2 + V[4, 2] ** 2
    ae = a[0] * e[0] + a[1] * e[1] + a[2] * e[2]
    be = b[0] * e[0] + b[1] * e[1] + b[2] * e[2]
    ta = ae / le2
    tb = be / le2
    for c in range(3):
        V[5, c] = V[3, c] / nA2            # uA
        V[6, c] = V[4, c] / nB2            # uB
        V[7, c] = e[c] / le                # unit edge
    _normal_derivative(V[3], M[0])
    _normal_derivative(V[4], M[1])
    _skew(a[0], a[1], a[2], M[2])
    _skew(e[0], e[1], e[2], M[3])
    _skew(b[0], b[1], b[2], M[4])
    Dg[:] = 0.0
    for p in range(3):
        for q in range(3):
            pa_sa = 0.0
            pa_se = 0.0
            pb_sb = 0.0
            pb_se = 0.0
            for r in range(3):
                pa_sa += M[0, p, r] * M[2, r, q]
                pa_se += M[0, p, r] * M[3, r, q]
                pb_sb += M[1, p, r] * M[4, r, q]
                pb_se += M[1, p, r] * M[3, r, q]
            Dg[2, 0, p, q] = V[5, p] * V[7, q] - le * pa_sa
            Dg[2, 1, p, q] = le * pa_se
            Dg[3, 0, p, q] = V[6, p] * V[7, q] + le * pb_sb
            Dg[3, 2, p, q] = -le * pb_se
    for c in range(3):
        dt[0, 0, c] = a[c] / le2 - 2.0 * ae * e[c] / (le2 * le2)
        dt[0, 1, c] = e[c] / le2
        dt[0, 2, c] = 0.0
        dt[1, 0, c] = b[c] / le2 - 2.0 * be * e[c] / (le2 * le2)
        dt[1, 1, c] = 0.0
        dt[1, 2, c] = e[c] / le2
    for v in range(3):
        for p in range(3):
            for q in range(3):
                o = g[2, p] * dt[0, v, q] + g[3, p] * dt[1, v, q]
                Dg[0, v, p, q] = o - (1.0 - ta) * Dg[2, v, p, q] - (1.0 - tb) * Dg[3, v, p, q]
                Dg[1, v, p, q] = -o - ta * Dg[2, v, p, q] - tb * Dg[3, v, p, q]
    for i in range(4):
        for p in range(3):
            for q in range(3):
                s = 0.0
                for v in range(3):
                    Hth[3 * i + p, 3 * (v + 1) + q] = Dg[i, v, p, q]
                    s += Dg[i, v, p, q]
                Hth[3 * i + p, q] = -s
    return theta


@njit(cache=True)
def _exact_hinge_hessian(x, hinge, h, theta0, kb, g, Hh, V, M, Dg, dt):
    """Hh (12, 12) = 2 kb (g g^T + (theta - theta0) Hess theta) for hinge h."""
    theta = hinge_angle_hessian(x, hinge[h, 0], hinge[h, 1], hinge[h, 2], hinge[h, 3],
                                g, Hh, V, M, Dg, dt)
    d = theta - theta0[h]
    c = 2.0 * kb[h]
    for i in range(12):
        gi = g[i // 3, i % 3]
        for j in range(12):
            Hh[i, j] = c * (gi * g[j // 3, j % 3] + d * Hh[i, j])


@njit(cache=True)
def exact_dihedral_stiffness_product(x, hinge, theta0, kb, w, out):
    """out += (df/dx) w = -H w with the exact hinge Hessians at x (recomputed)."""
    g = np.zeros((4, 3))
    Hh = np.zeros((12, 12))
    V = np.zeros((8, 3))
    M = np.zeros((5, 3, 3))
    Dg = np.zeros((4, 3, 3, 3))
    dt = np.zeros((2, 3, 3))
    for h in range(hinge.shape[0]):
        _exact_hinge_hessian(x, hinge, h, theta0, kb, g, Hh, V, M, Dg, dt)
        for a in range(4):
            for p in range(3):
                acc = 0.0
                for b in range(4):
                    j = hinge[h, b]
                    for q in range(3):
                        acc += Hh[3 * a + p, 3 * b + q] * w[j, q]
                out[hinge[h, a], p] -= acc


@njit(cache=True)
def add_exact_dihedral_blocks(x, hinge, theta0, kb, alpha, slots, data):
    """data[slot(a,b)] += alpha H_ab with the exact hinge Hessians at x (indefinite
    in general: for Newton-type solvers that handle it, and for tests)."""
    g = np.zeros((4, 3))
    Hh = np.zeros((12, 12))
    V = np.zeros((8, 3))
    M = np.zeros((5, 3, 3))
    Dg = np.zeros((4, 3, 3, 3))
    dt = np.zeros((2, 3, 3))
    for h in range(hinge.shape[0]):
        _exact_hinge_hessian(x, hinge, h, theta0, kb, g, Hh, V, M, Dg, dt)
        for a in range(4):
            for b in range(4):
                slot = slots[h, 4 * a + b]
                if slot < 0:
                    continue
                for p in range(3):
                    for q in range(3):
                        data[slot, p, q] += alpha * Hh[3 * a + p, 3 * b + q]


# --------------------------------------------------------------------------
# force terms
# --------------------------------------------------------------------------

class _HingeTerm(ForceTerm):
    name = "force:bending"

    def __init__(self, hinge, rest, stiffness, weight, rest_points=None):
        self.hinges = np.ascontiguousarray(hinge, dtype=np.int64).reshape(-1, 4)
        ne = self.hinges.shape[0]
        self.B = _per_hinge(stiffness, ne)
        self.weight = _per_hinge(weight, ne)
        # rest_points (ne, 4, 3): each hinge's own rest points (a welded garment
        # has no single rest shape, garment/weld.py); else rest[hinge]
        self.rest_x, self.rest_stencil = np.asarray(rest, dtype=np.float64), self.hinges
        if rest_points is not None:
            self.rest_x = np.asarray(rest_points, dtype=np.float64).reshape(-1, 3)
            self.rest_stencil = np.arange(4 * ne, dtype=np.int64).reshape(ne, 4)
        self.rest_edge2, self.rest_area, self.kvec = hinge_rest_geometry(self.rest_x,
                                                                         self.rest_stencil)
        self.kvec = np.ascontiguousarray(self.kvec)
        self.slots = None

    def stencils(self):
        return [self.hinges]

    def bind(self, pattern):
        self.slots = pattern.slots_for(self.hinges)


class IsometricBendingTerm(_HingeTerm):
    """Isometric quadratic bending (Bergou et al. 2006; EG07 tutorial, Part 1 §4.3).

    E = 1/2 x^T Q x,  Q = sum_h (2 C_HINGE B_h / (Abar_A + Abar_B)) k_h k_h^T (x) I3,
    constant and exact Jacobian df/dx = -Q.  Assumes a flat rest shape (see
    the module docstring); ``rest_energy`` is the (weighted) energy of the
    rest shape, zero up to round-off when it is flat."""

    def __init__(self, hinge, rest, stiffness, weight, rest_points=None):
        super().__init__(hinge, rest, stiffness, weight, rest_points)
        self.coef = np.ascontiguousarray(2.0 * C_HINGE * self.B / self.rest_area)
        s = np.einsum("ha,hac->hc", self.kvec, self.rest_x[self.rest_stencil])
        self.rest_energy = 0.5 * float(np.sum(self.coef * np.einsum("hc,hc->h", s, s)
                                              * self.weight))

    def evaluate(self, x, v, force, want_jac):
        energy = isometric_forces(x, self.hinges, self.kvec, self.coef, self.weight, force)
        return {"elastic_energy": energy}

    def stiffness_product(self, w, out):
        isometric_stiffness_product(self.hinges, self.kvec, self.coef, w, out)

    def add_to_system(self, data, alpha, beta):
        add_isometric_blocks(self.kvec, self.coef, alpha, self.slots, data)

    def energy(self, x):
        x = np.asarray(x, dtype=np.float64)
        s = np.einsum("ha,hac->hc", self.kvec, x[self.hinges])
        return 0.5 * float(np.sum(self.coef * np.einsum("hc,hc->h", s, s) * self.weight))


class FlexionLineTerm(IsometricBendingTerm):
    """Mass-spring bending on grid lines (the flexion stencils: three
    consecutive vertices first, middle, last of a grid row or column):

        E = 1/2 k |x_first + x_last - 2 x_mid|^2,   k = B A_mid / a^4,

    a the rest spacing along the line, A_mid the middle vertex's lumped area.
    The second difference is a^2 kappa n + O(a^4) for a line bent to
    curvature kappa, so E = 1/2 B kappa^2 A_mid: the continuum energy of a
    bend along the grid axis (what Kawabata's B measures), exactly to leading
    order.  Why not a spring between first and last (Provot 1995's flexion
    spring): its length changes only by a^3 kappa^2 / 4, so it resists
    bending at O(kappa^4) and has no linear bending stiffness at all.  The
    element is the isometric model of Bergou et al. 2006 on a 1-D stencil
    (Volino and Magnenat-Thalmann 2006's linear bending): quadratic, rotation
    invariant, zero for every affine map of the straight rest line (so it
    adds no in-plane stiffness), constant exact Jacobian.  Limits: bends
    along a grid diagonal get half the stiffness and twist none (the sum
    over the two axes is B/2 (f_xx^2 + f_yy^2), not B/2 |K|^2); a curved rest
    line is not at rest (as for the isometric hinges, ``rest_energy``).
    Stencil rows (first, last, mid, mid), weights (1, 1, -2, 0), so the
    isometric kernels apply as they are."""

    def __init__(self, lines, rest, stiffness, mid_area, weight):
        lines = np.ascontiguousarray(lines, dtype=np.int64).reshape(-1, 3)
        self.hinges = np.ascontiguousarray(lines[:, [0, 2, 1, 1]])
        ne = self.hinges.shape[0]
        self.B = _per_hinge(stiffness, ne)
        self.weight = _per_hinge(weight, ne)
        x = np.asarray(rest, dtype=np.float64)
        a = 0.5 * np.linalg.norm(x[lines[:, 2]] - x[lines[:, 0]], axis=1)
        self.kvec = np.ascontiguousarray(np.tile([1.0, 1.0, -2.0, 0.0], (ne, 1)))
        self.coef = np.ascontiguousarray(self.B * _per_hinge(mid_area, ne) / a ** 4)
        self.rest_energy = self.energy(x)
        self.slots = None


class TwistCellTerm(IsometricBendingTerm):
    """The twist part of the continuum bending energy on grid cells, with
    ``FlexionLineTerm`` along the grid lines the ``grid_lines`` bending of
    a continuum (fem) grid:

        E = 1/2 k |x_00 - x_10 - x_01 + x_11|^2,   k = 2 B / (a b),

    over the corners (i, j), (i + 1, j), (i, j + 1), (i + 1, j + 1) of a cell
    of rest sides a, b.  The mixed difference is a b x_uv + O(h^4), and for
    a bend of a flat sheet without stretch x_uv = K_uv n, so E = B K_uv^2 a b:
    with the line elements' B/2 (K_uu^2 + K_vv^2) the sum is the isotropic
    plate energy B/2 |K|^2 with bending Poisson ratio 0, the energy
    ``dihedral_shell`` discretises per triangle.  No term couples K_uu to
    K_vv or K_uv, so a strip bent along a grid line cannot lower its energy
    by twisting, which is how per-hinge sums on triangles lose 12-17 % of B
    (docs/mesh_independence.md).  Quadratic, rotation invariant, zero for
    every affine map of the flat cell, constant exact Jacobian; a curved
    rest shape is not at rest (``rest_energy``)."""

    def __init__(self, cells, rest, stiffness, weight):
        cells = np.ascontiguousarray(cells, dtype=np.int64).reshape(-1, 4)
        self.hinges = cells
        ne = cells.shape[0]
        self.B = _per_hinge(stiffness, ne)
        self.weight = _per_hinge(weight, ne)
        x = np.asarray(rest, dtype=np.float64)
        a = np.linalg.norm(x[cells[:, 1]] - x[cells[:, 0]], axis=1)
        b = np.linalg.norm(x[cells[:, 2]] - x[cells[:, 0]], axis=1)
        self.kvec = np.ascontiguousarray(np.tile([1.0, -1.0, -1.0, 1.0], (ne, 1)))
        self.coef = np.ascontiguousarray(2.0 * self.B / (a * b))
        self.rest_energy = self.energy(x)
        self.slots = None


class DihedralBendingTerm(_HingeTerm):
    """Dihedral-angle bending (Bridson et al. 2003; EG07 tutorial, Part 1 §4.3, Fig. 11 b).

    E = sum_h kb_h (theta_h - theta0_h)^2,  kb = C_HINGE B |ebar|^2 / (Abar_A + Abar_B),
    theta0 the rest angles (from ``rest`` unless ``rest_angle`` is given).
    Forces are the exact gradient.

    ``hessian="gauss-newton"`` (default): the system matrix and
    ``stiffness_product`` use 2 kb grad(theta) grad(theta)^T per hinge
    (symmetric positive semi-definite), exact only where theta = theta0: the
    curvature term 2 kb (theta - theta0) Hess(theta) is dropped.
    ``hessian="exact"``: the full Hessian (indefinite in general); it is
    recomputed from the positions of the last ``evaluate`` in
    ``add_to_system`` and ``stiffness_product`` instead of being stored
    (144 doubles per hinge would be)."""

    def __init__(self, hinge, rest, stiffness, weight, rest_angle=None, hessian="gauss-newton",
                 rest_points=None):
        super().__init__(hinge, rest, stiffness, weight, rest_points)
        if hessian not in ("gauss-newton", "exact"):
            raise ValueError(f"DihedralBendingTerm: unknown hessian {hessian!r}")
        self.hessian = hessian
        ne = self.hinges.shape[0]
        self.kb = np.ascontiguousarray(C_HINGE * self.B * self.rest_edge2 / self.rest_area)
        if rest_angle is None:
            self.theta0 = np.ascontiguousarray(hinge_angles(self.rest_x, self.rest_stencil))
        else:
            self.theta0 = _per_hinge(rest_angle, ne)
        self.grad = np.zeros((ne, 4, 3))
        self.coef = np.zeros(ne)
        self.branch = np.zeros(0)
        self._x = None

    def at_step_start(self, x0):
        """Every angle is followed continuously in time: a step's angles are
        taken within pi of its start's, and the start's within pi of the
        previous step's start (a hinge turns by far less than pi in a step).
        A fold pressed flat (theta near +-pi) that passes +-pi then goes on
        past it instead of jumping by 2 pi: its force does not reverse, and its
        energy stays continuous, so the forces are those of the energy the
        guard measures.  Reset per step instead, a step's trial states (the
        predictor, Newton's iterates, RK4's stages) saw continuous angles while
        the committed states' energy jumped, and RK4 on a heavy sheet gained
        energy; taken canonically throughout, folds that trial states carry
        through +-pi had their force reversed and a sewn skirt's kept
        jittering at 1-2 m/s."""
        theta = hinge_angles(x0, self.hinges)
        if self.branch.shape == theta.shape:
            theta = _unwrapped(theta, self.branch)
        self.branch = np.ascontiguousarray(theta)

    def evaluate(self, x, v, force, want_jac):
        energy, worst = dihedral_forces(x, self.hinges, self.theta0, self.kb, self.weight,
                                        force, self.grad, self.coef, self.branch)
        if want_jac and self.hessian == "exact":
            self._x = np.array(x, dtype=np.float64, order="C")
        return {"elastic_energy": energy}

    def evaluate_between(self, x0, x1, v, force, want_jac):
        x0 = np.ascontiguousarray(x0, dtype=np.float64)
        x1 = np.ascontiguousarray(x1, dtype=np.float64)
        xm = 0.5 * (x0 + x1)
        if want_jac:     # the Newton matrix: the Hessian at the midpoint
            self.evaluate(xm, v, np.zeros_like(force), True)
        dihedral_discrete_gradient(x0, x1, xm, self.hinges, self.theta0, self.kb, force,
                                   self.branch)
        return {}

    def stiffness_product(self, w, out):
        if self.hessian == "exact":
            exact_dihedral_stiffness_product(self._x, self.hinges, self.theta0, self.kb, w, out)
        else:
            gauss_newton_stiffness_product(self.hinges, self.grad, self.coef, w, out)

    def add_to_system(self, data, alpha, beta):
        if self.hessian == "exact":
            add_exact_dihedral_blocks(self._x, self.hinges, self.theta0, self.kb, alpha,
                                      self.slots, data)
        else:
            add_gauss_newton_blocks(self.grad, self.coef, alpha, self.slots, data)

    def energy(self, x):
        return float(dihedral_energy(np.ascontiguousarray(x, dtype=np.float64), self.hinges,
                                     self.theta0, self.kb, self.weight, self.branch))
