"""Bending with a per-triangle curvature tensor built from its three hinges.

Why not the per-hinge sums of ``bending.py``
---------------------------------------------
The hinge models of the EG07 tutorial, Part 1 §4.3 (dihedral angle, Bridson
et al. 2003; isometric, Bergou et al. 2006) add one independent term per
hinge, sum_h c_h theta_h^2. On a mesh whose hinges run in a few directions
that sum is the quadratic form sum_d c_d (n_d^T K n_d)^2 of the curvature
tensor K, which is not the isotropic plate energy: on the split-square grid
it has no twist stiffness along the grid axes, so a bent strip relieves its
diagonal hinges by twisting at the mesh scale and comes out 15-17 % too
compliant at every resolution (tests/test_elastica.py;
docs/mesh_independence.md).

What is done here (a rotation-free shell triangle: Onate and Zarate 2000,
"basic shell triangle"; Grinspun et al. 2006, "Computing discrete shape
operators on general meshes"): each triangle T gets a curvature tensor K_T
(2x2, in T's rest frame) from the bending of its (up to) three hinges, and
the energy is the continuum one on it,

    E = sum_T 1/2 B A_T |K_T|_F^2 = 1/2 B A_T (Kxx^2 + Kyy^2 + 2 Kxy^2),

i.e. a plate with bending Poisson ratio 0: B (N.m) is the moment per unit
width per unit curvature for a bend in any direction (Kawabata's strip
rigidity) and the twist rigidity is B/2 per unit twist, so a strip's
stiffness does not depend on whether it curls sideways.

The hinge measure of K (exact for every quadratic surface, on any mesh)
-------------------------------------------------------------------------
For a piecewise-linear interpolant of a height f over a flat hinge, the jump
of the normal derivative across the edge is sum_a w_a f_a with the cotangent
stencil w = -k / |e| of Bergou et al. (``bending.hinge_rest_geometry``; sign
below).  For f = 1/2 p^T K p (p the 2-D rest coordinates),

    jump_i = sum_a w_a 1/2 p_a^T K p_a = 1/2 K : M_i,   M_i = sum_a w_a p_a p_a^T,

exactly.  Written in the vector kappa = (Kxx, Kyy, sqrt2 Kxy) (so |K|_F =
|kappa|), jump_i = c_i . kappa with c_i = 1/2 (Mxx, Myy, sqrt2 Mxy).  The
dihedral angle of a hinge equals that jump to first order.  Triangle T has
rows c_i for the hinges it has.  Interior triangles: three rows, kappa =
C^-1 theta.  A triangle on a free edge has no neighbour there: by default
(``free_edge="zero_curvature"``) the missing row is built from T's mirror
image across the edge and its angle taken as 0 -- the curvature across a
free edge vanishes, the natural condition M_nn = 0 of a plate with bending
Poisson ratio 0; ``"min_norm"`` instead leaves the unmeasured curvature to
minimise the energy, kappa = C^T (C C^T)^-1 theta.  Either way

    E_T = 1/2 theta_T^T Q_T theta_T,   Q_T = B A_T [(C C^T)^-1 restricted to present hinges].

Measured (tests/test_bending_shell.py, tests/test_elastica.py,
docs/mesh_independence.md): exact on every quadratic surface on interior
triangles of any mesh, and on the split-square grid with diagonals all one
way the heavy cantilever matches the elastica to 0.1 % where the per-hinge
sums are 15 % too compliant.  KNOWN DEFECT: consistency is not stability.
On the alternating (checkerboard) grid an hourglass mode on the valence-4
vertices makes the free plate's second eigenvalue 45 % low and the
cantilever 27-45 % too compliant; on jittered Delaunay meshes the same kind
of soft mode leaves it 4-6 % too compliant, not improving with refinement.
Hence the curvature-jump penalty
1/2 gamma B A_e |K_T1 - K_T2|_F^2 (A_e = (A_T1 + A_T2)/3) between
neighbouring triangles that both have three hinges: zero on quadratic
surfaces (consistency kept), stiff on hourglass modes; gamma = JUMP_GAMMA =
10 from scripts/shell_bending_study.py.  With it the heavy cantilever is
within 2.5 % of the elastica on split-square, alternating and Delaunay
meshes (tests/test_elastica.py).  Cost: an extra 12-entry element per such
pair (wider matrix stencil and ghost layer).

The two models
--------------
* dihedral (nonlinear, large rotations): theta_i is the signed dihedral
  angle of hinge i minus its rest angle (``bending.hinge_angle_gradient``,
  Bridson et al. 2003's gradient).  Forces are exact; the system matrix is
  the Gauss-Newton Hessian sum_ij Q_ij grad theta_i grad theta_j^T
  (positive semi-definite since Q is); the dropped part sum_i (Q theta)_i
  Hess theta_i vanishes at rest.
* isometric (quadratic, constant Hessian; Bergou et al. 2006, the linear
  bending of Volino and Magnenat-Thalmann 2006, EG07 tutorial, Part 1 §4.3,
  Fig. 11c): theta_i is replaced by the vector jump J_i = sum_a w_a x_a (for a flat hinge bent by theta,
  J = theta n + O(theta^2)),
  E_T = 1/2 sum_ij Q_ij J_i . J_j.  The energy is a fixed quadratic form of
  the positions, rotation invariant, zero for every affine map of a flat
  rest shape (linear precision of w), Jacobian constant and exact.  Like
  Bergou's it assumes a flat rest shape.

Stencil layout: a row (v0, v1, v2, o0, o1, o2) per triangle, o_i the vertex
across edge i = (v_{i+1}, v_{i+2}); a missing neighbour (free or non-manifold
edge) repeats v_i there and its hinge is flagged absent (zero rows in Q).
Hinge i of T is (v_{i+1}, v_{i+2}, v_i, o_i) in ``bending``'s hinge layout
(edge as it runs in T, T first, neighbour second).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .bending import hinge_angle_gradient, hinge_angles
from .base import ForceTerm

SQRT2 = np.sqrt(2.0)
# stencil positions of hinge i of a triangle: edge (i+1, i+2), own vertex i, opposite 3+i
HINGE_SLOTS = np.array([[1, 2, 0, 3], [2, 0, 1, 4], [0, 1, 2, 5]], dtype=np.int64)


# --------------------------------------------------------------------------
# topology and rest geometry (vectorised numpy)
# --------------------------------------------------------------------------

def shell_stencils(triangles) -> tuple[np.ndarray, np.ndarray]:
    """(stencil (nt, 6) int64, present (nt, 3) bool) of a consistently oriented mesh.

    Raises ValueError when two triangles run a shared edge the same way."""
    tri = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    nt = tri.shape[0]
    stencil = np.concatenate([tri, tri], axis=1)
    present = np.zeros((nt, 3), dtype=bool)
    if nt == 0:
        return stencil, present
    src = tri[:, [1, 2, 0]].ravel()           # edge i of triangle t runs v_{i+1} -> v_{i+2}
    dst = tri[:, [2, 0, 1]].ravel()
    n = int(tri.max()) + 1
    key = np.minimum(src, dst) * n + np.maximum(src, dst)
    order = np.argsort(key, kind="stable")
    ks = key[order]
    starts = np.flatnonzero(np.concatenate([[True], ks[1:] != ks[:-1]]))
    counts = np.diff(np.concatenate([starts, [ks.shape[0]]]))
    two = starts[counts == 2]                 # manifold interior edges only
    a, b = order[two], order[two + 1]
    if np.any(src[a] != dst[b]):
        raise ValueError("shell_stencils: triangles are not consistently oriented")
    ta, ia = a // 3, a % 3
    tb, ib = b // 3, b % 3
    stencil[ta, 3 + ia] = tri[tb, ib]
    stencil[tb, 3 + ib] = tri[ta, ia]
    present[ta, ia] = True
    present[tb, ib] = True
    return stencil, present


def _rows(v):
    return np.einsum("ij,ij->i", v, v)


def hinge_jump_weights(p0, p1, p2, p3):
    """Jump weights w (m, 4) of hinges (p0 -> p1, own p2, opposite p3), any
    embedding: sum_a w_a f_a is the jump of the normal derivative of the
    piecewise-linear f across the edge, positive for a convex-up fold.  w =
    -k/|e| with Bergou's cotangent stencil k (see bending.py)."""
    def cot(u, v):
        return np.einsum("ij,ij->i", u, v) / np.linalg.norm(np.cross(u, v), axis=1)
    ca0, ca1 = cot(p1 - p0, p2 - p0), cot(p0 - p1, p2 - p1)
    cb0, cb1 = cot(p1 - p0, p3 - p0), cot(p0 - p1, p3 - p1)
    k = np.stack([ca1 + cb1, ca0 + cb0, -ca0 - ca1, -cb0 - cb1], axis=1)
    return -k / np.sqrt(_rows(p1 - p0))[:, None]


