"""Continuum membrane (linear triangles, plane stress): distcloth/physics/membrane_fem.py.

Finite differences: central differences with step EPS = 1e-6 on O(1)
coordinates have truncation error O(EPS^2 |f'''|) ~ 1e-12 and round-off
O(1e-16 |f| / EPS) ~ 1e-10 relative, so agreement to RTOL = 1e-6 relative
is a real check of exactness (a wrong term would be off by O(1)).
"""
import numpy as np

from fd import fd_jacobian as _fd_jacobian
import pytest
from scipy.linalg import sqrtm
from scipy.spatial import Delaunay

from distcloth.linalg.pattern import BlockPattern
from distcloth.physics.membrane_fem import (MembraneFEMTerm, orthotropic_plane_stress, uniaxial_modulus)

EPS = 1e-6
RTOL = 1e-6
MODELS = ["stvk", "corotated"]


def material():
    # E_weft nu_warp = 20 * 0.1 = 2 = nu_weft E_warp = 0.4 * 5 (symmetric C)
    return orthotropic_plane_stress(20.0, 5.0, 0.4, 0.1, 3.0)


def random_rotation(rng):
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q


def planar_mesh(rng, n=14):
    """Irregular Delaunay mesh of the unit square (2D coords, ccw triangles)."""
    P = np.vstack([[[0, 0], [1, 0], [0, 1], [1, 1]], rng.uniform(0.05, 0.95, (n - 4, 2))])
    tris = Delaunay(P).simplices.astype(np.int64)
    a, b, c = P[tris[:, 0]], P[tris[:, 1]], P[tris[:, 2]]
    cw = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]) < 0
    tris[cw] = tris[cw][:, [0, 2, 1]]
    return P, tris


def curved_rest(rng, n=14):
    """A non-flat rest shape: the planar mesh lifted onto a bump, random weft directions."""
    P, tris = planar_mesh(rng, n)
    X = np.column_stack([P, 0.3 * np.sin(3 * P[:, 0]) * np.cos(2 * P[:, 1])])
    weft = rng.normal(size=(len(tris), 3))
    return X, tris, weft


def dense_system(term, n_owned, n, tris, alpha=1.0):
    pattern = BlockPattern(n_owned, n, [tris])
    term.bind(pattern)
    data = pattern.new_values()
    term.add_to_system(data, alpha, 0.0)
    return pattern.local_matrix(data).toarray()


def fd_jacobian(fun, z):
    return _fd_jacobian(fun, z, EPS)


def force_fn(term, n):
    def f(x):
        out = np.zeros((n, 3))
        term.evaluate(x, None, out, False)
        return out
    return f


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("seed", [0, 1])
def test_forces_are_minus_energy_gradient_and_hessian_exact(model, seed):
    rng = np.random.default_rng(seed)
    X, tris, weft = curved_rest(rng)
    n = X.shape[0]
    # strongly deformed: elements stretched, compressed, sheared, rotated
    x = X @ random_rotation(rng).T + 0.15 * rng.normal(size=X.shape)
    weight = rng.uniform(0.3, 1.0, len(tris))
    term = MembraneFEMTerm(tris, X, weft, material(), model, weight, project=False)
    f = force_fn(term, n)(x)
    # forces carry no weight (owned rows are kept by the caller), energies do:
    # compare against the unweighted energy
    unweighted = MembraneFEMTerm(tris, X, weft, material(), model, np.ones(len(tris)))
    grad = fd_jacobian(lambda z: np.array([unweighted.energy(z)]), x)[0]
    assert np.abs(f.ravel() + grad).max() <= RTOL * np.abs(f).max()
    res = term.evaluate(x, None, np.zeros((n, 3)), True)
    assert res["elastic_energy"] == pytest.approx(term.energy(x), rel=1e-14)
    J = fd_jacobian(force_fn(term, n), x)
    A = dense_system(term, n, n, tris)                   # A = -df/dx = H
    assert np.abs(-A - J).max() <= RTOL * np.abs(J).max()
    # the stiffness product is the same derivative applied to a vector
    w = rng.normal(size=(n, 3))
    out = np.zeros((n, 3))
    term.stiffness_product(w, out)
    assert np.abs(out.ravel() - J @ w.ravel()).max() <= 10 * RTOL * np.abs(J).max() * np.abs(w).max()
    # ghost rows (last 3 vertices not owned) are skipped; owned rows unchanged
    Ag = dense_system(term, n - 3, n, tris)
    assert np.array_equal(Ag, A[: 3 * (n - 3)])


