"""Coulomb friction of body contacts inside the implicit solve.

Friction applied after the solve (clamping each contact vertex's tangential
velocity by mu times its normal velocity change) moves a vertex the solve
had moved with its neighbours; a vertex held back after its neighbours moved
as if it slid stretches the cloth, and nothing removes that energy. The
stability suite's pinch gained 0.3 to 1.2 S that way once its spheres
stopped, the cloth resting on the torso crept up by 0.1 S, and at the floor
the ribbon's front triangles were stretched tenfold (docs/collisions.md).

Here friction is a velocity-dependent force of the step, per contact vertex,

    f = -c P (v - u),   P = I - n n^T,   c >= 0,

with u the body's surface velocity, so the solve moves the contact vertex and
its neighbours together and backward Euler, BDF-2 (any scheme that takes a
damping force implicitly) can only lose energy to it.  c is fixed for the
step from the start state (a lagged, regularised Coulomb law; Baraff and
Witkin 1998 §5 treat stuck contacts as constraints, this is its soft form):

    v*   = v - u + h f_other / m          free relative velocity (f_other: all other forces)
    N    = max(0, -n . f_other) + m max(0, -n . (v - u)) / h     pressing force + approach
    s    = |P v*| - mu N h / m           tangential speed left after a full Coulomb impulse
    c    = min(mu N, m |P v*| / h) / max(s, V_STICK)
    c   <= mu N / max(|P (v - u)| - mu N h / m, V_STICK)

For one vertex alone this is exact Coulomb friction: sliding (s > 0), the
implicit step gives v_t = v*_t (1 - mu N h / (m |v*_t|)), the speed lost to a
kinetic friction impulse mu N h; stuck (s <= 0), the friction impulse is the
one that stops v*_t (at most mu N h, inside the Coulomb cone) and the vertex
creeps at most V_STICK.  The bound m |P v*| / h is what stopping needs.

The second bound is what a lone vertex sliding at its start speed would
get.  Where cloth wraps a convex edge, the bending and membrane forces on a
vertex at the kink nearly cancel its velocity in the explicit estimate v*
(|P v*| = 0.02 m/s for |v_t| = 0.15 m/s), so without it the vertex is
classed as held while the implicit solve moves it on with the strip: a
friction force of 1500 mu N, and a strip sliding over a box edge lost up to
a quarter of its speed in a step (docs/collisions.md, "Friction at a convex
edge").

Bounded coefficients: c enters the matrix as h c P on the vertex's diagonal
block.  With mu N / V_STICK alone, a stuck vertex pressed hard (an impact's
approach impulse, a stretched cloth pulled over the shoulders) reached
h c / m = 5e5 on the torso scene, and v* itself is inflated there: h f / m of
a stiff, sharply bent patch is an explicit estimate (10-20 m/s) of a motion
the implicit solve holds back.  Such rows make the system needlessly badly
conditioned (the linear solve of an earlier contact rule ran out of CG
iterations on that scene).  So h c / m <= DAMPING_MAX: a stuck vertex keeps
at most 1 / DAMPING_MAX of its free slip per step (1e-4 of a 1 m/s slip),
and capping c only weakens friction, so the force stays inside the Coulomb
cone and passive.

The normal force does not count the contact's position correction
(d - phi) / h: inflated by it, friction held vertices at convex edges.
"""
from __future__ import annotations

import numpy as np

from .base import ForceTerm

# m/s: the creep speed of a stuck contact (a 0.1 mm drift over a second);
# the tangential diagonal then grows by mu g h / V_STICK (about 250 at
# mu = 0.5, h = 5 ms), which only helps CG's diagonal dominance
V_STICK = 1.0e-4
DAMPING_MAX = 1.0e4   # largest h c / m: friction damping relative to the vertex's mass term


class ContactFrictionTerm(ForceTerm):
    name = "force:friction"

    def __init__(self, mass, n_owned):
        self.mass = np.asarray(mass, dtype=np.float64)
        self.n_owned = int(n_owned)
        self.diag_slots = None
        self.begin_step(None, 1.0)

    def bind(self, pattern):
        self.diag_slots = pattern.diag_slots

    def begin_step(self, contacts, h, use=None):
        """The attempt's contacts (``use``: mask of those this term handles);
        the coefficients follow at the first evaluation (the start state)."""
        self.h = float(h)
        self.index = np.zeros(0, dtype=np.int64)
        self.c = None
        if contacts is None or contacts.index.size == 0:
            return
        keep = (contacts.index < self.n_owned) & (contacts.friction > 0.0)
        if use is not None:
            keep &= use
        self.index = contacts.index[keep]
        self.normal = contacts.normal[keep]
        self.u = contacts.velocity[keep]
        self.mu = contacts.friction[keep]
        self.P = np.eye(3)[None] - np.einsum("ni,nj->nij", self.normal, self.normal)

    def evaluate(self, x, v, force, want_jac):
        idx = self.index
        if idx.size == 0:
            return
        if self.c is None:       # the step's first evaluation: force holds every other term
            self.c = self._coefficients(v[idx] - self.u, force[idx], self.mass[idx])
        vt = np.einsum("nij,nj->ni", self.P, v[idx] - self.u)
        np.subtract.at(force, idx, self.c[:, None] * vt)

    def _coefficients(self, vrel, f_other, m):
        n, h, mu = self.normal, self.h, self.mu
        pressing = np.maximum(0.0, -np.einsum("ni,ni->n", n, f_other))
        approach = m * np.maximum(0.0, -np.einsum("ni,ni->n", n, vrel)) / h
        N = pressing + approach
        vstar = vrel + h * f_other / m[:, None]
        speed = np.linalg.norm(np.einsum("nij,nj->ni", self.P, vstar), axis=1)
        slide = speed - mu * N * h / m
        c = np.minimum(mu * N, m * speed / h) / np.maximum(slide, V_STICK)
        # a vertex already sliding at its start speed gets no more than a
        # lone vertex sliding at that speed: at a convex kink the explicit
        # v* nearly vanishes while the solve moves the vertex on with the cloth
        start = np.linalg.norm(np.einsum("nij,nj->ni", self.P, vrel), axis=1)
        c = np.minimum(c, mu * N / np.maximum(start - mu * N * h / m, V_STICK))
        return np.minimum(c, DAMPING_MAX * m / h)

    def force_at(self, v_rows):
        """The friction force of this step's contacts at their velocities ``v_rows``."""
        return -self.c[:, None] * np.einsum("nij,nj->ni", self.P, v_rows - self.u)

    def add_to_system(self, data, alpha, beta):
        if self.index.size == 0 or self.c is None:
            return
        np.add.at(data, self.diag_slots[self.index], beta * self.c[:, None, None] * self.P)