def shell_rest_geometry(x_rest, stencil, present, stiffness, free_edge="zero_curvature"):
    """Per triangle: Q (nt, 3, 3), rest angles theta0 (nt, 3), jump weights
    W (nt, 3, 6) in stencil numbering (zero rows for absent hinges), area (nt,)."""
    x = np.asarray(x_rest, dtype=np.float64)
    nt = stencil.shape[0]
    Bt = np.broadcast_to(np.asarray(stiffness, dtype=np.float64), (nt,))
    v = x[stencil]                                  # (nt, 6, 3)
    e1 = v[:, 1] - v[:, 0]
    nrm = np.cross(e1, v[:, 2] - v[:, 0])
    area = 0.5 * np.linalg.norm(nrm, axis=1)
    nhat = nrm / (2.0 * area)[:, None]
    ex = e1 / np.linalg.norm(e1, axis=1)[:, None]
    ey = np.cross(nhat, ex)
    own2 = np.stack([np.einsum("tj,tj->t", v[:, a] - v[:, 0], ex) for a in range(3)]
                    + [np.einsum("tj,tj->t", v[:, a] - v[:, 0], ey) for a in range(3)],
                    axis=1).reshape(nt, 2, 3).transpose(0, 2, 1)   # (nt, 3, 2)
    C = np.zeros((nt, 3, 3))
    W = np.zeros((nt, 3, 6))
    theta0 = np.zeros((nt, 3))
    for i in range(3):
        s0, s1, s2, s3 = HINGE_SLOTS[i]
        has = present[:, i]
        a2, b2, c2 = own2[:, s0], own2[:, s1], own2[:, s2]
        e2 = b2 - a2
        le = np.linalg.norm(e2, axis=1)
        e2 = e2 / le[:, None]
        out = np.stack([e2[:, 1], -e2[:, 0]], axis=1)           # a normal of the edge in 2-D
        flip = np.einsum("tj,tj->t", out, c2 - a2) > 0.0         # ... pointing away from T
        out[flip] *= -1.0
        # the opposite vertex in T's plane: the neighbour's, unfolded across edge i
        # (rotated about the edge); for a free edge the mirror image of T's own
        along = np.einsum("tj,tj->t", c2 - a2, e2)
        away = np.abs(np.einsum("tj,tj->t", c2 - a2, out))
        t = np.nonzero(has)[0]
        e3 = v[t, s1] - v[t, s0]
        r3 = v[t, s3] - v[t, s0]
        along[t] = np.einsum("tj,tj->t", r3, e3) / le[t]
        away[t] = np.linalg.norm(r3 - (along[t] / le[t])[:, None] * e3, axis=1)
        q2 = a2 + along[:, None] * e2 + away[:, None] * out
        P = np.stack([a2, b2, c2, q2], axis=1)                  # (nt, 4, 2)
        P3 = np.concatenate([P, np.zeros((nt, 4, 1))], axis=2)
        w = hinge_jump_weights(P3[:, 0], P3[:, 1], P3[:, 2], P3[:, 3])
        M = np.einsum("ta,tap,taq->tpq", w, P, P)
        C[:, i] = 0.5 * np.stack([M[:, 0, 0], M[:, 1, 1], SQRT2 * M[:, 0, 1]], axis=1)
        for a, sl in enumerate((s0, s1, s2, s3)):
            W[t, i, sl] += w[t, a]
        theta0[t, i] = hinge_angles(x, stencil[t][:, [s0, s1, s2, s3]])
    absent = ~present
    if free_edge == "min_norm":
        C[absent] = 0.0
    G = np.einsum("tik,tjk->tij", C, C)
    idx = np.arange(3)
    if free_edge == "min_norm":
        G[:, idx, idx] += absent                    # rows of absent hinges are 0: invert the rest
    Q = np.linalg.pinv(G, rcond=1e-12, hermitian=True)
    Q[np.repeat(absent[:, :, None], 3, axis=2)] = 0.0
    Q[np.repeat(absent[:, None, :], 3, axis=1)] = 0.0
    # kappa = C^T (C C^T)^+ d (present hinges), then K3 = R K R^T in 3-D rest
    # coordinates (R = [ex ey]), as the 6-vector (xx, yy, zz, r2 xy, r2 xz, r2 yz)
    kmap = np.einsum("tik,tij->tkj", C, Q)                  # (nt, 3 kappa, 3 hinges)
    r2 = SQRT2
    basis = np.stack([_sym6(ex, ex), _sym6(ey, ey), _sym6(ex, ey, r2)], axis=2)   # (nt, 6, 3)
    kmap3 = np.einsum("tak,tkj->taj", basis, kmap)
    Q *= (Bt * area)[:, None, None]
    return np.ascontiguousarray(Q), theta0, np.ascontiguousarray(W), area, kmap3


