"""Body contact as an inequality of the step: a barrier energy and a lagged
friction dissipation (incremental potential contact, IPC, Li et al. 2020
§4-5, for vertices against distance-field bodies).

With ``contact.model: barrier`` a body contact is not a constraint chosen
before the solve (contact.py's detection, passes and fail-safe) but a
potential of the step that every Newton iterate sees.  For a vertex at
distance phi from a body whose contact distance is d, the gap s = phi - d
carries

    B(s) = kappa b(s),   b(s) = -(s - w)^2 ln(s / w)   for 0 < s < w, else 0

(IPC Eq. 6, w the barrier width): zero and flat beyond w, infinite at
s = 0, so a vertex never comes closer to the body than d, and C^2, so Newton
sees a smooth energy.  The force is -kappa b'(s) n along the body's outward
normal; its Jacobian -kappa b''(s) n n^T (the curvature of the distance
field, b' times the Hessian of phi, is left out: the Gauss-Newton part, PSD).
kappa is per vertex, kappa_i = stiffness m_i g / |b'(w/2)|: at half the
width the barrier holds ``stiffness`` times the vertex's weight, so a vertex
resting under its own weight sits in the outer part of the band, and one
pressed harder by tension moves in until the log term holds it.

Friction (IPC §5, in velocities): with the normal force lambda = kappa |b'(s)|
and the normal n lagged (fixed at the step's first iterate), the
dissipation potential R = mu lambda f0(|P (v - u)|), P = I - n n^T and u the
body's surface velocity, whose velocity gradient is a Coulomb force of size
mu lambda f1(|v_t|) against the tangential slip v_t; f1 rises from 0 to 1 over
the static speed eps (IPC Eq. 14's smoothing), so a vertex slower than eps is
held as if stuck.  Its damping Jacobian mu lambda f1(y)/y P is PSD (the
curvature of |v_t| left out, as for the barrier).

Everything here is per vertex and local: a rank computes its owned rows from
the replicated colliders; ghosts get nothing (their owners add it).
"""
from __future__ import annotations

import math

import numpy as np

from .base import ForceTerm


def barrier(s, w):
    """b(s) of the module docstring (0 for s >= w; s must be > 0 where < w)."""
    out = np.zeros_like(s)
    a = s < w
    r = s[a] - w
    out[a] = -r * r * np.log(s[a] / w)
    return out


def barrier_slope(s, w):
    """b'(s) (<= 0)."""
    out = np.zeros_like(s)
    a = s < w
    sa, r = s[a], s[a] - w
    out[a] = -2.0 * r * np.log(sa / w) - r * r / sa
    return out


def barrier_curvature(s, w):
    """b''(s) (>= 0 on 0 < s < w)."""
    out = np.zeros_like(s)
    a = s < w
    sa, r = s[a], s[a] - w
    out[a] = -2.0 * np.log(sa / w) - 4.0 * r / sa + r * r / (sa * sa)
    return out


def slip_potential(y, eps):
    """f0(y): y beyond the static speed eps, a cubic below it (f0' = f1)."""
    return np.where(y < eps, -y ** 3 / (3.0 * eps * eps) + y * y / eps + eps / 3.0, y)


def slip_force(y, eps):
    """f1(y) = f0'(y): the friction force's fraction of mu lambda at slip speed y."""
    return np.where(y < eps, 2.0 * y / eps - y * y / (eps * eps), 1.0)


def slip_damping(y, eps):
    """f1(y) / y, with its limit 2 / eps at y = 0: the friction's damping coefficient."""
    return np.where(y < eps, 2.0 / eps - y / (eps * eps), 1.0 / np.maximum(y, 1e-300))


# a move is cut where a vertex would keep less than this fraction of its gap
# (IPC's CCD keeps 0.1 of the distance, Li et al. 2020 §4)
KEEP_GAP = 0.1
# |b'(w / 2)| / w = ln 2 + 1/2
HALF_WIDTH_SLOPE = math.log(2.0) + 0.5


