"""Cloth-body contact kernels: arrays in, arrays out (no MPI, no PETSc).

The contact module (``collision/contact.py``) queries the colliders and hands
their phi / normal / velocity arrays to these functions.  Why each choice:

**Unilateral contact: who is a contact.**  d = cloth thickness + collider
thickness is the offset the cloth keeps from a body.  A vertex is predicted
to end the step at ``phi + h v_free`` with ``v_free = (v - v_b).n + h a.n``
its relative normal velocity after a step of free flight (``a``: the
vertex's acceleration in the last step, tension and support included;
gravity before the first).  It becomes a contact when

* the prediction falls inside d (it *lands*): its normal velocity is
  prescribed as ``v_b.n + (d - phi)/h``, so it ends the step exactly at
  phi = d (to first order in the curvature); a vertex already inside is
  pushed out over one step; or
* the last step's contacts held it against the body, or the fail-safe put
  it back, and it ended within 1.5 d, and the prediction stays within that
  band (it is *kept*): its normal velocity is
  held at ``v_b.n + min(v_free, 0)``, its free-flight approach or rest,
  never a pull toward the body.

No other vertex is constrained, however close: a cloth hovering above a
body stays where it is.  After the solve the contact model (``revise``)
releases every contact whose constraint impulse turned adhesive (the
constraint held the vertex against a pull away from the body) and makes a
contact of every free vertex that ended deeper than 5 % of d inside, and the
step is solved again (at most four passes, contact.py): what is left is a set in which
every constraint pushes.  A landing constraint slows an approaching vertex
(negative work), a kept one does no work at rest; positive work is done only
in pushing a penetrating vertex out, by at most its depth, and the works are
in the step's diagnostics (``contact_work``).  With several colliders the
*deepest* (smallest phi - d) wins: one constraint per vertex keeps S a
projection; a vertex wedged between two bodies is held by the deeper one and
put back by the position fail-safe, which visits every collider.

**Constraint in the implicit solve (Baraff and Witkin 1998 §5).**  A contact
is S = I - n n^T and a prescribed normal velocity: the tangential directions
stay free, the solve sees the contact (no stiff penalty, no step-size
limit), and the matrix pattern never changes.  Pins and sliding pins win
over contacts.  The constraint's impulse is what the filtered rows of the
solve leave out (``linalg/assembly.constraint_impulses``).

**Coulomb friction after the solve (Bridson et al. 2002 §7.3)**, for the
explicit schemes (implicit ones take friction into the solve,
``physics/contact_friction.py``).  The normal velocity change the contact
produced is estimated as ``dv_n = (v_new - v_free).n`` with
``v_free = v + h f/m`` and f the forces at the start of the step; the
tangential velocity relative to the body is then reduced by ``mu dv_n`` and
clamped at zero (``collision/friction.py``), so ``|v_t| <= mu dv_n`` is
static friction.  On an inclined plane this gives exactly
``a = g (sin t - mu cos t)`` per step.  Positions follow the velocity
change through the integrator's own dx1/dv1 (the step result's
``position_gain``).

**Position fail-safe.**  After the response, any vertex still at phi < d
(curvature, a missed contact, a vertex released as adhesive) is moved
along n to phi = d and its inward relative normal velocity removed.  It
only corrects residuals: the ``max_penetration`` diagnostic is measured
*before* it, so it reports what the solve achieved.

Contacts are sorted by local vertex index (collider index breaks ties in
``deepest``), so the result does not depend on the order of the colliders'
queries; every rank computes the same contact for a shared vertex from the
same ghost-updated positions.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .friction import coulomb_fractions


@dataclass
class Contacts:
    """One contact per constrained local vertex (sorted by vertex)."""
    index: np.ndarray       # (m,) local vertex indices, sorted
    collider: np.ndarray    # (m,) collider index
    normal: np.ndarray      # (m, 3) outward unit normals of the body
    velocity: np.ndarray    # (m, 3) body surface velocity
    phi: np.ndarray         # (m,) signed distance at the start of the step
    offset: np.ndarray      # (m,) d: cloth + collider thickness
    friction: np.ndarray    # (m,) Coulomb mu
    target: np.ndarray      # (m,) prescribed normal velocity at the end of the step

    @staticmethod
    def none() -> "Contacts":
        z = np.zeros(0)
        return Contacts(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 3)),
                        np.zeros((0, 3)), z, z.copy(), z.copy(), z.copy())


def detect(phis, normals, velocities, v, offsets, frictions, h, accel, band, exclude,
           persistent=None, forced=None) -> Contacts:
    """Contacts of the vertices against every collider (the rule: module docstring).

    ``phis`` (k, n), ``normals`` and ``velocities`` (k, n, 3): the colliders'
    answers for the n vertices at the start of the step; ``v`` (n, 3) the
    cloth velocities; ``offsets`` (k, n) d per collider and vertex;
    ``frictions`` (k,); ``accel`` (n, 3) or (3,): the acceleration of free flight;
    ``exclude`` (n,) bool: vertices that never get a contact (pins, contacts
    released in this attempt); ``persistent`` (k, n) bool or None: what
    touched each body at the end of the last step, kept (without pulling)
    while the predicted end stays within ``band`` (k, n) above d; ``forced`` (k, n) bool: contacts an earlier solve
    of the attempt missed, which land at d whatever the prediction."""
    k, n = phis.shape
    if k == 0 or n == 0:
        return Contacts.none()
    vrel_n = np.einsum("kni,kni->kn", v[None] - velocities, normals)
    # the normal velocity relative to the body at the end of a step of free flight
    accel = np.broadcast_to(np.asarray(accel, dtype=np.float64), v.shape)
    v_free = vrel_n + h * np.einsum("kni,ni->kn", normals, accel)
    predicted = phis + h * v_free
    landing = predicted < offsets
    if forced is not None:
        landing = landing | forced
    kept = (predicted < offsets + band) & persistent if persistent is not None else False
    touching = (landing | kept) & ~exclude[None]
    # deepest collider per vertex: smallest phi - d among those touching
    depth = np.where(touching, phis - offsets, np.inf)
    best = np.argmin(depth, axis=0)                      # ties: lowest collider index
    hit = np.isfinite(depth[best, np.arange(n)])
    idx = np.nonzero(hit)[0]
    c = best[idx]
    normal = normals[c, idx]
    vb = velocities[c, idx]
    phi = phis[c, idx]
    d = offsets[c, idx]
    # land exactly at d, or (a kept contact) keep at most the free-flight approach
    relative = np.where(landing[c, idx], (d - phi) / h, np.minimum(v_free[c, idx], 0.0))
    target = np.einsum("ni,ni->n", vb, normal) + relative
    return Contacts(idx.astype(np.int64), c.astype(np.int64), normal, vb, phi, d,
                    np.asarray(frictions, dtype=np.float64)[c], target)


def contact_constraint(contacts: Contacts, v) -> tuple[np.ndarray, np.ndarray]:
    """(S, z) of the contacts: S = I - n n^T, z = n (target - v.n)."""
    n = contacts.normal
    S = np.eye(3)[None] - np.einsum("ni,nj->nij", n, n)
    vn = np.einsum("ni,ni->n", v[contacts.index], n)
    z = n * (contacts.target - vn)[:, None]
    return S, z


def normal_impulse(v_new, v_free, normal) -> np.ndarray:
    """Normal velocity change the contact produced: (v_new - v_free).n
    (positive pushes out; negative is adhesive)."""
    return np.einsum("ni,ni->n", v_new - v_free, normal)


def friction(v_new, vb, normal, mu, dvn) -> np.ndarray:
    """Velocities after Coulomb friction: the tangential velocity relative to
    the body reduced by mu * max(dv_n, 0), clamped at zero (static friction)."""
    vrel = v_new - vb
    vt = vrel - np.einsum("ni,ni->n", vrel, normal)[:, None] * normal
    speed = np.linalg.norm(vt, axis=1)
    removed = coulomb_fractions(speed, mu * np.maximum(dvn, 0.0))
    return v_new - removed[:, None] * vt


def project(x, v, phi, normal, vb, d) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Fail-safe: vertices with phi < d moved along n to phi = d and their
    inward relative normal velocity removed.  Returns (x, v, moved mask)."""
    inside = d - phi > 1e-12      # round-off of a vertex landed exactly on phi = d is not a miss
    x = x.copy()
    v = v.copy()
    if np.any(inside):
        n = normal[inside]
        x[inside] += (d[inside] - phi[inside])[:, None] * n
        vn = np.einsum("ni,ni->n", v[inside] - vb[inside], n)
        v[inside] -= np.minimum(vn, 0.0)[:, None] * n
    return x, v, inside