def _sym6(a, b, scale=1.0):
    """The 3-D tensor scale * (a b^T + b a^T) / 2 (a = b: a a^T) of unit-vector
    rows as Frobenius-isometric 6-vectors (xx, yy, zz, r2 xy, r2 xz, r2 yz); for
    kappa_3 = Kxy the scale r2 makes (ex ey^T + ey ex^T) / r2 unit-norm."""
    S = 0.5 * (a[:, :, None] * b[:, None, :] + b[:, :, None] * a[:, None, :]) * scale
    r2 = SQRT2
    return np.stack([S[:, 0, 0], S[:, 1, 1], S[:, 2, 2], r2 * S[:, 0, 1], r2 * S[:, 0, 2],
                     r2 * S[:, 1, 2]], axis=1)


# --------------------------------------------------------------------------
# kernels for an element with nh hinges over an s-vertex stencil:
# E = 1/2 d^T Q d, d the hinge angle deviations (dihedral) -- or, isometric,
# E = 1/2 sum_ab H_ab x_a . x_b with H = W^T Q W.  hs (nh, 4): the stencil
# positions of each hinge (edge start, edge end, own vertex, opposite vertex).
# --------------------------------------------------------------------------

@njit(cache=True)
def shell_dihedral_forces(x, st, hs, present, theta0, Q, weight, force, G):
    """force += -sum_i (Q d)_i grad theta_i per element, d = theta - theta0.

    Fills G (ne, nh, s, 3) with grad theta_i in stencil numbering (zero for
    absent hinges).  Returns (weighted energy, max |d|)."""
    nh = hs.shape[0]
    ns = st.shape[1]
    g = np.zeros((4, 3))
    d = np.zeros(nh)
    energy = 0.0
    worst = 0.0
    for t in range(st.shape[0]):
        G[t] = 0.0
        for i in range(nh):
            d[i] = 0.0
            if not present[t, i]:
                continue
            theta = hinge_angle_gradient(x, st[t, hs[i, 0]], st[t, hs[i, 1]], st[t, hs[i, 2]],
                                         st[t, hs[i, 3]], g)
            d[i] = theta - theta0[t, i]
            if abs(d[i]) > worst:
                worst = abs(d[i])
            for a in range(4):
                for c in range(3):
                    G[t, i, hs[i, a], c] += g[a, c]
        e = 0.0
        for i in range(nh):
            m = 0.0
            for j in range(nh):
                m += Q[t, i, j] * d[j]
            e += 0.5 * d[i] * m
            if m == 0.0:
                continue
            for a in range(ns):
                k = st[t, a]
                for c in range(3):
                    force[k, c] -= m * G[t, i, a, c]
        energy += e * weight[t]
    return energy, worst