@pytest.mark.parametrize("model", MODELS)
def test_rigid_motion_gives_zero_force_and_energy(model):
    rng = np.random.default_rng(7)
    X, tris, weft = curved_rest(rng)
    term = MembraneFEMTerm(tris, X, weft, material(), model, np.ones(len(tris)))
    # force scale of a 1 % deformation, to judge "zero" by
    fscale = np.abs(force_fn(term, len(X))(X * 1.01)).max()
    for _ in range(3):
        x = X @ random_rotation(rng).T + rng.normal(size=3)
        f = force_fn(term, len(X))(x)
        # round-off: F is exact to ~1e-15, strains ~1e-15, vs 1e-2 strain for fscale
        assert np.abs(f).max() <= 1e-9 * fscale
        # energy ~ |C| strain^2 ~ 20 * (1e-15)^2: anything above 1e-20 is a real strain
        assert abs(term.energy(x)) <= 1e-20


@pytest.mark.parametrize("model", MODELS)
def test_projected_hessian_psd_and_exact_when_exact_is_psd(model):
    rng = np.random.default_rng(11)
    X, tris, weft = curved_rest(rng)
    n = len(X)
    args = (tris, X, weft, material(), model, np.ones(len(tris)))
    exact, proj = MembraneFEMTerm(*args, project=False), MembraneFEMTerm(*args, project=True)
    # compressed and sheared state: exact Hessian indefinite somewhere
    x = 0.8 * X + 0.1 * rng.normal(size=X.shape)
    for t in (exact, proj):
        t.evaluate(x, None, np.zeros((n, 3)), True)
    He, Hp = exact.element_hessians(), proj.element_hessians()
    scale = np.abs(He).max()
    assert np.linalg.eigvalsh(He).min() < -1e-3 * scale          # the premise
    # PSD up to the round-off of the eigen-reconstruction (~1e-15 relative) and the
    # 1e-10 |C| tolerance on the stress sign in the kernel's cheap PSD pre-test
    assert np.linalg.eigvalsh(Hp).min() >= -1e-9 * scale
    Ap = dense_system(proj, n, n, tris)
    assert np.allclose(Ap, Ap.T, rtol=0, atol=1e-13 * scale)
    assert np.linalg.eigvalsh(Ap).min() >= -1e-9 * scale
    # consistency: stiffness product uses the same projected matrix
    w = rng.normal(size=(n, 3))
    out = np.zeros((n, 3))
    proj.stiffness_product(w, out)
    assert np.allclose(out.ravel(), -Ap @ w.ravel(), rtol=0, atol=1e-12 * scale * np.abs(w).max())
    # uniform 10 % in-plane stretch (rest shape scaled about a point):
    # exact Hessian is PSD there, so the projection must leave it unchanged
    xs = 1.1 * X
    for t in (exact, proj):
        t.evaluate(xs, None, np.zeros((n, 3)), True)
    He, Hp = exact.element_hessians(), proj.element_hessians()
    scale = np.abs(He).max()
    assert np.linalg.eigvalsh(He).min() >= -1e-12 * scale        # the premise
    # 1e-10: elements with a zero eigenvalue go through eigh (round-off ~1e-15 relative
    # per element); positive definite ones pass through untouched
    assert np.abs(He - Hp).max() <= 1e-10 * scale


