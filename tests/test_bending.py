"""Hinge bending (EG07 tutorial, Part 1 §4.3): topology, invariances, derivatives, calibration.

Finite differences: central differences with step EPS = 1e-6 on O(1)
coordinates have truncation error O(EPS^2 |f'''|) ~ 1e-12 and round-off
O(1e-16 |f| / EPS) ~ 1e-10 relative, so RTOL = 1e-6 relative to the largest
entry is a real check (a wrong term is O(1) relative).
"""
import numpy as np
import pytest

from distcloth.linalg.pattern import BlockPattern
from distcloth.physics.bending import (C_HINGE, DihedralBendingTerm, IsometricBendingTerm,
                                       hinge_angles, hinges)

EPS = 1e-6
RTOL = 1e-6


def grid_mesh(nx, ny, width=1.0, height=1.0, kind="split"):
    """Flat (nx+1) x (ny+1) vertex sheet in the z = 0 plane, normals +z.

    kind="split": squares cut along one diagonal; kind="equi": rows shifted
    by half a cell (equilateral triangles when height/ny = sqrt(3)/2 width/nx)."""
    u, v = np.meshgrid(np.linspace(0, width, nx + 1), np.linspace(0, height, ny + 1),
                       indexing="ij")
    if kind == "equi":
        u = u + 0.5 * (width / nx) * (np.arange(ny + 1)[None, :] % 2)
    x = np.stack([u.ravel(), v.ravel(), np.zeros(u.size)], axis=1)
    tris = []
    for i in range(nx):
        for j in range(ny):
            a, b = i * (ny + 1) + j, (i + 1) * (ny + 1) + j
            c, d = b + 1, a + 1
            if kind == "equi" and j % 2 == 0:
                tris += [[a, b, d], [b, c, d]]
            else:
                tris += [[a, b, c], [a, c, d]]
    return x, np.array(tris, dtype=np.int64)


def roll(x, radius, axis=0):
    """Map the flat sheet isometrically onto a cylinder of the given radius
    whose axis is perpendicular to coordinate ``axis`` and lies above the sheet
    (on the +z side, where the normals point) when radius > 0."""
    y = x.copy()
    s = x[:, axis]
    y[:, axis] = radius * np.sin(s / radius)
    y[:, 2] = radius * (1.0 - np.cos(s / radius))
    return y


def random_rotation(rng):
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


def make_terms(hg, rest, B=1.0, weight=1.0):
    return (IsometricBendingTerm(hg, rest, B, weight), DihedralBendingTerm(hg, rest, B, weight))


def forces(term, x):
    f = np.zeros_like(x)
    info = term.evaluate(x, np.zeros_like(x), f, True)
    return f, info


def fd_gradient(fun, x):
    g = np.zeros_like(x)
    z = x.copy()
    flat, gf = z.reshape(-1), g.reshape(-1)
    for q in range(flat.size):
        old = flat[q]
        flat[q] = old + EPS
        ep = fun(z)
        flat[q] = old - EPS
        em = fun(z)
        flat[q] = old
        gf[q] = (ep - em) / (2 * EPS)
    return g


def fd_jacobian(term, x):
    n = x.shape[0]
    J = np.zeros((3 * n, 3 * n))
    z = x.copy()
    flat = z.reshape(-1)
    for q in range(flat.size):
        old = flat[q]
        flat[q] = old + EPS
        fp = forces(term, z)[0].ravel()
        flat[q] = old - EPS
        fm = forces(term, z)[0].ravel()
        flat[q] = old
        J[:, q] = (fp - fm) / (2 * EPS)
    return J


def assembled(term, hg, n_owned, n_local, alpha=1.0, beta=0.0):
    pattern = BlockPattern(n_owned, n_local, [hg])
    term.bind(pattern)
    data = pattern.new_values()
    term.add_to_system(data, alpha, beta)
    return pattern.local_matrix(data).toarray()


def small_sheet(rng, nx=3, ny=3, jitter=0.15):
    """A flat, irregular (jittered in-plane) sheet: rest shape for the tests."""
    x, tris = grid_mesh(nx, ny)
    x[:, :2] += jitter * (1.0 / nx) * rng.uniform(-1, 1, size=(x.shape[0], 2))
    return x, tris, hinges(tris)