@njit(cache=True)
def shell_gn_product(st, G, Q, w, out):
    """out += (df/dx) w = -sum_ij Q_ij grad theta_i (grad theta_j . w)."""
    nh = G.shape[1]
    ns = st.shape[1]
    s = np.zeros(nh)
    for t in range(st.shape[0]):
        for i in range(nh):
            acc = 0.0
            for a in range(ns):
                k = st[t, a]
                for c in range(3):
                    acc += G[t, i, a, c] * w[k, c]
            s[i] = acc
        for i in range(nh):
            m = 0.0
            for j in range(nh):
                m += Q[t, i, j] * s[j]
            if m == 0.0:
                continue
            for a in range(ns):
                k = st[t, a]
                for c in range(3):
                    out[k, c] -= m * G[t, i, a, c]


@njit(cache=True)
def add_shell_gn_blocks(G, Q, hs, alpha, slots, data):
    """data[slot(a,b)] += alpha sum_ij Q_ij G_i[a] G_j[b]^T (slots (ne, s*s), -1 skipped).

    grad theta_i is non-zero only on its hinge's four stencil entries hs[i],
    so block (a, b) sums G_i[a] P_i[b]^T over the hinges i holding a (P = Q G):
    a third of the dense sum's work on the 12-entry curvature-jump stencil."""
    nh = G.shape[1]
    ns = G.shape[2]
    P = np.zeros((nh, ns, 3))
    for t in range(G.shape[0]):
        for i in range(nh):
            for a in range(ns):
                for c in range(3):
                    P[i, a, c] = 0.0
            for j in range(nh):
                q = alpha * Q[t, i, j]
                if q == 0.0:
                    continue
                for k in range(4):
                    a = hs[j, k]
                    for c in range(3):
                        P[i, a, c] += q * G[t, j, a, c]
        for i in range(nh):
            for k in range(4):
                a = hs[i, k]
                for b in range(ns):
                    slot = slots[t, ns * a + b]
                    if slot < 0:
                        continue
                    for p in range(3):
                        g = G[t, i, a, p]
                        for q in range(3):
                            data[slot, p, q] += g * P[i, b, q]