@pytest.mark.parametrize("model", MODELS)
def test_patch_test_homogeneous_strain(model):
    rng = np.random.default_rng(3)
    P, tris = planar_mesh(rng, n=30)
    R = random_rotation(rng)
    u3, v3 = R[:, 0], R[:, 1]                # rest plane spanned by u3 (weft), v3
    X = P[:, :1] * u3 + P[:, 1:] * v3 + rng.normal(size=3)
    C = material()
    term = MembraneFEMTerm(tris, X, np.tile(u3, (len(tris), 1)), C, model, np.ones(len(tris)))
    F0 = rng.normal(size=(3, 2)) * 0.3 + np.eye(3, 2)        # any full-rank 3x2 map
    x = P @ F0.T + rng.normal(size=3)
    M = F0.T @ F0
    if model == "stvk":
        E = 0.5 * (M - np.eye(2))
    else:
        E = np.real(sqrtm(M)) - np.eye(2)                     # small strain of the stretch
    e = np.array([E[0, 0], E[1, 1], 2 * E[0, 1]])
    expected = 0.5 * e @ C @ e * 1.0                          # area of the unit square
    # exact up to round-off: every element sees the same F0, energies sum
    assert term.energy(x) == pytest.approx(expected, rel=1e-12)
    # interior vertices are in equilibrium under a homogeneous stress
    f = force_fn(term, len(X))(x)
    interior = np.all((P > 1e-9) & (P < 1 - 1e-9), axis=1)
    assert np.abs(f[interior]).max() <= 1e-12 * np.abs(f).max()


def grid(nx, ny, Lx, Ly):
    gx, gy = np.meshgrid(np.linspace(0, Lx, nx + 1), np.linspace(0, Ly, ny + 1), indexing="ij")
    P = np.column_stack([gx.ravel(), gy.ravel()])
    idx = np.arange((nx + 1) * (ny + 1)).reshape(nx + 1, ny + 1)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    tris = np.vstack([np.column_stack([a, b, c]), np.column_stack([a, c, d])])
    return P, tris


def uniaxial_stress_ratio(model, weft, pull_axis, delta=1e-6):
    """Pull a free-edged rectangle along ``pull_axis``; return traction / strain.

    Left edge held at its rest coordinate along the pull, right edge displaced
    by delta * L, lateral motion free (one vertex pinned against translation),
    out-of-plane fixed; equilibrium by Newton with the exact Hessian."""
    L = np.array([2.0, 1.0])
    P, tris = grid(6, 4, *L)
    X = np.column_stack([P, np.zeros(len(P))])
    n = len(X)
    term = MembraneFEMTerm(tris, X, None if weft is None else np.tile(weft, (len(tris), 1)),
                           material(), model, np.ones(len(tris)), project=False)
    lo = np.isclose(P[:, pull_axis], 0.0)
    hi = np.isclose(P[:, pull_axis], L[pull_axis])
    fixed = np.zeros((n, 3), bool)
    fixed[:, 2] = True
    fixed[lo | hi, pull_axis] = True
    fixed[0, :] = True
    x = X.copy()
    x[hi, pull_axis] += delta * L[pull_axis]
    free = ~fixed.ravel()
    for _ in range(4):
        f = np.zeros((n, 3))
        term.evaluate(x, None, f, True)
        A = dense_system(term, n, n, tris)
        dx = np.linalg.solve(A[np.ix_(free, free)], f.ravel()[free])
        x.ravel()[free] += dx
    f = np.zeros((n, 3))
    term.evaluate(x, None, f, False)
    # equilibrium to round-off (~1e-15 N against edge forces ~1e-5 N): a residual
    # below 1e-6 of the edge forces changes the measured traction by < 1e-6
    assert np.abs(f.ravel()[free]).max() <= 1e-6 * np.abs(f[hi, pull_axis]).max()
    width = L[1 - pull_axis]
    traction = -f[hi, pull_axis].sum() / width      # N/m on the pulled edge
    return traction / delta


@pytest.mark.parametrize("model", MODELS)
def test_uniaxial_modulus_weft_and_warp(model):
    C = material()
    Eu, Ev = uniaxial_modulus(C, 0), uniaxial_modulus(C, 1)
    # orthotropic with nu_weft E_warp = nu_warp E_weft: uniaxial moduli are E_weft, E_warp
    assert Eu == pytest.approx(20.0, rel=1e-12) and Ev == pytest.approx(5.0, rel=1e-12)
    # delta = 1e-6: the response is linear up to O(delta) relative; Newton on the
    # exact Hessian converges to ~1e-10 of the forces, so 1e-4 is generous
    weft_x = uniaxial_stress_ratio(model, None, 0)                # weft = default global x
    assert weft_x == pytest.approx(Eu, rel=1e-4)
    warp_y = uniaxial_stress_ratio(model, None, 1)
    assert warp_y == pytest.approx(Ev, rel=1e-4)
    assert weft_x / warp_y == pytest.approx(Eu / Ev, rel=1e-4)
    # weft along y: pulling along x now meets the warp modulus
    assert uniaxial_stress_ratio(model, np.array([0.0, 1.0, 0.0]), 0) == pytest.approx(Ev, rel=1e-4)