# --------------------------------------------------------------------------
# topology
# --------------------------------------------------------------------------

@pytest.mark.parametrize("nx,ny", [(1, 1), (3, 2), (5, 7)])
def test_hinges_count_and_orientation(nx, ny):
    _, tris = grid_mesh(nx, ny)
    hg = hinges(tris)
    total = nx * (ny + 1) + ny * (nx + 1) + nx * ny        # horizontal, vertical, diagonal
    boundary = 2 * (nx + ny)
    assert hg.shape == (total - boundary, 4)
    keys = {tuple(sorted(h[:2])) for h in hg}
    assert len(keys) == hg.shape[0]                       # each interior edge once
    tri_set = {tuple(np.roll(t, r)) for t in tris for r in range(3)}
    for i0, i1, i2, i3 in hg:
        assert (i0, i1, i2) in tri_set                    # triangle A runs i0 -> i1
        assert (i1, i0, i3) in tri_set                    # triangle B runs i1 -> i0


def test_hinges_boundary_nonmanifold_and_orientation_errors():
    assert hinges(np.array([[0, 1, 2]])).shape == (0, 4)
    assert hinges(np.zeros((0, 3), dtype=int)).shape == (0, 4)
    # three triangles on edge (0, 1): non-manifold, no hinge
    assert hinges(np.array([[0, 1, 2], [1, 0, 3], [1, 0, 4]])).shape == (0, 4)
    with pytest.raises(ValueError):
        hinges(np.array([[0, 1, 2], [0, 1, 3]]))          # both run 0 -> 1


# --------------------------------------------------------------------------
# sign and value of the dihedral angle
# --------------------------------------------------------------------------

@pytest.mark.parametrize("phi", [0.3, -0.7, 2.5])
def test_dihedral_angle_sign_and_value(phi):
    # edge along x, wing x2 at +y (A = (x0, x1, x2) has normal +z), x3 at -y;
    # rotating each wing by phi/2 about the edge towards +z folds by phi
    c, s = np.cos(phi / 2), np.sin(phi / 2)
    x = np.array([[0, 0, 0], [1, 0, 0], [0.3, c, s], [0.6, -c, s]], dtype=float)
    hg = np.array([[0, 1, 2, 3]])
    assert np.isclose(hinge_angles(x, hg)[0], phi, atol=1e-14)


def test_cylinder_angles_signed_consistently():
    x, tris = grid_mesh(6, 5)
    hg = hinges(tris)
    for axis in (0, 1):
        up = hinge_angles(roll(x, 0.8, axis), hg)      # rolled towards the normals
        down = hinge_angles(roll(x, -0.8, axis), hg)
        # on the split grid only edges parallel to the cylinder axis bend (by h/R)
        assert up.min() > -1e-12 and up.max() > 0.1
        assert np.allclose(down, -up, atol=1e-12)
        # flipping every triangle flips the normals and the sign
        flipped = hinges(tris[:, ::-1])
        assert np.allclose(np.sort(hinge_angles(roll(x, 0.8, axis), flipped)),
                           np.sort(-up), atol=1e-12)


# --------------------------------------------------------------------------
# invariances
# --------------------------------------------------------------------------

@pytest.mark.parametrize("seed", [0, 1])
def test_rigid_motions_give_no_force(seed):
    rng = np.random.default_rng(seed)
    rest, _, hg = small_sheet(rng)
    R, t = random_rotation(rng), rng.normal(size=3)
    moved = rest @ R.T + t
    iso, dih = make_terms(hg, rest, B=rng.uniform(0.5, 2.0, hg.shape[0]))
    # force scale of a genuine unit-order bend, to make "zero" relative
    bent = rest.copy()
    bent[:, 2] = 0.3 * rng.normal(size=rest.shape[0])
    for term in (iso, dih):
        scale = np.abs(forces(term, bent)[0]).max()
        for x in (rest, moved):
            f, info = forces(term, x)
            # round-off only: sums of O(10) terms of size ~scale
            assert np.abs(f).max() <= 1e-12 * scale * 100
            assert abs(info["elastic_energy"]) <= 1e-20 + 1e-14 * scale
    # dihedral: also for a curved rest shape (the angles are intrinsic to the hinge)
    curved = rest.copy()
    curved[:, 2] = 0.2 * rng.normal(size=rest.shape[0])
    dih_c = DihedralBendingTerm(hg, curved, 1.0, 1.0)
    f, _ = forces(dih_c, curved @ R.T + t)
    scale = np.abs(forces(dih_c, bent)[0]).max()
    assert np.abs(f).max() <= 1e-10 * scale