@njit(cache=True)
def shell_isometric_forces(x, st, H, weight, force):
    ns = st.shape[1]
    energy = 0.0
    y = np.zeros((ns, 3))
    for t in range(st.shape[0]):
        e = 0.0
        for a in range(ns):
            for c in range(3):
                acc = 0.0
                for b in range(ns):
                    acc += H[t, a, b] * x[st[t, b], c]
                y[a, c] = acc
        for a in range(ns):
            k = st[t, a]
            for c in range(3):
                e += 0.5 * x[k, c] * y[a, c]
                force[k, c] -= y[a, c]
        energy += e * weight[t]
    return energy


@njit(cache=True)
def shell_isometric_product(st, H, w, out):
    ns = st.shape[1]
    for t in range(st.shape[0]):
        for a in range(ns):
            ja = st[t, a]
            for b in range(ns):
                h = H[t, a, b]
                if h == 0.0:
                    continue
                jb = st[t, b]
                out[ja, 0] -= h * w[jb, 0]
                out[ja, 1] -= h * w[jb, 1]
                out[ja, 2] -= h * w[jb, 2]


@njit(cache=True)
def add_shell_isometric_blocks(H, alpha, slots, data):
    ns = H.shape[1]
    for t in range(H.shape[0]):
        for a in range(ns):
            for b in range(ns):
                slot = slots[t, ns * a + b]
                if slot < 0:
                    continue
                val = alpha * H[t, a, b]
                data[slot, 0, 0] += val
                data[slot, 1, 1] += val
                data[slot, 2, 2] += val


# --------------------------------------------------------------------------
# force terms
# --------------------------------------------------------------------------