class BarrierContactTerm(ForceTerm):
    """The barrier and friction of the vertices against the scene's bodies.

    ``queries``: per body, (x, t, max_distance) -> (phi, normal, velocity);
    ``offsets`` (k, n_local): the contact distance d per body and vertex;
    ``mu`` (k,): Coulomb coefficients; ``excluded`` (n_local,): held vertices."""
    name = "force:contact"

    def __init__(self, queries, offsets, mu, excluded, mass, n_owned, width, stiffness,
                 gravity, static_speed, convex=None):
        self.queries = list(queries)
        # per body: whether its signed distance is a convex function (a convex
        # shape's is: the analytic ones), which step_bound uses
        self.convex = (np.zeros(len(self.queries), dtype=bool) if convex is None
                       else np.asarray(convex, dtype=bool).reshape(len(self.queries)))
        self.offsets = np.asarray(offsets, dtype=np.float64)
        self.mu = np.asarray(mu, dtype=np.float64)
        self.n_owned = int(n_owned)
        self.free = ~np.asarray(excluded, dtype=bool)[: self.n_owned]
        self.width = float(width)
        self.eps = float(static_speed)
        weight = np.asarray(mass, dtype=np.float64)[: self.n_owned] * max(float(gravity), 1.0)
        self.kappa = stiffness * weight / (HALF_WIDTH_SLOPE * self.width)
        self.t = 0.0
        self.diag_slots = None
        self.lagged = None         # per body: (rows, lambda * mu, P, u) of the friction
        self._blocks = None

    def bind(self, pattern):
        self.diag_slots = pattern.diag_slots

    @property
    def reach(self) -> float:
        """How far from a body a vertex can feel it: the largest d plus the width."""
        return float(np.max(self.offsets, initial=0.0)) + self.width

    def begin_step(self, t_end: float) -> None:
        """The step's bodies are where they are at its end; friction not yet lagged."""
        self.t = float(t_end)
        self.lagged = None

    def gaps(self, x):
        """Per body: (s, normal, velocity) of the owned rows at x (s = phi - d,
        +inf where a mesh body is farther than ``reach``)."""
        n = self.n_owned
        out = []
        for j, query in enumerate(self.queries):
            phi, normal, vel = query(x[:n], self.t, self.reach)
            out.append((phi - self.offsets[j, :n], normal, vel))
        return out

    def touching(self, x) -> int:
        """How many owned vertices lie within the barrier's width of a body at x."""
        near = np.zeros(self.n_owned, dtype=bool)
        for s, _, _ in self.gaps(x):
            near |= s < self.width
        return int(np.sum(near & self.free))

    def lag(self, x) -> None:
        """Fix the friction's normal forces and directions at x (IPC's lagging)."""
        self.lagged = []
        for j, (s, normal, vel) in enumerate(self.gaps(x)):
            rows = np.nonzero(self.free & (s < self.width) & (s > 0.0))[0]
            lam = self.kappa[rows] * -barrier_slope(s[rows], self.width)
            P = np.eye(3)[None] - np.einsum("ni,nj->nij", normal[rows], normal[rows])
            self.lagged.append((rows, self.mu[j] * lam, P, vel[rows]))

    def evaluate(self, x, v, force, want_jac):
        n = self.n_owned
        blocks = np.zeros((n, 3, 3)) if want_jac else None
        damp = np.zeros((n, 3, 3)) if want_jac else None
        gaps = self.gaps(x)
        for s, normal, _ in gaps:
            rows = np.nonzero(self.free & (s < self.width))[0]
            if rows.size == 0:
                continue
            # an iterate is never infeasible (the line search keeps s > 0): a
            # start state inside a body is moved out before the first iterate
            sr = np.maximum(s[rows], 1e-12 * self.width)
            k = self.kappa[rows]
            nr = normal[rows]
            force[rows] -= (k * barrier_slope(sr, self.width))[:, None] * nr
            if want_jac:
                blocks[rows] += (k * barrier_curvature(sr, self.width))[:, None, None] * \
                    np.einsum("ni,nj->nij", nr, nr)
        for rows, mul, P, u in self.lagged or ():
            if rows.size == 0:
                continue
            vt = np.einsum("nij,nj->ni", P, v[rows] - u)
            y = np.linalg.norm(vt, axis=1)
            c = mul * slip_damping(y, self.eps)
            force[rows] -= c[:, None] * vt
            if want_jac:
                damp[rows] += c[:, None, None] * P
        if want_jac:
            # the band's rows at x and the friction's, lagged at an earlier iterate
            touched = np.unique(np.concatenate(
                [np.nonzero(self.free & (s < self.width))[0] for s, _, _ in gaps]
                + [lag[0] for lag in self.lagged or ()] + [np.zeros(0, np.int64)]))
            self._blocks = (blocks, damp, touched)

    def add_to_system(self, data, alpha, beta):
        # A = M - beta df/dv - alpha df/dx: both blocks are -df on the diagonal;
        # only the rows in the barrier's band have any (one diagonal slot a row)
        if self._blocks is None:
            return
        stiff, damp, rows = self._blocks
        data[self.diag_slots[rows]] += alpha * stiff[rows] + beta * damp[rows]

    def stiffness_product(self, w, out):
        if self._blocks is not None:
            out[: self.n_owned] -= np.einsum("nij,nj->ni", self._blocks[0], w[: self.n_owned])

    def energy(self, x):
        """The barrier's potential on the owned rows (friction has none)."""
        total = 0.0
        for s, _, _ in self.gaps(x):
            rows = self.free & (s < self.width)
            total += float(np.sum(self.kappa[rows] * barrier(np.maximum(s[rows], 1e-300),
                                                             self.width)))
        return total

    def dissipation(self, x, v):
        """The friction's dissipation potential R(v) on the owned rows."""
        total = 0.0
        for rows, mul, P, u in self.lagged or ():
            y = np.linalg.norm(np.einsum("nij,nj->ni", P, v[rows] - u), axis=1)
            total += float(np.sum(mul * slip_potential(y, self.eps)))
        return total

    def step_bound(self, x, dx, iterations: int = 12) -> np.ndarray:
        """Per owned row, the largest fraction t <= 1 of the move x -> x + dx
        along which the vertex keeps at least KEEP_GAP of its gap s at x
        (conservative advancement, as IPC's additive CCD; each advance
        queries the gaps again).  Each body's gap along the move is bounded
        below by a line through the current point: for a convex body its
        tangent s + tau n.dx (a convex set's signed distance is convex, so
        it lies above its tangents), which never holds back a vertex that
        slides along the body or leaves it; for any other body, whose
        distance field is only 1-Lipschitz, s - tau |dx|.  Vertices whose
        move is shorter than their gap are free at once."""
        n = self.n_owned
        length = np.linalg.norm(dx[:n], axis=1)
        t = np.ones(n)
        active = self.free & (length > 0.0)
        reach = float(np.max(length, initial=0.0)) + self.reach
        if not active.any():
            return t
        t[active] = 0.0
        rows = np.nonzero(active)[0]
        floor = None
        for _ in range(iterations):
            xr = x[rows] + t[rows, None] * dx[rows]
            gaps, closing = [], []
            for j, query in enumerate(self.queries):
                phi, normal, _ = query(xr, self.t, reach)
                gap = phi - self.offsets[j, rows]
                gaps.append(np.where(np.isfinite(gap), gap, reach))
                # how fast the lower bound falls per unit of t
                closing.append(-np.einsum("ni,ni->n", normal, dx[rows]) if self.convex[j]
                               else length[rows])
            if floor is None:
                floor = KEEP_GAP * np.maximum(np.min(gaps, axis=0), 0.0)
            advance = np.full(rows.size, np.inf)
            for gap, speed in zip(gaps, closing):
                closer = speed > 0.0
                advance[closer] = np.minimum(advance[closer],
                                             np.maximum(gap[closer] - floor[closer], 0.0)
                                             / speed[closer])
            t[rows] = np.minimum(1.0, t[rows] + advance)
            keep = (t[rows] < 1.0) & (advance > 1e-3 * (1.0 - t[rows]))
            rows, floor = rows[keep], floor[keep]
            if rows.size == 0:
                break
        return t