def coulomb_split(f, normal):
    """(f.n, the tangential part of f, its length) per row: the normal and
    tangential parts of forces ``f`` (n, 3) at a body with outward ``normal``."""
    fn = np.einsum("ij,ij->i", f, normal)
    ft = f - fn[:, None] * normal
    return fn, ft, np.sqrt(np.einsum("ij,ij->i", ft, ft))


def unbalanced_force(f, touching, normal, mu):
    """(n,) the part of the forces ``f`` (n, 3) that contacts cannot balance:
    the residual of the Coulomb contact conditions (Wriggers 2006 ch. 5, the
    friction cone |f_t| <= mu f_N with f_N >= 0 the body's reaction).  On a
    ``touching`` vertex with outward body ``normal`` and Coulomb ``mu`` the
    body supports any push into it (f.n <= 0) and static friction any
    tangential force up to mu |f.n|, so what is left is the excess over the
    friction cone; a pull away from the body and a free vertex keep |f|."""
    fn, _, ft = coulomb_split(f, normal)
    mag = np.sqrt(np.einsum("ij,ij->i", f, f))
    pressed = touching & (fn <= 0.0)
    return np.where(pressed, np.maximum(ft - mu * np.abs(fn), 0.0), mag)


def coulomb_active_set(f, touching, normal, mu, slack=0.0):
    """The contacts of a static (Newton) step under the forces ``f`` (n, 3):
    (stick, slide, friction).  A touching vertex pressed into the body sticks
    when its tangential force is inside the friction cone (widened by
    ``slack``, a force per vertex: at impending slip within a tolerance is at
    rest); outside it slides
    against the cone's limit force ``friction`` = -mu |f.n| t (t the unit
    tangential force; zero elsewhere), so what moves it is the excess over
    the cone that ``unbalanced_force`` counts (Wriggers 2006 ch. 5: the
    return mapping onto the Coulomb cone).  A pull away from the body frees it."""
    fn, ft_vec, ft = coulomb_split(f, normal)
    pressed = touching & (fn <= 0.0)
    limit = mu * np.abs(fn)
    stick = pressed & (ft <= limit + slack)
    slide = pressed & ~stick
    scale = np.where(slide, limit / np.maximum(ft, 1e-300), 0.0)
    return stick, slide, -scale[:, None] * ft_vec