JUMP_GAMMA = 10.0
"""Weight of the curvature-jump penalty (module docstring): measured on the
linear cantilever, scripts/shell_bending_study.py."""
JUMP_SLOTS = np.concatenate([HINGE_SLOTS, HINGE_SLOTS + 6])


def shell_jump_stencils(stencil, present) -> np.ndarray:
    """(ne, 12): the two 6-stencils of each pair of neighbouring triangles that
    both have all three hinges (the penalty's elements)."""
    full = present.all(axis=1)
    tri = stencil[:, :3]
    if tri.shape[0] == 0:
        return np.zeros((0, 12), dtype=np.int64)
    src, dst = tri[:, [1, 2, 0]].ravel(), tri[:, [2, 0, 1]].ravel()
    n = int(tri.max()) + 1
    key = np.minimum(src, dst) * n + np.maximum(src, dst)
    order = np.argsort(key, kind="stable")
    ks = key[order]
    starts = np.flatnonzero(np.concatenate([[True], ks[1:] != ks[:-1]]))
    two = starts[np.diff(np.concatenate([starts, [ks.shape[0]]])) == 2]
    t1, t2 = order[two] // 3, order[two + 1] // 3
    keep = full[t1] & full[t2]
    return np.concatenate([stencil[t1[keep]], stencil[t2[keep]]], axis=1).astype(np.int64)


class _Group:
    """Elements of one kind: stencil (ne, s), hinge slots hs (nh, 4), present
    (ne, nh), rest angles, Q (ne, nh, nh), jump weights W (ne, nh, s), energy weights."""

    def __init__(self, stencil, hs, present, theta0, Q, W, weight):
        self.stencil = np.ascontiguousarray(stencil, dtype=np.int64)
        self.hs = np.ascontiguousarray(hs, dtype=np.int64)
        self.present = np.ascontiguousarray(present, dtype=np.bool_)
        self.theta0 = np.ascontiguousarray(theta0, dtype=np.float64)
        self.Q = np.ascontiguousarray(Q, dtype=np.float64)
        self.W = np.ascontiguousarray(W, dtype=np.float64)
        self.weight = np.ascontiguousarray(np.broadcast_to(
            np.asarray(weight, dtype=np.float64), (self.stencil.shape[0],)))
        self.H = np.ascontiguousarray(np.einsum("tia,tij,tjb->tab", self.W, self.Q, self.W))
        self.G = np.zeros((self.stencil.shape[0], hs.shape[0], self.stencil.shape[1], 3))
        self.slots = None

    def angles(self, x):
        out = np.zeros(self.present.shape)
        for i in range(self.hs.shape[0]):
            t = np.nonzero(self.present[:, i])[0]
            out[t, i] = hinge_angles(x, self.stencil[t][:, self.hs[i]])
        return out


def _jump_group(jump_stencil, rest, stiffness, weight, gamma):
    """Penalty 1/2 gamma B A_e |K_T1 - K_T2|_F^2, A_e = (A_T1 + A_T2) / 3, as a
    quadratic form in the six hinge deviations of the two triangles."""
    ne = jump_stencil.shape[0]
    ones = np.ones((ne, 3), dtype=bool)
    _, th1, W1, A1, K1 = shell_rest_geometry(rest, jump_stencil[:, :6], ones, 1.0)
    _, th2, W2, A2, K2 = shell_rest_geometry(rest, jump_stencil[:, 6:], ones, 1.0)
    D = np.concatenate([K1, -K2], axis=2)                       # (ne, 6, 6)
    Bt = np.broadcast_to(np.asarray(stiffness, dtype=np.float64), (ne,))
    Q = (gamma * Bt * (A1 + A2) / 3.0)[:, None, None] * np.einsum("tki,tkj->tij", D, D)
    W = np.zeros((ne, 6, 12))
    W[:, :3, :6] = W1
    W[:, 3:, 6:] = W2
    return _Group(jump_stencil, JUMP_SLOTS, np.ones((ne, 6), dtype=bool),
                  np.concatenate([th1, th2], axis=1), Q, W, weight)


