"""Mass-spring bending on grid lines (physics/bending.py, FlexionLineTerm).

The element is E = 1/2 B A_mid / a^4 |x_first + x_last - 2 x_mid|^2 on every
three consecutive vertices of a grid row or column.  Checked: the continuum
energy of a cylindrical bend along either grid axis (O(h^2)), no energy for
affine maps (no in-plane stiffness) and rigid motions, forces and the
constant Jacobian against finite differences, and why the plain flexion
spring it replaces cannot do this (its bending energy is O(kappa^4)).
"""
import numpy as np
import pytest

from distcloth.physics.bending import FlexionLineTerm, TwistCellTerm
from distcloth.physics.springs import spring_energy_only
from distcloth.scene.grid import (grid_flexion_lines, grid_twist_cells, grid_vertex_area,
                                  grid_vertices)
from test_bending import assembled, fd_gradient, fd_jacobian, forces, random_rotation, roll

RTOL = 1e-6          # as tests/test_bending.py (central differences, EPS = 1e-6)


def sheet(nu, nv, size=(1.0, 0.6)):
    res = (nu, nv)
    x = np.asarray(grid_vertices(size, res), dtype=np.float64)
    x = x - x.min(axis=0)                   # u along x from 0, v along y from 0
    return x, grid_flexion_lines(res), grid_vertex_area(size, res)


def term_for(x, lines, area, B=1.0):
    return FlexionLineTerm(lines, x, B, area[lines[:, 1]], 1.0)


@pytest.mark.parametrize("axis", [0, 1])
def test_cylinder_energy_is_the_continuum_one(axis):
    """Rolled onto a cylinder of radius R across either grid axis, E ->
    1/2 B A / R^2.  Per line element 1/2 k (2 a sin(a / 2R))^2 = 1/2 B A_mid /
    R^2 (1 - a^2 / 12 R^2 + ...); the lines' middles miss the two end columns
    (a strip of width a/2 at each end): error ~ a / L + a^2/(12 R^2), first
    order, measured -5.2 % then -2.5 % across x, -5.1 %, -2.5 % across y
    (a = 1/20, 1/40 of the sheet)."""
    B, R = 2e-5, 0.5
    errors = []
    for n in (21, 41):
        x, lines, area = sheet(n, n)
        exact = 0.5 * B * area.sum() / R ** 2
        e = term_for(x, lines, area, B).energy(roll(x, R, axis))
        errors.append(e / exact - 1.0)
    assert -0.06 <= errors[0] < 0 and -0.035 <= errors[1] < 0, errors
    assert 0.4 <= errors[1] / errors[0] <= 0.6, errors       # first order: the end strips


def test_no_energy_for_affine_maps_and_rigid_motions():
    """Linear precision of the second difference: no in-plane stiffness, so the
    structural springs keep their whole constant (scene/springs.py)."""
    rng = np.random.default_rng(3)
    x, lines, area = sheet(7, 5)
    term = term_for(x, lines, area)
    A = rng.normal(size=(3, 3))
    for y in (x @ A.T + rng.normal(size=3), x @ random_rotation(rng).T + rng.normal(size=3)):
        f, _ = forces(term, y)
        scale = term.coef.max() * np.abs(y).max()
        assert term.energy(y) <= 1e-24 * scale * np.abs(y).max()
        assert np.abs(f).max() <= 1e-12 * scale


@pytest.mark.parametrize("element", ["line", "twist"])
def test_forces_and_constant_jacobian_against_finite_differences(element):
    """The line element, and the twist element of the continuum's grid_lines
    bending (TwistCellTerm, tests/test_grid_lines.py), which uses the same
    kernels on the cell's four corners."""
    rng = np.random.default_rng(4)
    x, lines, area = sheet(4, 3)
    term = (term_for(x, lines, area, B=1.5) if element == "line"
            else TwistCellTerm(grid_twist_cells((4, 3)), x, 1.5, 1.0))
    y = x + 0.2 * rng.normal(size=x.shape)
    f, _ = forces(term, y)
    g = fd_gradient(term.energy, y)
    assert np.abs(f + g).max() <= RTOL * np.abs(g).max()
    J = fd_jacobian(term, y)
    A = assembled(term, term.hinges, x.shape[0], x.shape[0])
    assert np.abs(-A - J).max() <= RTOL * np.abs(J).max()
    w = rng.normal(size=x.shape)
    out = np.zeros_like(x)
    term.stiffness_product(w, out)
    assert np.allclose(out.ravel(), -A @ w.ravel(), rtol=0, atol=1e-11 * np.abs(A).max())


def test_a_plain_flexion_spring_has_no_linear_bending_stiffness():
    """Why the line element: the spring k_f = 4B / (2a)^2 between first and last
    (Provot 1995) stretches by 2a (1 - cos(phi/2)) when the line folds by phi,
    so its energy is O(phi^4): at a curvature kappa = phi / a of 0.1 / a it
    stores 1e-4 of the line element's energy, and halving kappa divides it
    by 16, not 4."""
    a, B = 0.01, 1e-4
    x = np.array([[0.0, 0, 0], [a, 0, 0], [2 * a, 0, 0]])
    lines = np.array([[0, 1, 2]])
    term = FlexionLineTerm(lines, x, B, np.array([a * a]), 1.0)
    ratio = []
    for phi in (0.1, 0.05):
        y = x.copy()
        y[2] = [a + a * np.cos(phi), 0.0, a * np.sin(phi)]
        spring = spring_energy_only(y, np.array([[0, 2]]), np.array([2 * a]),
                                    np.array([4 * B / (2 * a) ** 2]), np.ones(1))
        line = term.energy(y)
        exact = 0.5 * B * (phi / a) ** 2 * a * a
        assert abs(line / exact - 1) <= phi ** 2 / 12 + 1e-9       # 2 sin(phi/2) vs phi
        ratio.append(spring / line)
    assert ratio[0] < 2e-3 and 3.5 <= ratio[0] / ratio[1] <= 4.5


def test_grid_and_mesh_file_pieces_together(tmp_path):
    """A mass-spring scene with a grid (flexion line elements) and a mesh file
    (dihedral angles on its hinges) has one bending stage holding both; it is
    at rest in the rest shape and both kinds bend (energy > 0 once the pieces
    droop)."""
    from distcloth.physics.base import TermSum
    from distcloth.scene.meshio import write_obj
    from test_physics import grid_scene, make_sim
    from distcloth.scene.grid import grid_triangles
    x, _, _ = sheet(5, 5, size=(0.2, 0.2))
    path = str(tmp_path / "patch.obj")
    write_obj(path, x, grid_triangles((5, 5), "alternating"), header="test patch")
    raw = grid_scene(time={"end": 0.1, "step": 0.01})
    raw["cloth"][0]["pins"] = [{"edge": "top"}]
    raw["cloth"].append({"name": "patch", "mesh": {"file": path, "center": [1, 0, 1]},
                         "pins": [{"indices": [0, 1, 2, 3, 4]}],
                         "material": dict(raw["cloth"][0]["material"])})
    from mpi4py import MPI
    sim = make_sim(raw, comm=MPI.COMM_SELF)    # one rank holds both pieces
    (term,) = [t for t in sim.terms if t.name == "force:bending"]
    assert isinstance(term, TermSum) and len(term.parts) == 2
    rest = sim.model.rest_positions[sim.layout.local_input]
    assert term.energy(rest) <= 1e-20
    for _ in range(5):
        sim.step()
    x1 = sim.state.x
    line, hinge = term.parts
    assert line.energy(x1) > 0 and hinge.energy(x1) > 0
    sim.destroy()
