"""Continuum membrane: linear triangles in plane stress (EG07 tutorial, Part 1 §3.2-3.6).

Each triangle gets, once, a 2D rest frame in its plane whose first axis is
the fabric's weft direction (u) and second the warp (v = n x u), the inverse
Dm^-1 of its 2x2 rest edge matrix and its rest area A (§3.6: linear element,
constant strain).  With Ds = [x1 - x0, x2 - x0] (3x2) the deformation gradient
(EG07 tutorial, Part 1 Eq. 3) is F = Ds Dm^-1 (3x2), i.e. F = sum_i x_i g_i^T with
g_1, g_2 the rows of Dm^-1 and g_0 = -g_1 - g_2 (``G`` below, (ne, 3, 2)).

Strain measures (Voigt, engineering shear: e = [e_uu, e_vv, 2 e_uv]):

* ``stvk``: Green strain E = 1/2 (F^T F - I) (Part 1 Eq. 6), energy
  W = 1/2 A e^T C e (St. Venant-Kirchhoff).
* ``corotated``: polar decomposition F = R S (Part 1 Eq. 9), R (3x2) with
  orthonormal columns, S = sqrt(F^T F) (2x2 SPD, right stretch).  The
  corotated Cauchy strain of Eq. 11, eps_C(R^T phi), is sym(R^T F) - I =
  S - I (the Biot strain); energy W = 1/2 A eps^T C eps.  The rotation is
  NOT frozen (unlike the lagged-R "corotational FEM"): W is a hyperelastic
  energy of F, the forces are its exact gradient and the Hessian includes the
  rotation's derivative.  S is computed QR/SVD-free in closed form:
  with M = F^T F, s = sqrt(det M), t = sqrt(tr M + 2 s),
  S = (M + s I) / t (Cayley-Hamilton for 2x2 SPD matrices).

Both energies depend on F only through M = F^T F, so every quantity is
written in terms of the Green strain e: Sigma = dW/de (3,), D = d2W/de2 (3x3),
and (per unit area) d2W/dF2 = B^T D B + Sigma_mat (x) I3 with B = de/dF
(3x6) and Sigma_mat = [[S0, S2], [S2, S1]].

Material (EG07 tutorial, Part 1 §3.5, Eq. 22): orthotropic plane stress in the weft/warp frame

    C = 1/(1 - nu_u nu_v) [[E_u, nu_u E_v, 0], [nu_v E_u, E_v, 0],
                           [0, 0, G (1 - nu_u nu_v)]]

symmetric only if nu_u E_v = nu_v E_u; positive definite iff also
nu_u nu_v < 1 (with positive moduli).  Moduli are per unit width (N/m).

Indefiniteness and projection.  The exact Hessian is indefinite (a) for
StVK whenever Sigma_mat has a negative eigenvalue (compression: the
geometric term Sigma_mat (x) I3 is negative, D = C is PSD), (b) for the
corotated model additionally through the curvature of S = sqrt(M), i.e. the
rotation's derivative sum_m (C eps)_m d2 eps_m/de2, which is negative in
some directions both under compression and under stretch (shear).  For the
system matrix each element's 9x9 Hessian is projected to PSD by clamping its
negative eigenvalues to zero.  The 9x9 Hessian is
H = (Q0 (x) I3) Hr (Q0 (x) I3)^T with Q0 a fixed 3x2 orthonormal basis of the
vectors orthogonal to (1,1,1) (every g has zero sum) and Hr (6x6) the
F-Hessian in the frame G = Q0 Rg; since Q0 (x) I3 has orthonormal columns,
eig(H) = eig(Hr) plus three zeros (translations).  So the kernel clamps the
6x6 Hr, which is exactly the eigenvalue clamp of the 9x9 H, cheaper; a
6x6 Cholesky test first skips the eigendecomposition for elements whose Hr
is already positive definite (and, before that, an exact sufficient test:
D PSD and Sigma_mat PSD, which covers rest and stretched elements).
Elements store Hr (ne, 6, 6), not 9x9.

Measured on 199,712 triangles (2 cores, one thread, 2% stretch + noise 3%
of an edge, ~48 % of elements indefinite): forces 13 ms (stvk) / 27 ms
(corotated); forces + exact Hessian 36 / 64 ms; forces + projected Hessian
~290 / ~320 ms (at rest or uniformly stretched: 30 / 60 ms, no eigh called);
where only the normal block needs the clamp (most compressed triangles of
a hanging or draped cloth) it is a closed-form rank-two update: 2.75 against
4.15 ms an evaluation of the draped 41² tablecloth.
The alternative, numpy's stacked eigh after the kernel, costs 0.62 s for
all 6x6 Hr (1.23 s on the 9x9 H) on top of the kernel, so in-kernel
projection with the pre-tests is kept.  add_to_system 22 ms,
stiffness_product 7 ms.

Nonlinear tension (EG07 tutorial, Part 2 §1.1, §1.3: weft and warp kept
independent, each linear parameter replaced by a measured strain-stress
curve, stiffening with strain): ``stvk`` with tables.  The weft and warp
direct stresses are piecewise-linear functions S_d(e_d) of their Green
strains (tables of (e, S) from (0, 0), increasing), extended with the last
segment's slope beyond the table and the first segment's slope in
compression; the energy W = Psi_u(e_u) + Psi_v(e_v) + C12 e_u e_v + Psi_s(|g|)
(Psi_d' = S_d, the shear curve odd in g) keeps the Poisson coupling of Eq. 22 and is C¹ with
a piecewise-constant second derivative, so the Hessian stays exact.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from .base import ForceTerm

STVK = 0
COROTATED = 1
TABULATED = 2          # stvk with tabulated weft/warp direct stresses
STRAIN_MODELS = {"stvk": STVK, "corotated": COROTATED}
NO_TABLE = np.zeros((3, 2, 2))


@njit(cache=True)
def _tabulated(e, table):
    """(Psi(e), S(e), dS/de) of a piecewise-linear S through table[:, 0] -> table[:, 1].

    A first row at negative strain (with_compression) is the compression
    branch: S linear through it for e <= 0; otherwise compression continues
    the first segment."""
    k = table.shape[0]
    start = 1 if table[0, 0] < 0.0 else 0
    if e <= 0.0:
        if start == 1:
            slope = table[0, 1] / table[0, 0]
        else:
            slope = (table[1, 1] - table[0, 1]) / (table[1, 0] - table[0, 0])
        return 0.5 * slope * e * e, slope * e, slope
    psi = 0.0
    for i in range(start, k - 1):
        e0, e1 = table[i, 0], table[i + 1, 0]
        s0, s1 = table[i, 1], table[i + 1, 1]
        slope = (s1 - s0) / (e1 - e0)
        if e <= e1 or i == k - 2:
            de = e - e0
            return psi + s0 * de + 0.5 * slope * de * de, s0 + slope * de, slope
        psi += 0.5 * (s0 + s1) * (e1 - e0)
    return psi, 0.0, 0.0

# fixed orthonormal basis of {y in R^3 : sum(y) = 0}, columns
Q0 = np.array([[1.0 / np.sqrt(2.0), 1.0 / np.sqrt(6.0)],
               [-1.0 / np.sqrt(2.0), 1.0 / np.sqrt(6.0)],
               [0.0, -2.0 / np.sqrt(6.0)]])


# ----------------------------------------------------------------- material

def orthotropic_plane_stress(E_weft, E_warp, nu_weft, nu_warp, G):
    """3x3 Voigt (engineering shear) plane-stress stiffness, EG07 tutorial, Part 1 §3.5 Eq. 22.

    Raises ValueError unless nu_weft E_warp == nu_warp E_weft (rel. 1e-9,
    the symmetry of C) and nu_weft nu_warp < 1."""
    E_u, E_v, nu_u, nu_v, G = (float(E_weft), float(E_warp), float(nu_weft),
                               float(nu_warp), float(G))
    a, b = nu_u * E_v, nu_v * E_u
    if abs(a - b) > 1e-9 * max(abs(a), abs(b)):
        raise ValueError(f"orthotropic material not symmetric: nu_weft*E_warp = {a} "
                         f"!= nu_warp*E_weft = {b}")
    if nu_u * nu_v >= 1.0:
        raise ValueError(f"orthotropic material: nu_weft*nu_warp = {nu_u * nu_v} must be < 1")
    d = 1.0 - nu_u * nu_v
    off = 0.5 * (a + b) / d
    return np.array([[E_u / d, off, 0.0],
                     [off, E_v / d, 0.0],
                     [0.0, 0.0, G]])


def uniaxial_modulus(C, direction=0):
    """Modulus under uniaxial stress along frame axis 0 (weft) or 1 (warp): 1/(C^-1)_dd."""
    return 1.0 / np.linalg.inv(C)[direction, direction]


# ----------------------------------------------------------- rest geometry

def rest_frames(X, tris, weft=None):
    """Per-triangle rest data, vectorised: (G (ne,3,2), Rg (ne,2,2), area (ne,), frame (ne,3,3)).

    ``weft`` (ne,3) or None: a 3D direction per triangle, projected into the
    triangle's plane (default: global x); where the projection is shorter than
    1e-6 of its input the first edge is used.  frame[:, 0] = weft unit vector
    u, frame[:, 1] = warp v = n x u, frame[:, 2] = n."""
    X = np.asarray(X, dtype=np.float64)
    tris = np.asarray(tris, dtype=np.int64)
    e1 = X[tris[:, 1]] - X[tris[:, 0]]
    e2 = X[tris[:, 2]] - X[tris[:, 0]]
    cr = np.cross(e1, e2)
    dbl = np.linalg.norm(cr, axis=1)
    if np.any(dbl <= 0.0):
        raise ValueError("degenerate rest triangle (zero area)")
    n = cr / dbl[:, None]
    if weft is None:
        d = np.zeros_like(e1)
        d[:, 0] = 1.0
    else:
        d = np.broadcast_to(np.asarray(weft, dtype=np.float64), e1.shape).copy()
    dn = np.linalg.norm(d, axis=1)
    p = d - np.einsum("ij,ij->i", d, n)[:, None] * n
    pn = np.linalg.norm(p, axis=1)
    bad = pn <= 1e-6 * np.maximum(dn, 1e-300)
    p[bad] = e1[bad]
    pn[bad] = np.linalg.norm(e1[bad], axis=1)
    u = p / pn[:, None]
    v = np.cross(n, u)
    Dm = np.empty((len(tris), 2, 2))
    Dm[:, 0, 0] = np.einsum("ij,ij->i", e1, u)
    Dm[:, 0, 1] = np.einsum("ij,ij->i", e2, u)
    Dm[:, 1, 0] = np.einsum("ij,ij->i", e1, v)
    Dm[:, 1, 1] = np.einsum("ij,ij->i", e2, v)
    Dinv = np.linalg.inv(Dm)
    G = np.empty((len(tris), 3, 2))
    G[:, 1] = Dinv[:, 0]
    G[:, 2] = Dinv[:, 1]
    G[:, 0] = -G[:, 1] - G[:, 2]
    Rg = np.einsum("ia,eib->eab", Q0, G)          # G = Q0 Rg
    frame = np.stack([u, v, n], axis=1)
    return (np.ascontiguousarray(G), np.ascontiguousarray(Rg), 0.5 * dbl,
            frame)


# ------------------------------------------------------------ numba kernels

@njit(cache=True)
def _energy_density(e, C, model, want_hess, sig, D, wk, tables):
    """W(e) per unit area; fills sig = dW/de (3,) and, with ``want_hess``,
    D = d2W/de2 (3,3).  ``wk`` (8, 3, 3) is scratch (no allocation per element).

    Returns (W, largest principal strain of the model's strain measure).
    Hook: a tabulated nonlinear tension law would replace sigma = C eps here."""
    if model == TABULATED:
        pu, su, du = _tabulated(e[0], tables[0])
        pv, sv, dv = _tabulated(e[1], tables[1])
        sig[0] = su + C[0, 1] * e[1]
        sig[1] = sv + C[0, 1] * e[0]
        # shear: a curve of |gamma|, odd in gamma (no preferred shear sense)
        ps, ss, ds = _tabulated(abs(e[2]), tables[2])
        sig[2] = ss if e[2] >= 0.0 else -ss
        for m in range(3):
            for q in range(3):
                D[m, q] = 0.0
        D[0, 0] = du
        D[1, 1] = dv
        D[0, 1] = C[0, 1]
        D[1, 0] = C[0, 1]
        D[2, 2] = ds
        W = pu + pv + C[0, 1] * e[0] * e[1] + ps
        h = 0.5 * (e[0] - e[1])
        return W, 0.5 * (e[0] + e[1]) + np.sqrt(h * h + 0.25 * e[2] * e[2])
    if model == STVK:
        W = 0.0
        for m in range(3):
            acc = 0.0
            for q in range(3):
                acc += C[m, q] * e[q]
                D[m, q] = C[m, q]
            sig[m] = acc
            W += 0.5 * acc * e[m]
        # principal Green strain of [[e0, e2/2], [e2/2, e1]]
        h = 0.5 * (e[0] - e[1])
        pmax = 0.5 * (e[0] + e[1]) + np.sqrt(h * h + 0.25 * e[2] * e[2])
        return W, pmax
    # corotated: eps = voigt(sqrt(I + 2E) - I) as a function of p = (a, b, c),
    # M = [[a, c], [c, b]], a = 1 + 2 e0, b = 1 + 2 e1, c = e2;
    # S = (M + s I) / t, s = sqrt(ab - c^2), t = sqrt(a + b + 2 s).
    a = 1.0 + 2.0 * e[0]
    b = 1.0 + 2.0 * e[1]
    c = e[2]
    q = a * b - c * c
    if q < 1e-300:                  # degenerate (collapsed) triangle
        q = 1e-300
    s = np.sqrt(q)
    r = a + b + 2.0 * s
    t = np.sqrt(r)
    it = 1.0 / t
    eps0 = (a + s) * it - 1.0
    eps1 = (b + s) * it - 1.0
    eps2 = 2.0 * c * it
    sg0 = C[0, 0] * eps0 + C[0, 1] * eps1 + C[0, 2] * eps2
    sg1 = C[1, 0] * eps0 + C[1, 1] * eps1 + C[1, 2] * eps2
    sg2 = C[2, 0] * eps0 + C[2, 1] * eps1 + C[2, 2] * eps2
    W = 0.5 * (eps0 * sg0 + eps1 * sg1 + eps2 * sg2)
    h = 0.5 * (eps0 - eps1)
    pmax = 0.5 * (eps0 + eps1) + np.sqrt(h * h + 0.25 * eps2 * eps2)
    # first derivatives in p
    dq = wk[0, 0]
    dq[0] = b
    dq[1] = a
    dq[2] = -2.0 * c
    ds = wk[0, 1]
    dr = wk[0, 2]
    dt = wk[1, 0]
    for i in range(3):
        ds[i] = dq[i] / (2.0 * s)
        dr[i] = 2.0 * ds[i] + (1.0 if i < 2 else 0.0)
        dt[i] = dr[i] / (2.0 * t)
    dN = wk[2]                      # dN[m] = d numerator_m / dp
    for i in range(3):
        dN[0, i] = ds[i]
        dN[1, i] = ds[i]
        dN[2, i] = 0.0
    dN[0, 0] += 1.0
    dN[1, 1] += 1.0
    dN[2, 2] = 1.0
    num0 = a + s
    num1 = b + s
    num2 = c
    Jp = wk[3]                      # d eps / dp, then d eps / de
    sgm = wk[1, 1]
    sgm[0] = sg0
    sgm[1] = sg1
    sgm[2] = sg2
    for m in range(3):
        num = num0 if m == 0 else (num1 if m == 1 else num2)
        fac = 2.0 if m == 2 else 1.0
        for i in range(3):
            Jp[m, i] = fac * (dN[m, i] * it - num * dt[i] * it * it)
    K0, K1, K2 = 2.0, 2.0, 1.0      # dp/de
    for i in range(3):
        Ki = K0 if i == 0 else (K1 if i == 1 else K2)
        sig[i] = Ki * (Jp[0, i] * sg0 + Jp[1, i] * sg1 + Jp[2, i] * sg2)
    if not want_hess:
        return W, pmax
    # second derivatives in p: d2q, d2s, d2r = 2 d2s, d2t
    d2s = wk[4]
    d2t = wk[5]
    for i in range(3):
        for j in range(3):
            d2q = 0.0
            if (i == 0 and j == 1) or (i == 1 and j == 0):
                d2q = 1.0
            elif i == 2 and j == 2:
                d2q = -2.0
            d2s[i, j] = d2q / (2.0 * s) - dq[i] * dq[j] / (4.0 * s * s * s)
    for i in range(3):
        for j in range(3):
            d2t[i, j] = 2.0 * d2s[i, j] / (2.0 * t) - dr[i] * dr[j] / (4.0 * t * t * t)
    # D = J^T C J + sum_m sigma_m d2 eps_m / de2, J = Jp K
    J = wk[6]
    for m in range(3):
        J[m, 0] = Jp[m, 0] * K0
        J[m, 1] = Jp[m, 1] * K1
        J[m, 2] = Jp[m, 2] * K2
    CJ = wk[7]
    for m in range(3):
        for j in range(3):
            CJ[m, j] = C[m, 0] * J[0, j] + C[m, 1] * J[1, j] + C[m, 2] * J[2, j]
    for i in range(3):
        Ki = K0 if i == 0 else (K1 if i == 1 else K2)
        for j in range(3):
            Kj = K0 if j == 0 else (K1 if j == 1 else K2)
            acc = 0.0
            for m in range(3):
                num = num0 if m == 0 else (num1 if m == 1 else num2)
                fac = 2.0 if m == 2 else 1.0
                d2N = d2s[i, j] if m < 2 else 0.0
                hp = fac * (d2N * it
                            - (dN[m, i] * dt[j] + dt[i] * dN[m, j]) * it * it
                            - num * d2t[i, j] * it * it
                            + 2.0 * num * dt[i] * dt[j] * it * it * it)
                acc += J[m, i] * CJ[m, j] + sgm[m] * hp * Ki * Kj
            D[i, j] = acc
    return W, pmax


@njit(cache=True)
def _is_psd3(D):
    """Symmetric 3x3 D positive semidefinite: all principal minors >= 0."""
    if D[0, 0] < 0.0 or D[1, 1] < 0.0 or D[2, 2] < 0.0:
        return False
    if (D[0, 0] * D[1, 1] - D[0, 1] * D[1, 0] < 0.0 or D[0, 0] * D[2, 2] - D[0, 2] * D[2, 0] < 0.0
            or D[1, 1] * D[2, 2] - D[1, 2] * D[2, 1] < 0.0):
        return False
    det = (D[0, 0] * (D[1, 1] * D[2, 2] - D[1, 2] * D[2, 1])
           - D[0, 1] * (D[1, 0] * D[2, 2] - D[1, 2] * D[2, 0])
           + D[0, 2] * (D[1, 0] * D[2, 1] - D[1, 1] * D[2, 0]))
    return det >= 0.0


@njit(cache=True)
def _is_pd6(A, L):
    """True if the symmetric 6x6 A is positive definite (Cholesky succeeds)."""
    return _is_pd_leading(A, 6, L)


@njit(cache=True)
def _is_pd_leading(A, n, L):
    """True if the leading n x n block of the symmetric A is positive definite
    (Cholesky succeeds; L is scratch)."""
    for j in range(n):
        d = A[j, j]
        for k in range(j):
            d -= L[j, k] * L[j, k]
        if d <= 1e-12 * (abs(A[j, j]) + 1e-300):
            return False
        L[j, j] = np.sqrt(d)
        for i in range(j + 1, n):
            acc = A[i, j]
            for k in range(j):
                acc -= L[i, k] * L[j, k]
            L[i, j] = acc / L[j, j]
    return True


@njit(cache=True)
def _project_psd6(A):
    """Clamp the negative eigenvalues of the symmetric 6x6 A to zero, in place
    (LAPACK's eigh: the fallback of ``_project_psd_split``)."""
    w, V = np.linalg.eigh(A)
    for i in range(6):
        for j in range(6):
            acc = 0.0
            for k in range(6):
                if w[k] > 0.0:
                    acc += V[i, k] * w[k] * V[j, k]
            A[i, j] = acc


@njit(cache=True)
def _jacobi_block(a, V, lo, hi):
    """Eigendecomposition of the symmetric block a[lo:hi, lo:hi] by cyclic
    Jacobi rotations (Golub and Van Loan, Matrix Computations, §8.5): on
    return its diagonal holds the eigenvalues and V[lo:hi, lo:hi] (the
    identity on entry) the eigenvectors as columns."""
    scale = 0.0
    for i in range(lo, hi):
        for j in range(lo, hi):
            scale += a[i, j] * a[i, j]
    for _ in range(50):
        off = 0.0
        for p in range(lo, hi - 1):
            for q in range(p + 1, hi):
                off += a[p, q] * a[p, q]
        if off <= 1e-32 * scale:
            return
        for p in range(lo, hi - 1):
            for q in range(p + 1, hi):
                apq = a[p, q]
                if apq == 0.0:
                    continue
                theta = (a[q, q] - a[p, p]) / (2.0 * apq)
                t = 1.0 / (abs(theta) + np.sqrt(theta * theta + 1.0))
                if theta < 0.0:
                    t = -t
                c = 1.0 / np.sqrt(t * t + 1.0)
                s = t * c
                for k in range(lo, hi):
                    akp, akq = a[k, p], a[k, q]
                    a[k, p] = c * akp - s * akq
                    a[k, q] = s * akp + c * akq
                for k in range(lo, hi):
                    apk, aqk = a[p, k], a[q, k]
                    a[p, k] = c * apk - s * aqk
                    a[q, k] = s * apk + c * aqk
                for k in range(lo, hi):
                    vkp, vkq = V[k, p], V[k, q]
                    V[k, p] = c * vkp - s * vkq
                    V[k, q] = s * vkp + c * vkq


@njit(cache=True)
def _project_psd_split(A, F, T, a, V):
    """``_project_psd6`` for an element Hessian Hr = (Rg (x) I3)(B^T D B)(Rg (x) I3)^T
    + (Rg Sigma Rg^T) (x) I3 at deformation gradient F (3x2), without LAPACK.

    The rows of B are built from F's columns, so with t0, t1 an orthonormal
    basis of span(F) and n its normal, R^2 (x) span(t0, t1) and R^2 (x) n are
    invariant subspaces of Hr: in that basis Hr is block diagonal 4 + 2 (the
    2x2 block is Rg Sigma Rg^T), and two small Jacobi eigensolves replace
    the 6x6 one, several times faster than numba's LAPACK call.  Where the
    4x4 in-plane block is definite (mild compression: the material term
    outweighs the stress there) only the normal block is clamped, in closed
    form, as a rank-two update of A.  A flat (collapsed) F has no such
    plane: LAPACK then."""
    f0 = math.sqrt(F[0, 0] ** 2 + F[1, 0] ** 2 + F[2, 0] ** 2)
    f1 = math.sqrt(F[0, 1] ** 2 + F[1, 1] ** 2 + F[2, 1] ** 2)
    if f0 == 0.0 or f1 == 0.0:
        _project_psd6(A)
        return
    t0 = np.empty(3)
    t1 = np.empty(3)
    for k in range(3):
        t0[k] = F[k, 0] / f0
    d = t0[0] * F[0, 1] + t0[1] * F[1, 1] + t0[2] * F[2, 1]
    for k in range(3):
        t1[k] = F[k, 1] - d * t0[k]
    r = math.sqrt(t1[0] ** 2 + t1[1] ** 2 + t1[2] ** 2)
    if r <= 1e-6 * f1:
        _project_psd6(A)
        return
    for k in range(3):
        t1[k] /= r
    # basis of R^2 (x) R^3, index al*3+k: column c is e_al(c) (x) T[c] with
    # (al, vector) = (0, t0), (0, t1), (1, t0), (1, t1), (0, n), (1, n)
    for k in range(3):
        T[0, k] = t0[k]
        T[1, k] = t1[k]
        T[2, k] = t0[k]
        T[3, k] = t1[k]
    T[4, 0] = t0[1] * t1[2] - t0[2] * t1[1]
    T[4, 1] = t0[2] * t1[0] - t0[0] * t1[2]
    T[4, 2] = t0[0] * t1[1] - t0[1] * t1[0]
    for k in range(3):
        T[5, k] = T[4, k]
    for c in range(6):                       # V = (basis)^T A, 6 x 6
        o = 3 * _AL[c]
        for q in range(6):
            V[c, q] = T[c, 0] * A[o, q] + T[c, 1] * A[o + 1, q] + T[c, 2] * A[o + 2, q]
    for i in range(6):                       # a = (basis)^T A (basis)
        for j in range(i, 6):
            o = 3 * _AL[j]
            acc = V[i, o] * T[j, 0] + V[i, o + 1] * T[j, 1] + V[i, o + 2] * T[j, 2]
            a[i, j] = acc
            a[j, i] = acc
    if _is_pd_leading(a, 4, V):
        # the in-plane block is already definite (the material term outweighs
        # a compression's stress in it: most compressed triangles), so the
        # clamp only takes off the normal block's negative part, a rank-two
        # update without the eigensolves
        _clamp_normal_block(A, a, T)
        return
    for i in range(6):
        for j in range(6):
            V[i, j] = 1.0 if i == j else 0.0
    _jacobi_block(a, V, 0, 4)
    _jacobi_block(a, V, 4, 6)
    # eigenvector k in the original index: W[al*3+l, k] = sum over the columns c
    # of that al of T[c, l] V[c, k] (the 4 + 2 blocks keep V zero across them)
    for al in range(2):
        for l in range(3):
            r = al * 3 + l
            for k in range(6):
                acc = 0.0
                for c in range(6):
                    if _AL[c] == al:
                        acc += T[c, l] * V[c, k]
                A[r, k] = acc                # A holds W until the product below
    for k in range(6):
        a[k, 0] = max(a[k, k], 0.0)          # the clamped eigenvalues
    for i in range(6):                       # W diag(max(w, 0)) W^T
        for j in range(i, 6):
            acc = 0.0
            for k in range(6):
                acc += A[i, k] * a[k, 0] * A[j, k]
            V[i, j] = acc
            V[j, i] = acc
    for i in range(6):
        for j in range(6):
            A[i, j] = V[i, j]


@njit(cache=True)
def _clamp_normal_block(A, a, T):
    """A -= sum over the negative eigenvalues lam of the 2x2 block
    a[4:6, 4:6] (the normal subspace R^2 (x) n of ``_project_psd_split``'s
    basis, n = T[4]) of lam w w^T, w = (v0 n, v1 n) for the unit eigenvector
    v: the eigenvalue clamp of A where its other block needs none."""
    p = a[4, 4]
    q = a[5, 5]
    r = 0.5 * (a[4, 5] + a[5, 4])
    h = 0.5 * (p - q)
    m = 0.5 * (p + q)
    rad = math.sqrt(h * h + r * r)
    for sign in (-1.0, 1.0):
        lam = m + sign * rad
        if lam >= 0.0:
            continue
        if rad == 0.0:              # a multiple of the identity: both directions
            for v0, v1 in ((1.0, 0.0), (0.0, 1.0)):
                _subtract_rank_one(A, T, lam, v0, v1)
            return
        # (r, lam - p) and (lam - q, r) both solve the eigen equation; the
        # longer one is the better conditioned
        v0, v1 = r, lam - p
        u0, u1 = lam - q, r
        if u0 * u0 + u1 * u1 > v0 * v0 + v1 * v1:
            v0, v1 = u0, u1
        nv = math.sqrt(v0 * v0 + v1 * v1)
        _subtract_rank_one(A, T, lam, v0 / nv, v1 / nv)


@njit(cache=True)
def _subtract_rank_one(A, T, lam, v0, v1):
    """A -= lam w w^T with w[al*3 + l] = v_al n[l], n = T[4]."""
    w = np.empty(6)
    for l in range(3):
        w[l] = v0 * T[4, l]
        w[3 + l] = v1 * T[4, l]
    for i in range(6):
        for j in range(6):
            A[i, j] -= lam * w[i] * w[j]


# which copy of R^3 (the F column alpha) each column of _project_psd_split's basis lies in
_AL = np.array([0, 0, 1, 1, 0, 1], dtype=np.int64)


@njit(cache=True)
def _green_strain(x, G, el, i0, i1, i2, F, e):
    """F = sum_i x_i g_i^T (3x2) and its Green strain e (Voigt, engineering shear)."""
    for k in range(3):
        for al in range(2):
            F[k, al] = x[i0, k] * G[el, 0, al] + x[i1, k] * G[el, 1, al] + x[i2, k] * G[el, 2, al]
    e[0] = 0.5 * (F[0, 0] * F[0, 0] + F[1, 0] * F[1, 0] + F[2, 0] * F[2, 0] - 1.0)
    e[1] = 0.5 * (F[0, 1] * F[0, 1] + F[1, 1] * F[1, 1] + F[2, 1] * F[2, 1] - 1.0)
    e[2] = F[0, 0] * F[0, 1] + F[1, 0] * F[1, 1] + F[2, 0] * F[2, 1]


@njit(cache=True)
def _add_element_force(F, sig, A, G, tris, el, B, gF, force):
    """force -= A sig . de/dx for element el: B = de/dF at F (3x6, column
    alpha*3 + l; B[1, :3] and B[0, 3:] stay zero), the vertices through G."""
    for l in range(3):
        B[0, l] = F[l, 0]
        B[1, 3 + l] = F[l, 1]
        B[2, l] = F[l, 1]
        B[2, 3 + l] = F[l, 0]
    for col in range(6):
        gF[col] = A * (sig[0] * B[0, col] + sig[1] * B[1, col] + sig[2] * B[2, col])
    for vi in range(3):
        node = tris[el, vi]
        for k in range(3):
            force[node, k] -= G[el, vi, 0] * gF[k] + G[el, vi, 1] * gF[3 + k]


@njit(cache=True)
def membrane_forces(x, tris, G, Rg, area, C, model, weight, want_jac, project,
                    force, hr, tables=NO_TABLE):
    """Accumulate membrane forces into ``force`` (n_local, 3).

    With ``want_jac`` fills ``hr`` (ne, 6, 6) with each element's Hessian in
    the reduced frame (see module doc), projected to PSD if ``project``.
    Returns (weighted elastic energy, largest principal strain)."""
    ne = tris.shape[0]
    energy = 0.0
    max_strain = -np.inf
    F = np.empty((3, 2))
    e = np.empty(3)
    sig = np.empty(3)
    D = np.empty((3, 3))
    B = np.zeros((3, 6))
    gF = np.empty(6)
    HF = np.empty((6, 6))
    T = np.empty((6, 6))
    L = np.empty((6, 6))
    T6 = np.empty((6, 6))
    A6 = np.empty((6, 6))
    V6 = np.empty((6, 6))
    wk = np.empty((8, 3, 3))
    tol = 1e-10 * np.abs(C).max()
    for el in range(ne):
        i0 = tris[el, 0]
        i1 = tris[el, 1]
        i2 = tris[el, 2]
        _green_strain(x, G, el, i0, i1, i2, F, e)
        W, pm = _energy_density(e, C, model, want_jac, sig, D, wk, tables)
        A = area[el]
        energy += W * A * weight[el]
        if pm > max_strain:
            max_strain = pm
        _add_element_force(F, sig, A, G, tris, el, B, gF, force)
        if want_jac:
            # HF = A (B^T D B + Sigma_mat (x) I3)
            for p in range(6):
                for q in range(6):
                    acc = 0.0
                    for m in range(3):
                        bm = B[m, p]
                        if bm != 0.0:
                            for n in range(3):
                                acc += bm * D[m, n] * B[n, q]
                    HF[p, q] = A * acc
            for k in range(3):
                HF[k, k] += A * sig[0]
                HF[3 + k, 3 + k] += A * sig[1]
                HF[k, 3 + k] += A * sig[2]
                HF[3 + k, k] += A * sig[2]
            # Hr[a*3+k, b*3+l] = sum Rg[a,al] Rg[b,be] HF[al*3+k, be*3+l]
            for a in range(2):
                for k in range(3):
                    for q in range(6):
                        T[a * 3 + k, q] = Rg[el, a, 0] * HF[k, q] + Rg[el, a, 1] * HF[3 + k, q]
            for p in range(6):
                for b in range(2):
                    for l in range(3):
                        hr[el, p, b * 3 + l] = Rg[el, b, 0] * T[p, l] + Rg[el, b, 1] * T[p, 3 + l]
            if project:
                for p in range(6):
                    for q in range(p):
                        sym = 0.5 * (hr[el, p, q] + hr[el, q, p])
                        hr[el, p, q] = sym
                        hr[el, q, p] = sym
                # Hr is PSD if D and Sigma_mat are (B^T D B + Sigma_mat (x) I3 is a
                # congruence plus a Kronecker product); else try Cholesky; else eigh
                # (Sigma tested against -tol, tol = 1e-10 |C|: the round-off of a rest
                # state's strain is ~1e-16 / (edge / coordinate size), 1e-13 on fine
                # meshes; an admitted negative eigenvalue is < 1e-10 of the material
                # stiffness A |C|, far below the solver tolerances)
                if not (_is_psd3(D) and sig[0] >= -tol and sig[1] >= -tol
                        and (sig[0] + tol) * (sig[1] + tol) >= sig[2] * sig[2]):
                    if not _is_pd6(hr[el], L):
                        _project_psd_split(hr[el], F, T6, A6, V6)
    if ne == 0:
        max_strain = 0.0
    return energy, max_strain


@njit(cache=True)
def membrane_discrete_gradient(x0, x1, tris, G, area, C, model, force, tables=NO_TABLE):
    """Accumulate the membrane force of a step from x0 to x1 into ``force``: a
    discrete gradient, force . (x1 - x0) = -(U(x1) - U(x0)) to round-off.

    The Green strain is quadratic in x, so e1 - e0 = B(F_m) : (F1 - F0) exactly
    with F_m = (F0 + F1)/2; the stress is Gonzalez's discrete gradient of W in
    strain space (Gonzalez 1996), sig = dW/de(e_m) + (W1 - W0 - dW/de(e_m) . de)
    de / |de|^2 with e_m = (e0 + e1)/2.  For stvk W is quadratic in e, the
    correction vanishes and sig = C (e0 + e1)/2: Simo and Tarnow's (1992)
    average of the end-point stresses with F at the midpoint."""
    ne = tris.shape[0]
    F0 = np.empty((3, 2))
    F1 = np.empty((3, 2))
    e0 = np.empty(3)
    e1 = np.empty(3)
    em = np.empty(3)
    sig = np.empty(3)
    sc = np.empty(3)
    D = np.empty((3, 3))
    B = np.zeros((3, 6))
    gF = np.empty(6)
    wk = np.empty((8, 3, 3))
    for el in range(ne):
        i0 = tris[el, 0]
        i1 = tris[el, 1]
        i2 = tris[el, 2]
        _green_strain(x0, G, el, i0, i1, i2, F0, e0)
        _green_strain(x1, G, el, i0, i1, i2, F1, e1)
        for m in range(3):
            em[m] = 0.5 * (e0[m] + e1[m])
        _energy_density(em, C, model, False, sig, D, wk, tables)
        if model != STVK:
            W0 = _energy_density(e0, C, model, False, sc, D, wk, tables)[0]
            W1 = _energy_density(e1, C, model, False, sc, D, wk, tables)[0]
            dd = 0.0
            lin = 0.0
            for m in range(3):
                de = e1[m] - e0[m]
                dd += de * de
                lin += sig[m] * de
            # below a strain change of 1e-12 the correction is round-off of W1 - W0
            if dd > 1e-24:
                c = (W1 - W0 - lin) / dd
                for m in range(3):
                    sig[m] += c * (e1[m] - e0[m])
        for k in range(3):
            for al in range(2):
                F0[k, al] = 0.5 * (F0[k, al] + F1[k, al])
        _add_element_force(F0, sig, area[el], G, tris, el, B, gF, force)


@njit(cache=True)
def membrane_stiffness_product(tris, hr, w, out):
    """out += (df/dx) w = -H w with H = (Q0 (x) I3) Hr (Q0 (x) I3)^T per element."""
    q00, q01 = 1.0 / np.sqrt(2.0), 1.0 / np.sqrt(6.0)
    Q = np.array([[q00, q01], [-q00, q01], [0.0, -2.0 * q01]])
    wr = np.empty(6)
    for el in range(tris.shape[0]):
        for a in range(2):
            for k in range(3):
                acc = 0.0
                for i in range(3):
                    acc += Q[i, a] * w[tris[el, i], k]
                wr[a * 3 + k] = acc
        for p in range(6):
            acc = 0.0
            for q in range(6):
                acc += hr[el, p, q] * wr[q]
            a = p // 3
            k = p % 3
            for i in range(3):
                out[tris[el, i], k] -= Q[i, a] * acc


@njit(cache=True)
def add_membrane_blocks(hr, alpha, slots, data):
    """data[slot(i,j)] += alpha H_ij with H_ij[k,l] = sum_ab Q0[i,a] Q0[j,b] Hr[a*3+k, b*3+l].

    ``slots`` (ne, 9) row-major over (i, j) vertex pairs, -1 for ghost rows."""
    q00, q01 = 1.0 / np.sqrt(2.0), 1.0 / np.sqrt(6.0)
    Q = np.array([[q00, q01], [-q00, q01], [0.0, -2.0 * q01]])
    for el in range(hr.shape[0]):
        for i in range(3):
            for j in range(3):
                slot = slots[el, i * 3 + j]
                if slot < 0:
                    continue
                for k in range(3):
                    for l in range(3):
                        acc = 0.0
                        for a in range(2):
                            for b in range(2):
                                acc += Q[i, a] * Q[j, b] * hr[el, a * 3 + k, b * 3 + l]
                        data[slot, k, l] += alpha * acc


def element_hessians(hr):
    """Dense 9x9 per-element Hessians (ne, 9, 9), index i*3+k (diagnostics, tests)."""
    H = hr.reshape(-1, 2, 3, 2, 3)
    return np.einsum("ia,jb,eakbl->eikjl", Q0, Q0, H).reshape(-1, 9, 9)


# -------------------------------------------------------------------- term

class MembraneFEMTerm(ForceTerm):
    """Continuum membrane on local triangles (owned vertices first, then ghosts).

    ``weight`` (ne,) multiplies each triangle's energy (the caller passes the
    fraction of its vertices this rank owns, so ranks sum to the total).
    ``project=True`` (default) stores the PSD-projected element Hessians,
    used consistently by ``stiffness_product`` and ``add_to_system``;
    ``project=False`` keeps the exact Hessian (finite-difference tests)."""

    name = "force:membrane"

    def __init__(self, triangles, rest_positions, weft, C, strain_model, weight,
                 project=True, tables=None, rest_corners=None, scale=None):
        if strain_model not in STRAIN_MODELS:
            raise ValueError(f"unknown strain model {strain_model!r}; "
                             f"choose from {sorted(STRAIN_MODELS)}")
        self.tris = np.ascontiguousarray(triangles, dtype=np.int64).reshape(-1, 3)
        self.model = STRAIN_MODELS[strain_model]
        self.strain_model = strain_model
        # tables: weft, warp (Green strain, direct stress N/m), shear (engineering
        # shear strain 2 E_uv, shear stress N/m); each (k, 2) from (0, 0)
        self.tables = NO_TABLE
        if tables is not None:
            if strain_model != "stvk":
                raise ValueError("tabulated tension curves go with the stvk strain model")
            k = max(len(t) for t in tables)
            self.tables = np.array([_pad(np.asarray(t, float), k) for t in tables])
            self.model = TABULATED
        self.C = np.ascontiguousarray(C, dtype=np.float64)
        self.weight = np.ascontiguousarray(np.broadcast_to(
            np.asarray(weight, dtype=np.float64), (self.tris.shape[0],)))
        self.project = bool(project)
        if self.tris.shape[0]:
            # rest_corners (ne, 3, 3): each triangle's own rest corners (a welded
            # garment has no single rest shape, garment/weld.py)
            rest, stencil = rest_positions, self.tris
            if rest_corners is not None:
                rest = np.asarray(rest_corners, dtype=np.float64).reshape(-1, 3)
                stencil = np.arange(rest.shape[0], dtype=np.int64).reshape(-1, 3)
            self.G, self.Rg, self.area, self.frame = rest_frames(rest, stencil, weft)
            if scale is not None:
                # a fused interlining adds its stiffness: every term of the
                # element's energy, force and Hessian is linear in its area
                self.area = self.area * np.asarray(scale, dtype=np.float64)
        else:
            self.G, self.Rg = np.zeros((0, 3, 2)), np.zeros((0, 2, 2))
            self.area, self.frame = np.zeros(0), np.zeros((0, 3, 3))
        self.hr = np.zeros((self.tris.shape[0], 6, 6))
        self.slots = None
        # the last evaluation with the Hessian (which self.hr holds) and without:
        # (x, force, energy, strain) each
        self._cache = {True: None, False: None}

    def stencils(self):
        return [self.tris]

    def bind(self, pattern):
        self.slots = pattern.slots_for(self.tris)

    def _run(self, x, force, want_jac):
        return membrane_forces(np.ascontiguousarray(x, dtype=np.float64), self.tris, self.G,
                               self.Rg, self.area, self.C, self.model, self.weight,
                               want_jac, self.project, force, self.hr, self.tables)

    def _at(self, x, want_jac):
        """(force contribution, energy, largest strain) at x, from the last
        evaluation if it was at the same x (and kept the Hessian if asked):
        a step's contact passes evaluate the same start state again, and the
        health check's energy and the diagnostics' strain the same end state;
        with compressed triangles (after contact) each evaluation costs
        their Hessians' projections."""
        for c in (self._cache[True],) if want_jac else (self._cache[True], self._cache[False]):
            if c is not None and np.array_equal(c[0], x):
                return c[1:]
        f = np.zeros((np.asarray(x).shape[0], 3))
        energy, strain = self._run(x, f, want_jac)
        self._cache[want_jac] = (np.array(x, dtype=np.float64), f, energy, strain)
        return f, energy, strain

    def evaluate(self, x, v, force, want_jac):
        f, energy, strain = self._at(x, want_jac)
        force += f
        return {"elastic_energy": energy, "max_strain": strain}

    def evaluate_between(self, x0, x1, v, force, want_jac):
        x0 = np.ascontiguousarray(x0, dtype=np.float64)
        x1 = np.ascontiguousarray(x1, dtype=np.float64)
        if want_jac:     # the Newton matrix: the Hessian at the midpoint
            self._cache[True] = None
            self._run(0.5 * (x0 + x1), np.zeros_like(x1), True)
        membrane_discrete_gradient(x0, x1, self.tris, self.G, self.area, self.C, self.model,
                                   force, self.tables)
        return {}

    def stiffness_product(self, w, out):
        membrane_stiffness_product(self.tris, self.hr, np.ascontiguousarray(w), out)

    def add_to_system(self, data, alpha, beta):
        add_membrane_blocks(self.hr, alpha, self.slots, data)

    def energy(self, x):
        return float(self._at(x, False)[1])

    def max_strain(self, x):
        """Largest principal engineering strain (stretch - 1) over the triangles.
        The kernel reports the model's own measure: Green's E for stvk (and
        tables), whose principal stretch is sqrt(1 + 2 E); Biot's S - I for
        corotated, already stretch - 1."""
        if not self.tris.shape[0]:
            return 0.0
        e = float(self._at(x, False)[2])
        if self.model != COROTATED:
            e = math.sqrt(max(1.0 + 2.0 * e, 0.0)) - 1.0
        return max(e, 0.0)

    def element_hessians(self):
        return element_hessians(self.hr)


def with_compression(table, factor: float):
    """A tension curve [[e, S], ...] from (0, 0) with a compression branch of
    ``factor`` times its first slope, as a leading row at e = -1."""
    table = np.asarray(table, dtype=np.float64)
    slope = (table[1, 1] - table[0, 1]) / (table[1, 0] - table[0, 0])
    return np.vstack([[-1.0, -factor * slope], table])


def _pad(table, k):
    """Repeat the last segment's slope to give every table k points (one array)."""
    while table.shape[0] < k:
        slope = (table[-1] - table[-2])
        table = np.vstack([table, table[-1] + slope])
    return table
