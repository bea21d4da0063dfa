"""The barrier Newton's conservative bound on a move
(BarrierContactTerm.step_bound, physics/contact_barrier.py):

* it is conservative: along every random move, sampled finely up to the
  fraction it allows, each vertex keeps KEEP_GAP of its gap to every body
  (the analytic shapes, bounded by their tangents, and a body bounded only
  by the distance field's Lipschitz constant);
* head on against a plane it is exact: the fraction that leaves KEEP_GAP
  of the gap;
* a vertex sliding along a convex body, however close, is never held back;
  the Lipschitz bound cuts the same move to a few gaps' length.
"""
import numpy as np
import pytest

from distcloth.collision.colliders import AnalyticCollider, Box, Capsule, Plane, Sphere
from distcloth.physics.contact_barrier import KEEP_GAP, BarrierContactTerm

SHAPES = {
    "plane": Plane((0.0, 0.0, 1.0), 0.0),
    "sphere": Sphere((0.0, 0.0, 0.3), 0.25),
    "capsule": Capsule((-0.2, 0.0, 0.3), (0.2, 0.1, 0.3), 0.1),
    "box": Box((0.0, 0.0, 0.3), (0.2, 0.15, 0.1)),
}
OFFSET = 0.003      # the contact distance d (cloth + collider thickness)


def _term(shapes, n, convex):
    bodies = [AnalyticCollider(s) for s in shapes]
    queries = [lambda x, t, maxd, b=b: b.query(x, t) for b in bodies]
    return BarrierContactTerm(queries, np.full((len(bodies), n), OFFSET), [0.0] * len(bodies),
                              np.zeros(n, dtype=bool), np.full(n, 1e-4), n, OFFSET / 2, 10.0,
                              9.81, 1e-3, convex=[convex] * len(bodies)), bodies


def _gaps(bodies, x):
    return np.min([b.query(x)[0] - OFFSET for b in bodies], axis=0)


def _outside(bodies, rng, n):
    """n points at gaps between 1e-5 and 0.05 m from the bodies."""
    x = rng.uniform([-0.4, -0.4, 0.0], [0.4, 0.4, 0.6], size=(8 * n, 3))
    g = _gaps(bodies, x)
    keep = (g > 1e-5) & (g < 0.05)
    assert keep.sum() >= n
    return x[keep][:n]


@pytest.mark.parametrize("convex", [True, False])
def test_the_bound_keeps_a_tenth_of_every_gap(convex):
    rng = np.random.default_rng(3)
    term, bodies = _term(list(SHAPES.values()), 400, convex)
    x = _outside(bodies, rng, 400)
    # moves of 0.1 mm to 0.2 m, many of them into the bodies
    dx = rng.normal(size=x.shape) * rng.uniform(1e-4, 0.2, size=(x.shape[0], 1))
    t = term.step_bound(x, dx)
    floor = KEEP_GAP * _gaps(bodies, x)
    for tau in np.linspace(0.0, 1.0, 2001):
        along = _gaps(bodies, x + (tau * t)[:, None] * dx)
        # both lower bounds hold along the whole segment (the analytic
        # distances are exact), so every sample keeps the floor, up to round-off
        assert np.all(along >= floor * (1 - 1e-9) - 1e-12), tau
    assert np.all((t >= 0.0) & (t <= 1.0))
    # some moves were cut, some were free
    assert np.any(t < 0.5) and np.any(t == 1.0)


def test_head_on_against_a_plane_the_bound_is_exact():
    term, _ = _term([SHAPES["plane"]], 3, convex=True)
    s = np.array([1e-4, 1e-3, 1e-2])
    x = np.column_stack([np.zeros(3), np.zeros(3), OFFSET + s])
    dx = np.tile([0.0, 0.0, -0.05], (3, 1))
    t = term.step_bound(x, dx)
    np.testing.assert_allclose(t, (1 - KEEP_GAP) * s / 0.05, rtol=1e-12)


def test_sliding_along_a_convex_body_is_never_held_back():
    n = 50
    x = np.column_stack([np.linspace(-0.2, 0.2, n), np.zeros(n), np.full(n, OFFSET + 1e-5)])
    dx = np.tile([0.03, 0.02, 0.0], (n, 1))         # 36 mm along the floor at 10 um
    convex, _ = _term([SHAPES["plane"]], n, convex=True)
    np.testing.assert_array_equal(convex.step_bound(x, dx), 1.0)
    # moving away is free too; a body only known to be 1-Lipschitz allows
    # at most its iterations' (12) worth of 0.9 of the gap
    np.testing.assert_array_equal(convex.step_bound(x, dx + [0.0, 0.0, 0.01]), 1.0)
    lipschitz, _ = _term([SHAPES["plane"]], n, convex=False)
    t = lipschitz.step_bound(x, dx)
    assert np.all(t <= 12 * (1 - KEEP_GAP) * 1e-5 / np.linalg.norm(dx[0]) * (1 + 1e-9))
    # over the sphere's top, along its tangent plane: the gap only grows
    top = np.array([[0.0, 0.0, 0.55 + OFFSET + 1e-5]])
    sphere, _ = _term([SHAPES["sphere"]], 1, convex=True)
    assert sphere.step_bound(top, np.array([[0.05, 0.0, 0.0]]))[0] == 1.0