def test_orthotropic_refusals_and_form():
    C = orthotropic_plane_stress(20.0, 5.0, 0.4, 0.1, 3.0)
    d = 1 - 0.04
    assert np.allclose(C, [[20 / d, 2 / d, 0], [2 / d, 5 / d, 0], [0, 0, 3.0]], rtol=1e-14)
    assert np.all(np.linalg.eigvalsh(C) > 0)
    with pytest.raises(ValueError, match="symmetric"):
        orthotropic_plane_stress(20.0, 5.0, 0.4, 0.2, 3.0)
    with pytest.raises(ValueError, match="< 1"):
        orthotropic_plane_stress(1.0, 1.0, 1.0, 1.0, 3.0)
    # within the relative tolerance 1e-9 is accepted
    orthotropic_plane_stress(20.0, 5.0, 0.4, 0.1 * (1 + 1e-12), 3.0)


def test_rest_frame_weft_projection_and_fallback():
    X = np.array([[0.0, 0, 0], [1, 0, 1], [0, 1, 0]])
    # weft given along the normal: falls back to the first edge
    n = np.cross(X[1] - X[0], X[2] - X[0])
    t = MembraneFEMTerm([[0, 1, 2]], X, n[None, :], material(), "stvk", [1.0])
    assert np.allclose(t.frame[0, 0], (X[1] - X[0]) / np.linalg.norm(X[1] - X[0]))
    # default global x projected into the plane
    t = MembraneFEMTerm([[0, 1, 2]], X, None, material(), "stvk", [1.0])
    assert np.allclose(t.frame[0, 0], [1, 0, 1] / np.sqrt(2))
    assert t.area[0] == pytest.approx(0.5 * np.linalg.norm(n))
    with pytest.raises(ValueError):
        MembraneFEMTerm([[0, 1, 2]], X, None, material(), "neo", [1.0])



def _linear_tables(C, compression):
    from distcloth.physics.membrane_fem import with_compression
    lin = [[[0.0, 0.0], [1.0, C[d, d]]] for d in range(3)]
    return [with_compression(lin[0], compression), with_compression(lin[1], compression), lin[2]]


def _one_triangle_stress(term, e_weft):
    """Weft direct stress (N/m) of a unit right triangle stretched along x to
    the Green strain e_weft, from the force on the free corner."""
    X = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    stretch = np.sqrt(1.0 + 2.0 * e_weft)
    x = X.copy()
    x[1, 0] = stretch
    f = np.zeros((3, 3))
    term.evaluate(x, None, f, False)
    # the first Piola stress P = F S: the corner force is P times the area-weighted
    # normal of its opposite edge, so along x: f = -stretch S_xx * (1/2) * 1
    return -f[1, 0] / (0.5 * stretch)


def test_compression_branch_scales_compressive_stiffness_only():
    C = orthotropic_plane_stress(20.0, 5.0, 0.0, 0.0, 3.0)   # no Poisson coupling: S_xx = C11 e
    X = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    tris = np.array([[0, 1, 2]])
    plain = MembraneFEMTerm(tris, X, None, C, "stvk", np.ones(1))
    soft = MembraneFEMTerm(tris, X, None, C, "stvk", np.ones(1), tables=_linear_tables(C, 0.1))
    for e in (0.02, 0.1):     # tension: untouched (the table is the linear law)
        assert _one_triangle_stress(soft, e) == pytest.approx(_one_triangle_stress(plain, e),
                                                              rel=1e-12)
        assert _one_triangle_stress(plain, e) == pytest.approx(20.0 * e, rel=1e-12)
    for e in (-0.01, -0.05):  # compression: a tenth of the stiffness
        assert _one_triangle_stress(soft, e) == pytest.approx(0.1 * 20.0 * e, rel=1e-12)