def test_flat_states_have_zero_energy_at_any_resolution():
    rng = np.random.default_rng(4)
    A = np.eye(3) + 0.3 * rng.normal(size=(3, 3))
    A[2] = [0, 0, 1.0]                                     # in-plane affine map
    for n in (2, 8, 20):
        x, tris = grid_mesh(n, n)
        hg = hinges(tris)
        for term in make_terms(hg, x):
            assert abs(term.energy(x)) < 1e-20
        # isometric: linear precision -> any in-plane affine map is exactly flat
        iso = IsometricBendingTerm(hg, x, 1.0, 1.0)
        assert abs(iso.energy(x @ A.T)) < 1e-18
        assert abs(iso.rest_energy) < 1e-20


# --------------------------------------------------------------------------
# derivatives
# --------------------------------------------------------------------------

@pytest.mark.parametrize("seed", [0, 1, 2])
def test_forces_are_minus_energy_gradient(seed):
    rng = np.random.default_rng(seed)
    rest, _, hg = small_sheet(rng)
    x = rest + 0.15 * rng.normal(size=rest.shape)        # strongly deformed
    weight = rng.uniform(0.2, 1.0, hg.shape[0])
    for term in make_terms(hg, rest, B=rng.uniform(0.5, 2.0, hg.shape[0]), weight=weight):
        # forces are unweighted (the caller keeps owned rows); test with unit weight
        unit = type(term)(hg, rest, term.B, 1.0)
        f, info = forces(unit, x)
        g = fd_gradient(unit.energy, x)
        assert np.abs(f + g).max() <= RTOL * np.abs(g).max()
        # evaluate's energy equals energy(), and carries the weights
        _, winfo = forces(term, x)
        assert np.isclose(winfo["elastic_energy"], term.energy(x), rtol=1e-12)
        assert np.isclose(info["elastic_energy"], unit.energy(x), rtol=1e-12)
        assert winfo["elastic_energy"] < info["elastic_energy"]


@pytest.mark.parametrize("seed", [0, 1])
def test_isometric_jacobian_exact_and_constant(seed):
    rng = np.random.default_rng(seed)
    rest, _, hg = small_sheet(rng)
    n = rest.shape[0]
    term = IsometricBendingTerm(hg, rest, rng.uniform(0.5, 2.0, hg.shape[0]), 1.0)
    A = assembled(term, hg, n, n)                        # A = -df/dx = Q
    assert np.allclose(A, A.T, atol=1e-12 * np.abs(A).max())
    assert np.linalg.eigvalsh(A).min() > -1e-10 * np.abs(A).max()
    for _ in range(2):                                   # any state: the Jacobian is constant
        x = rest + 0.3 * rng.normal(size=rest.shape)
        J = fd_jacobian(term, x)
        assert np.abs(-A - J).max() <= RTOL * np.abs(J).max()
        # force is linear: f = -Q x
        assert np.allclose(forces(term, x)[0].ravel(), -A @ x.ravel(),
                           atol=1e-12 * np.abs(A).max() * np.abs(x).max())
    w = rng.normal(size=(n, 3))
    out = np.zeros((n, 3))
    term.stiffness_product(w, out)
    assert np.allclose(out.ravel(), -A @ w.ravel(), rtol=0, atol=1e-12 * np.abs(A).max() * 10)