class _ShellTerm(ForceTerm):
    """Per-triangle curvature energy, plus (``jump`` = (stencils (ne, 12),
    stiffness, weight, gamma)) the curvature-jump penalty between neighbours."""
    name = "force:bending"

    def __init__(self, stencil, present, rest, stiffness, weight, jump=None):
        stencil = np.ascontiguousarray(stencil, dtype=np.int64).reshape(-1, 6)
        present = np.ascontiguousarray(present, dtype=np.bool_).reshape(-1, 3)
        Q, theta0, W, self.area, self.kmap3 = shell_rest_geometry(rest, stencil, present, stiffness)
        self.groups = [_Group(stencil, HINGE_SLOTS, present, theta0, Q, W, weight)]
        if jump is not None and jump[0].shape[0] > 0:
            js, jB, jw, gamma = jump
            self.groups.append(_jump_group(np.asarray(js, dtype=np.int64).reshape(-1, 12),
                                           rest, jB, jw, gamma))

    # the triangle group's arrays, for tests and diagnostics
    stencil = property(lambda self: self.groups[0].stencil)
    present = property(lambda self: self.groups[0].present)
    Q = property(lambda self: self.groups[0].Q)
    theta0 = property(lambda self: self.groups[0].theta0)
    W = property(lambda self: self.groups[0].W)
    H6 = property(lambda self: self.groups[0].H)

    def stencils(self):
        return [g.stencil for g in self.groups]

    def bind(self, pattern):
        for g in self.groups:
            g.slots = pattern.slots_for(g.stencil)


class ShellDihedralBendingTerm(_ShellTerm):
    """Dihedral-angle bending (Bridson et al. 2003 angles and gradients) with the
    per-triangle curvature energy of the module docstring; Gauss-Newton system
    matrix (positive semi-definite, exact at rest)."""

    def evaluate(self, x, v, force, want_jac):
        energy = 0.0
        for g in self.groups:
            e, _ = shell_dihedral_forces(x, g.stencil, g.hs, g.present, g.theta0, g.Q,
                                         g.weight, force, g.G)
            energy += e
        return {"elastic_energy": energy}

    def stiffness_product(self, w, out):
        for g in self.groups:
            shell_gn_product(g.stencil, g.G, g.Q, w, out)

    def add_to_system(self, data, alpha, beta):
        for g in self.groups:
            add_shell_gn_blocks(g.G, g.Q, g.hs, alpha, g.slots, data)

    def energy(self, x):
        total = 0.0
        for g in self.groups:
            d = g.angles(x) - g.theta0
            total += 0.5 * float(np.sum(np.einsum("ti,tij,tj->t", d, g.Q, d) * g.weight))
        return total

    def angles(self, x):
        """Signed dihedral angles (nt, 3) of each triangle's hinges (0 where absent)."""
        return self.groups[0].angles(x)


class ShellIsometricBendingTerm(_ShellTerm):
    """Quadratic isometric bending with the per-triangle curvature energy: constant,
    exact Jacobian -H, H = sum (W^T Q W) (x) I3 (flat rest shape assumed;
    ``rest_energy`` reports how far from flat the rest shape is)."""

    def __init__(self, stencil, present, rest, stiffness, weight, jump=None):
        super().__init__(stencil, present, rest, stiffness, weight, jump)
        self.rest_energy = self.energy(np.asarray(rest, dtype=np.float64))

    def evaluate(self, x, v, force, want_jac):
        return {"elastic_energy": sum(shell_isometric_forces(x, g.stencil, g.H, g.weight, force)
                                      for g in self.groups)}

    def stiffness_product(self, w, out):
        for g in self.groups:
            shell_isometric_product(g.stencil, g.H, w, out)

    def add_to_system(self, data, alpha, beta):
        for g in self.groups:
            add_shell_isometric_blocks(g.H, alpha, g.slots, data)

    def energy(self, x):
        xa = np.asarray(x, dtype=np.float64)
        total = 0.0
        for g in self.groups:
            xs = xa[g.stencil]
            total += float(np.sum(0.5 * np.einsum("tac,tab,tbc->t", xs, g.H, xs) * g.weight))
        return total