def test_compression_branch_forces_and_hessian_exact():
    # the strongly deformed random elements of the exactness test cross e = 0 in
    # both directions: the branch keeps the energy C1 and its Hessian exact
    rng = np.random.default_rng(3)
    X, tris, weft = curved_rest(rng)
    n = X.shape[0]
    x = X @ random_rotation(rng).T + 0.15 * rng.normal(size=X.shape)
    C = material()
    term = MembraneFEMTerm(tris, X, weft, C, "stvk", np.ones(len(tris)), project=False,
                           tables=_linear_tables(C, 0.5))
    f = force_fn(term, n)(x)
    grad = fd_jacobian(lambda z: np.array([term.energy(z)]), x)[0]
    assert np.abs(f.ravel() + grad).max() <= RTOL * np.abs(f).max()
    J = fd_jacobian(force_fn(term, n), x)
    term.evaluate(x, None, np.zeros((n, 3)), True)
    A = dense_system(term, n, n, tris)
    # the branch switch at e = 0 is a kink of the second derivative; no element
    # strain of this state lies within the differencing step of it
    assert np.abs(-A - J).max() <= RTOL * np.abs(J).max()


@pytest.mark.parametrize("squeeze, noise", [(0.8, 0.1), (0.995, 0.002)])
@pytest.mark.parametrize("model", MODELS)
def test_projection_is_the_eigenvalue_clamp(model, squeeze, noise):
    """The kernel's split 4 + 2 projection gives LAPACK's clamp of every
    element's 6x6 Hessian, on strongly compressed, wrinkled triangles (both
    blocks indefinite: two Jacobi eigensolves) and on mildly compressed ones
    (the in-plane block definite: only the normal block's negative part
    taken off)."""
    rng = np.random.default_rng(5)
    X, tris, weft = curved_rest(rng)
    args = (tris, X, weft, material(), model, np.ones(len(tris)))
    exact, proj = MembraneFEMTerm(*args, project=False), MembraneFEMTerm(*args, project=True)
    x = squeeze * X + noise * rng.normal(size=X.shape)
    for t in (exact, proj):
        t.evaluate(x, None, np.zeros((len(X), 3)), True)
    H = 0.5 * (exact.hr + exact.hr.transpose(0, 2, 1))
    w, V = np.linalg.eigh(H)
    own = np.abs(H).max(axis=(1, 2))
    assert (w.min(axis=1) < -1e-3 * own).sum() > len(H) // 4     # the premise: many to clamp
    clamp = np.einsum("eik,ek,ejk->eij", V, np.maximum(w, 0.0), V)
    # 1e-9: the kernel keeps elements its PSD pre-test admits with eigenvalues
    # down to -1e-10 |C| A; the eigensolvers' own round-off is ~1e-15
    assert np.all(np.abs(proj.hr - clamp).max(axis=(1, 2)) <= 1e-9 * own)


def test_a_repeated_evaluation_reuses_the_last_one_only_at_the_same_x():
    rng = np.random.default_rng(6)
    X, tris, weft = curved_rest(rng)
    term = MembraneFEMTerm(tris, X, weft, material(), "stvk", np.ones(len(tris)))
    fresh = MembraneFEMTerm(tris, X, weft, material(), "stvk", np.ones(len(tris)))
    x = 0.9 * X + 0.05 * rng.normal(size=X.shape)
    f1, f2 = np.zeros_like(x), np.zeros_like(x)
    term.evaluate(x, None, f1, True)
    term.evaluate(x, None, f2, True)                  # served again, added again
    assert np.array_equal(f1, f2)
    assert term.energy(x) == fresh.energy(x)
    x[3] += 1e-3                                      # moved in place: a new evaluation
    f3, f4 = np.zeros_like(x), np.zeros_like(x)
    term.evaluate(x, None, f3, True)
    fresh.evaluate(x, None, f4, True)
    assert np.array_equal(f3, f4) and np.array_equal(term.hr, fresh.hr)
    assert term.max_strain(x) == fresh.max_strain(x)
