"""Every force and Jacobian against finite differences on random deformed states.

Central differences with step eps have truncation error O(eps^2 |f'''|) and
round-off O(1e-16 |f| / eps); with eps = 1e-6 on O(1) coordinates both are
below 1e-8 relative, so 1e-6 relative agreement is a real check.
"""
import numpy as np

from fd import fd_jacobian as _fd_jacobian
import pytest

from distcloth.linalg.pattern import BlockPattern
from distcloth.physics.terms import DragTerm, GravityTerm, SpringDampingTerm, SpringTerm

EPS = 1e-6
RTOL = 1e-6


def random_springs(rng, n=12, ns=40):
    springs = np.array([rng.choice(n, 2, replace=False) for _ in range(ns)])
    x_rest = rng.normal(size=(n, 3))
    rest = np.linalg.norm(x_rest[springs[:, 0]] - x_rest[springs[:, 1]], axis=1)
    # deform strongly: some springs stretched, some compressed
    x = x_rest + 0.3 * rng.normal(size=(n, 3))
    v = rng.normal(size=(n, 3))
    k = rng.uniform(1.0, 50.0, ns)
    c = rng.uniform(0.1, 2.0, ns)
    return springs, rest, k, c, x, v


def dense_system(term, n, springs, alpha, beta):
    pattern = BlockPattern(n, n, [springs])
    term.bind(pattern)
    data = pattern.new_values()
    term.add_to_system(data, alpha, beta)
    return pattern.local_matrix(data).toarray()


def fd_jacobian(fun, z):
    return _fd_jacobian(fun, z, EPS)


def spring_force(term, n):
    def f(x, v=None):
        out = np.zeros((n, 3))
        term.evaluate(x, np.zeros((n, 3)) if v is None else v, out, False)
        return out
    return f


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_spring_jacobian_exact(seed):
    rng = np.random.default_rng(seed)
    springs, rest, k, c, x, v = random_springs(rng)
    n = x.shape[0]
    term = SpringTerm("force:membrane", springs, rest, k, np.ones(len(k)), np.ones(len(k), bool),
                      clamp=False)
    f = spring_force(term, n)
    term.evaluate(x, v, np.zeros((n, 3)), True)
    A = dense_system(term, n, springs, alpha=1.0, beta=0.0)      # A = -df/dx
    J = fd_jacobian(f, x)
    assert np.abs(-A - J).max() <= RTOL * np.abs(J).max()
    # the stiffness product is the same derivative applied to a vector
    w = rng.normal(size=(n, 3))
    out = np.zeros((n, 3))
    term.stiffness_product(w, out)
    assert np.allclose(out.ravel(), J @ w.ravel(), rtol=0, atol=RTOL * np.abs(J).max() * 10)


def test_spring_force_is_minus_energy_gradient():
    rng = np.random.default_rng(3)
    springs, rest, k, c, x, v = random_springs(rng)
    n = x.shape[0]
    term = SpringTerm("force:membrane", springs, rest, k, np.ones(len(k)), np.ones(len(k), bool))
    grad = fd_jacobian(lambda z: np.array([term.energy(z)]), x)[0]
    f = spring_force(term, n)(x).ravel()
    assert np.abs(f + grad).max() <= RTOL * np.abs(f).max()


def test_clamped_hessian_is_exact_when_stretched_and_psd_always():
    rng = np.random.default_rng(4)
    springs, rest, k, c, x, v = random_springs(rng)
    n = x.shape[0]
    clamped = SpringTerm("m", springs, rest, k, np.ones(len(k)), np.ones(len(k), bool), clamp=True)
    clamped.evaluate(x, v, np.zeros((n, 3)), True)
    A = dense_system(clamped, n, springs, 1.0, 0.0)
    # positive semidefinite even with compressed springs present
    assert np.linalg.eigvalsh(0.5 * (A + A.T)).min() > -1e-10 * np.abs(A).max()
    assert np.allclose(A, A.T, atol=1e-12 * np.abs(A).max())
    # all springs stretched by 10 %: clamping changes nothing
    xs = x.copy()
    rest_s = np.linalg.norm(xs[springs[:, 0]] - xs[springs[:, 1]], axis=1) / 1.1
    exact = SpringTerm("m", springs, rest_s, k, np.ones(len(k)), np.ones(len(k), bool), clamp=False)
    clamp2 = SpringTerm("m", springs, rest_s, k, np.ones(len(k)), np.ones(len(k), bool), clamp=True)
    for t in (exact, clamp2):
        t.evaluate(xs, v, np.zeros((n, 3)), True)
    assert np.allclose(dense_system(exact, n, springs, 1, 0), dense_system(clamp2, n, springs, 1, 0))


def test_damping_velocity_jacobian_exact():
    rng = np.random.default_rng(5)
    springs, rest, k, c, x, v = random_springs(rng)
    n = x.shape[0]
    term = SpringDampingTerm(springs, rest, c)

    def f_of_v(vv):
        out = np.zeros((n, 3))
        term.evaluate(x, vv, out, False)
        return out

    term.evaluate(x, v, np.zeros((n, 3)), True)
    A = dense_system(term, n, springs, alpha=0.0, beta=1.0)      # A = -df/dv
    J = fd_jacobian(f_of_v, v)
    assert np.abs(-A - J).max() <= RTOL * np.abs(J).max()
    # damping removes energy: v . f_damp <= 0
    assert np.sum(v * f_of_v(v)) <= 0.0


def test_drag_and_gravity():
    rng = np.random.default_rng(6)
    n = 7
    area = rng.uniform(0.1, 1.0, n)
    mass = rng.uniform(0.1, 1.0, n)
    x, v = rng.normal(size=(n, 3)), rng.normal(size=(n, 3))
    drag = DragTerm(area, 0.7, n)
    springs = np.array([[0, 1]])
    pattern = BlockPattern(n, n, [springs])
    drag.bind(pattern)
    data = pattern.new_values()
    drag.add_to_system(data, 0.0, 1.0)

    def f_of_v(vv):
        out = np.zeros((n, 3))
        drag.evaluate(x, vv, out, False)
        return out

    J = fd_jacobian(f_of_v, v)
    assert np.abs(-pattern.local_matrix(data).toarray() - J).max() <= RTOL * np.abs(J).max()
    g = np.array([0.0, 0.0, -9.81])
    grav = GravityTerm(mass, g, np.ones(n))
    out = np.zeros((n, 3))
    grav.evaluate(x, v, out, False)
    assert np.allclose(out, mass[:, None] * g)
    grad = fd_jacobian(lambda z: np.array([grav.energy(z)]), x)[0]
    assert np.allclose(-grad, out.ravel(), rtol=RTOL, atol=1e-9)
