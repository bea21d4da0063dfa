"""Uniaxial tensile test of the continuum membrane (EG07 tutorial, Part 1 §3.5-3.6, Eq. 22).

A 0.2 m x 0.05 m strip (alternating 21 x 7 grid) is stretched by a uniform
engineering strain; its ends are held only along the load axis (sliding pins,
free to contract sideways) and the middle vertex of the left end also across
it, to remove rigid motion without restraining the symmetric contraction.
At equilibrium the state is homogeneous, which linear triangles represent
exactly (patch test), so the end reaction per reference width must follow
the model's exact uniaxial law: for St. Venant-Kirchhoff with lateral stress
zero, S_xx = E_u E_xx with E_u = 1 / (C^-1)_11 and E_xx the Green strain,
and the nominal force per width is P = (1 + eps) S_xx.  1 % is far above the
Newton/CG tolerances used (1e-10) and far below the error of any wrong law
(linear instead of Green strain is off by eps/2 + ..., > 5 % at 10 %).
"""
import numpy as np
import pytest

from distcloth.physics.membrane_fem import orthotropic_plane_stress, uniaxial_modulus
from distcloth.scene import build_model
from distcloth.config.load import config_from_dict
from test_physics import make_sim

L, W = 0.2, 0.05


def strip_reaction(eps, weft, E_weft=100.0, E_warp=50.0, nu_weft=0.3, **material):
    from mpi4py import MPI
    raw = {"cloth": [{"name": "strip",
                      "mesh": {"grid": {"size": [L, W], "resolution": [21, 7]}},
                      "pins": [{"edge": "left", "axis": [1, 0, 0]},
                               {"edge": "right", "axis": [1, 0, 0]},
                               {"box": {"min": [-0.11, -0.001, -0.001], "max": [-0.09, 0.001, 0.001]}}],
                      "material": {"model": "fem", "density": 0.1, "E_weft": E_weft,
                                   "E_warp": E_warp, "nu_weft": nu_weft, "G": 20.0,
                                   "weft": weft, "bending": 0.0, **material}}],
           "effects": ["membrane"],
           "time": {"end": 1000.0, "step": 100.0, "newton_iterations": 30,
                    "newton_tolerance": 1e-12},
           "solver": {"ksp_rtol": 1e-12, "ksp_norm_type": "unpreconditioned"},
           "output": {"file": "unused.h5", "every": 1000.0, "preview": False}}
    model = build_model(config_from_dict(raw, ".", "strip"))
    x = model.rest_positions.copy()
    x[:, 0] *= 1.0 + eps                 # stretched ends; the interior relaxes from here
    model.initial_positions = x
    sim = make_sim(raw, model)
    for _ in range(5):
        sim.step()
    n = sim.n_owned
    f = sim.ctx.forces(sim.state.x, np.zeros_like(sim.state.v), want_jac=False)[:n]
    right = np.isclose(model.rest_positions[sim.layout.owned_input, 0], L / 2)
    reaction = MPI.COMM_WORLD.allreduce(-float(f[right, 0].sum()), op=MPI.SUM)
    sim.destroy()
    return reaction / W


@pytest.mark.parametrize("eps", [0.02, 0.1, 0.2])
def test_uniaxial_law_weft(eps):
    C = orthotropic_plane_stress(100.0, 50.0, 0.3, 0.15, 20.0)
    expected = (1 + eps) * uniaxial_modulus(C, 0) * ((1 + eps) ** 2 - 1) / 2
    assert abs(strip_reaction(eps, [1, 0, 0]) - expected) <= 0.01 * expected


def test_weft_and_warp_in_the_ratio_of_their_moduli():
    # the same stretch along weft, then along warp (weft turned to y): at small
    # strain the loads are in the ratio of the uniaxial moduli
    C = orthotropic_plane_stress(100.0, 50.0, 0.3, 0.15, 20.0)
    ratio = strip_reaction(0.01, [1, 0, 0]) / strip_reaction(0.01, [0, 1, 0])
    assert abs(ratio - uniaxial_modulus(C, 0) / uniaxial_modulus(C, 1)) <= 0.01 * ratio


# a stiffening weft curve, Green strain -> direct stress (N/m): initial slope 100,
# 300 beyond 5 %, 900 beyond 10 %
CURVE = [[0.0, 0.0], [0.05, 5.0], [0.10, 20.0], [0.30, 200.0]]


def tabulated_strip_reaction(eps):
    return strip_reaction(eps, [1, 0, 0], tension_weft=CURVE)


def exact_tabulated_uniaxial(eps):
    """The model's uniaxial law: e_u from eps; lateral stress zero,
    S_v(e_v) + C12 e_u = 0 with the linear warp law S_v = C22 e_v; then
    S_u = S_weft(e_u) + C12 e_v and P = (1 + eps) S_u."""
    C = orthotropic_plane_stress(100.0, 50.0, 0.3, 0.15, 20.0)
    e_u = ((1 + eps) ** 2 - 1) / 2
    e_v = -C[0, 1] * e_u / C[1, 1]
    s_weft = np.interp(e_u, [p[0] for p in CURVE], [p[1] for p in CURVE])
    return (1 + eps) * (s_weft + C[0, 1] * e_v)


@pytest.mark.parametrize("eps", [0.02, 0.08, 0.2])
def test_uniaxial_law_tabulated(eps):
    expected = exact_tabulated_uniaxial(eps)
    assert abs(tabulated_strip_reaction(eps) - expected) <= 0.01 * expected


def test_tabulated_kernel_is_consistent():
    """Forces = -grad energy and the Hessian = -dforce/dx (central differences,
    eps 1e-7 on O(0.1) coordinates: truncation and round-off below 1e-6 relative),
    on a random state straddling the curve's kinks only away from them."""
    from distcloth.physics.membrane_fem import MembraneFEMTerm
    from distcloth.linalg.pattern import BlockPattern
    rng = np.random.default_rng(3)
    X = np.array([[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0], [0.1, 0.1, 0]], float)
    tris = np.array([[0, 1, 3], [0, 3, 2]])
    C = orthotropic_plane_stress(100.0, 50.0, 0.3, 0.15, 20.0)
    term = MembraneFEMTerm(tris, X, None, C, "stvk", np.ones(2), project=False,
                           tables=(CURVE, [[0.0, 0.0], [0.2, 8.0]],
                                   [[0.0, 0.0], [0.01, 0.2], [0.1, 5.0]]))
    x = X * np.array([1.12, 0.97, 1.0]) + 0.002 * rng.normal(size=X.shape)
    x[3, 0] += 0.004          # some shear, past the shear curve's first kink
    f = np.zeros_like(x)
    term.evaluate(x, None, f, True)
    h = 1e-7
    grad = np.zeros(12)
    J = np.zeros((12, 12))
    for q in range(12):
        for sgn in (1, -1):
            xp = x.copy().ravel()
            xp[q] += sgn * h
            xp = xp.reshape(4, 3)
            grad[q] += sgn * term.energy(xp) / (2 * h)
            fp = np.zeros_like(x)
            term.evaluate(xp, None, fp, False)
            J[:, q] += sgn * fp.ravel() / (2 * h)
    assert np.abs(f.ravel() + grad).max() <= 1e-6 * np.abs(f).max()
    pattern = BlockPattern(4, 4, [tris])
    term.evaluate(x, None, np.zeros_like(x), True)
    term.bind(pattern)
    data = pattern.new_values()
    term.add_to_system(data, 1.0, 0.0)
    assert np.abs(-pattern.local_matrix(data).toarray() - J).max() <= 1e-5 * np.abs(J).max()