@pytest.mark.parametrize("seed", [0, 1])
def test_dihedral_gauss_newton_hessian(seed):
    rng = np.random.default_rng(seed)
    rest, _, hg = small_sheet(rng)
    rest[:, 2] = 0.15 * rng.normal(size=rest.shape[0])   # curved rest shape, theta0 != 0
    n = rest.shape[0]
    term = DihedralBendingTerm(hg, rest, rng.uniform(0.5, 2.0, hg.shape[0]), 1.0)
    # at theta = theta0 (a rigid motion of the rest shape) Gauss-Newton is exact
    R, t = random_rotation(rng), rng.normal(size=3)
    x = rest @ R.T + t
    forces(term, x)
    A = assembled(term, hg, n, n)
    J = fd_jacobian(term, x)
    assert np.abs(-A - J).max() <= RTOL * np.abs(J).max()
    # away from rest: symmetric PSD, and the stiffness product applies the same matrix
    x = rest + 0.2 * rng.normal(size=rest.shape)
    forces(term, x)
    A = assembled(term, hg, n, n)
    assert np.allclose(A, A.T, atol=1e-12 * np.abs(A).max())
    assert np.linalg.eigvalsh(A).min() > -1e-10 * np.abs(A).max()
    w = rng.normal(size=(n, 3))
    out = np.zeros((n, 3))
    term.stiffness_product(w, out)
    assert np.allclose(out.ravel(), -A @ w.ravel(), rtol=0, atol=1e-12 * np.abs(A).max() * 10)
    # ... and differs from the exact Jacobian there (the dropped curvature term)
    J = fd_jacobian(term, x)
    assert np.abs(-A - J).max() > 1e-3 * np.abs(J).max()


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_dihedral_exact_hessian(seed):
    rng = np.random.default_rng(seed)
    rest, _, hg = small_sheet(rng)
    rest[:, 2] = 0.15 * rng.normal(size=rest.shape[0])
    n = rest.shape[0]
    term = DihedralBendingTerm(hg, rest, rng.uniform(0.5, 2.0, hg.shape[0]), 1.0,
                               hessian="exact")
    x = rest + 0.2 * rng.normal(size=rest.shape)        # far from rest: curvature term matters
    forces(term, x)
    A = assembled(term, hg, n, n)
    J = fd_jacobian(term, x)
    assert np.abs(-A - J).max() <= RTOL * np.abs(J).max()
    assert np.allclose(A, A.T, atol=1e-10 * np.abs(A).max())
    forces(term, x)             # the finite differences left the last perturbed state
    w = rng.normal(size=(n, 3))
    out = np.zeros((n, 3))
    term.stiffness_product(w, out)
    assert np.allclose(out.ravel(), -A @ w.ravel(), rtol=0, atol=1e-12 * np.abs(A).max() * 10)
    # the Hessian is the one at the last evaluate, not at later states
    forces(term, x + 0.1)                              # translation: same Hessian
    assert np.allclose(assembled(term, hg, n, n), A, rtol=0, atol=1e-9 * np.abs(A).max())
    with pytest.raises(ValueError):
        DihedralBendingTerm(hg, rest, 1.0, 1.0, hessian="newton")


def test_add_to_system_skips_ghost_rows_and_scales():
    rng = np.random.default_rng(7)
    rest, _, hg = small_sheet(rng)
    n = rest.shape[0]
    n_owned = n // 2
    x = rest + 0.1 * rng.normal(size=rest.shape)
    for term in make_terms(hg, rest) + (DihedralBendingTerm(hg, rest, 1.0, 1.0, hessian="exact"),):
        forces(term, x)
        full = assembled(term, hg, n, n, alpha=0.7, beta=0.3)
        part = assembled(term, hg, n_owned, n, alpha=0.7, beta=0.3)
        assert np.allclose(part, full[: 3 * n_owned], rtol=0, atol=1e-14 * np.abs(full).max())
        ref = assembled(term, hg, n, n, alpha=1.0, beta=0.0)
        assert np.allclose(full, 0.7 * ref, rtol=0, atol=1e-14 * np.abs(full).max())


# --------------------------------------------------------------------------
# calibration: cylinder energy 1/2 B (1/R)^2 area, resolution independence
# --------------------------------------------------------------------------

@pytest.mark.parametrize("kind,axis", [("split", 0), ("split", 1), ("equi", 1)])
def test_cylinder_energy_converges_to_continuum(kind, axis):
    B, radius, width, height = 2.5e-5, 0.6, 1.0, 0.8
    errors = {"iso": [], "dih": []}
    for n in (16, 32):
        ny = n if kind == "split" else int(round(n * height / width * 2 / np.sqrt(3)))
        x, tris = grid_mesh(n, ny, width, height, kind)
        hg = hinges(tris)
        area = width * height
        exact = 0.5 * B * area / radius ** 2
        y = roll(x, radius, axis)
        iso, dih = make_terms(hg, x, B=B)
        errors["iso"].append(abs(iso.energy(y) - exact) / exact)
        errors["dih"].append(abs(dih.energy(y) - exact) / exact)
        # the two models agree to leading order in the hinge angle (~h/R)
        assert abs(iso.energy(y) - dih.energy(y)) <= 0.01 * exact
    for model, err in errors.items():
        # the error is the missing boundary hinges, O(h / width): ~6 % then ~3 %
        assert err[1] < 0.05, (model, err)
        assert err[1] < 0.7 * err[0], (model, err)
    assert C_HINGE == 0.5


def test_energy_weight_scales_energy_not_forces():
    rng = np.random.default_rng(9)
    rest, _, hg = small_sheet(rng)
    x = rest + 0.1 * rng.normal(size=rest.shape)
    for cls in (IsometricBendingTerm, DihedralBendingTerm):
        a, b = cls(hg, rest, 1.0, 1.0), cls(hg, rest, 1.0, 0.25)
        fa, ia = forces(a, x)
        fb, ib = forces(b, x)
        assert np.array_equal(fa, fb)
        assert np.isclose(ib["elastic_energy"], 0.25 * ia["elastic_energy"], rtol=1e-13)



def test_a_fold_pressed_flat_keeps_its_force_across_pi():
    # two triangles folded on each other (dihedral angle pi - 0.05 from a flat
    # rest): a state that folds them 0.1 rad further crosses +-pi.  Followed
    # from the step's start its angle is pi + 0.05 and the force keeps opening
    # the fold, as just before the crossing (same direction, a little larger);
    # the raw angle -pi + 0.05 would reverse the force, which pushed folds
    # further through and kept a sewn skirt jittering
    hinge = np.array([[0, 1, 2, 3]])
    rest = np.array([[0.0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.5, -1, 0]])

    def folded(angle):     # triangle (0, 1, 3) turned about the hinge's edge
        x = rest.copy()
        c, s = np.cos(angle), np.sin(angle)
        x[3] = [0.5, -c, -s]
        return x

    term = DihedralBendingTerm(hinge, rest, 1.0, 1.0)
    start, crossed = folded(np.pi - 0.05), folded(np.pi + 0.05)
    assert hinge_angles(crossed, hinge)[0] * hinge_angles(start, hinge)[0] < 0

    def force(x):
        f = np.zeros((4, 3))
        term.evaluate(x, None, f, False)
        return f

    before = force(start)
    raw = force(crossed)          # no step has started: the raw angle
    term.at_step_start(start)
    on_branch = force(crossed)
    cos_raw = np.sum(raw * before) / np.linalg.norm(raw) / np.linalg.norm(before)
    cos_branch = np.sum(on_branch * before) / np.linalg.norm(on_branch) / np.linalg.norm(before)
    assert cos_raw < -0.99 and cos_branch > 0.99
    # |theta - theta0| is pi + 0.05 against pi - 0.05: the force grows by that ratio
    ratio = np.linalg.norm(on_branch) / np.linalg.norm(before)
    assert abs(ratio - (np.pi + 0.05) / (np.pi - 0.05)) < 1e-9
    # the energy the forces derive from, on the same branch: continuous across pi
    w = term.kb[0] * term.weight[0]
    assert abs(term.energy(crossed) - w * (np.pi + 0.05) ** 2) < 1e-12
    # the next step starts where this one ended: the angle is followed in time
    # (a fold that went past flat stays past it), and folding back recrosses
    term.at_step_start(crossed)
    assert abs(term.energy(crossed) - w * (np.pi + 0.05) ** 2) < 1e-12
    term.at_step_start(folded(np.pi + 0.3))
    term.at_step_start(folded(np.pi - 0.2))
    assert abs(term.energy(folded(np.pi - 0.2)) - w * (np.pi - 0.2) ** 2) < 1e-12
