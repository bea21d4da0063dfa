"""Grips (pins with a prescribed motion), point and line loads, initial
velocities (docs/loads_and_grips.md), against known answers; in process on
every rank of the test job (partitioned under mpiexec -n 2).

* a strip pulled at constant velocity: the grips' reactions are the
  material law's E W strain (linear corotated membrane, no Poisson
  contraction: a homogeneous uniaxial state the linear triangles hold
  exactly);
* a grip follows its path exactly, keyframed translations and rotations,
  in every integrator, a sliding grip along its axis;
* a free grid with an initial velocity and no force moves exactly;
* a point load on a hanging sheet: the pins carry the weight plus the load;
* a line load is lumped by the edge lengths;
* a loaded passive scene keeps its energy, loads' potential included, and
  the energy guard stays quiet.
"""
import numpy as np
import pytest

from distcloth.config.load import config_from_dict
from distcloth.scene import build_model
from distcloth.scene.grips import PinPath

from test_physics import gather_positions, make_sim

L, W, E, V = 0.1, 0.02, 1000.0, 0.01
INTEGRATORS = ("backward_euler", "bdf2", "implicit_midpoint", "newmark", "symplectic_euler",
               "explicit_midpoint", "rk4")
EXPLICIT = ("symplectic_euler", "explicit_midpoint", "rk4")


def strip(motion, integrator="backward_euler", step=0.01, end=0.5, axis=None, **piece):
    """A 10 cm x 2 cm strip, left end clamped, right end a grip; corotated
    linear membrane with nu = 0 (uniaxial stress E * strain exactly)."""
    grip = {"edge": "right", "motion": motion}
    if axis is not None:
        grip["axis"] = axis
    return {"cloth": [{"name": "strip",
                       "mesh": {"grid": {"size": [L, W], "resolution": [11, 3]}},
                       "pins": [{"edge": "left"}, grip],
                       "material": {"model": "fem", "density": 0.1, "E_weft": E, "nu_weft": 0.0,
                                    "G": 100.0, "strain": "corotated", "bending": 0.0},
                       **piece}],
            "effects": ["membrane"],
            "time": {"end": end, "step": step, "integrator": integrator},
            "solver": {"ksp_rtol": 1e-12, "ksp_norm_type": "unpreconditioned"},
            "output": {"file": "unused.h5", "every": end, "preview": False}}


@pytest.mark.parametrize("integrator, tol", [
    # backward Euler and BDF-2 reproduce a ramp exactly (a linear motion has no
    # second difference) and damp the start transient: round-off and CG (1e-12)
    ("backward_euler", 1e-9), ("bdf2", 1e-9),
    # no numerical damping: the start transient (the grip's jump to V) rings
    # on undamped; its amplitude here is 9e-4 of the final load
    ("implicit_midpoint", 2e-3)])
def test_pulled_strip_reaction_is_the_material_law(integrator, tol):
    sim = make_sim(strip({"velocity": [V, 0, 0]}, integrator))
    for _ in range(50):
        d = sim.step()
    strain = V * sim.state.t / L
    expected = E * W * strain                      # N: stiffness x strain x width
    assert d["reaction_1_x"] == pytest.approx(expected, rel=tol)
    assert d["reaction_0_x"] == pytest.approx(-expected, rel=tol)
    assert abs(d["reaction_1_y"]) + abs(d["reaction_1_z"]) <= 1e-9 * expected
    sim.destroy()


def _grip_rows(sim):
    right = np.isclose(sim.model.rest_positions[sim.layout.local_input, 0], L / 2)
    return right, sim.model.rest_positions[sim.layout.local_input][right]


def keys(end):
    """Keyframes over [0, end]: a pull, a sideways move and a turn, held after 0.8 end."""
    return {"times": [0.0, 0.4 * end, 0.8 * end],
            "translations": [[0, 0, 0], [0.001, 0, 0], [0.001, 5e-4, 0]],
            "rotations": [[0, 0, 0], [0, 0, 0], [0, 0, 0.1]]}


@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_a_grip_follows_its_keyframes_exactly(integrator):
    # explicit: below the stability bound, and few steps (explicit midpoint is
    # weakly unstable without damping)
    h, end = (5e-5, 0.002) if integrator in EXPLICIT else (1e-3, 0.01)
    steps = int(round(end / h))
    raw = strip(keys(end), integrator, step=h, end=end)
    raw["time"]["energy_guard"] = False      # explicit midpoint gains energy undamped
    sim = make_sim(raw)
    right, X = _grip_rows(sim)
    path = sim.model.grips[1].path
    worst = 0.0
    for _ in range(steps):
        sim.step()
        worst = max(worst, float(np.abs(sim.state.x[right] - path.positions(X, sim.state.t)).max()))
    # on the path to round-off at every step, through the keys and the rotation
    assert worst <= 1e-15
    assert np.allclose(sim.state.x[right], path.positions(X, end), atol=1e-15)
    sim.destroy()


@pytest.mark.parametrize("integrator", ["backward_euler", "implicit_midpoint", "rk4"])
def test_a_sliding_grip_follows_its_path_along_its_axis_only(integrator):
    h = 5e-5 if integrator in EXPLICIT else 1e-3
    sim = make_sim(strip({"velocity": [V, 0, 0.5]}, integrator, step=h, end=0.005,
                         axis=[1, 0, 0]))
    right, X = _grip_rows(sim)
    for _ in range(int(round(0.005 / h))):
        sim.step()
    # held along x: exactly on the path's x; the z component of the motion is
    # not prescribed (free across the axis), and nothing pushes along z
    assert np.allclose(sim.state.x[right, 0], X[:, 0] + V * 0.005, atol=1e-15, rtol=0)
    assert np.abs(sim.state.x[right, 2]).max() <= 1e-12
    sim.destroy()


def test_pin_path_constant_velocity_window_and_keyframes():
    from distcloth.config.schema import PinMotionSpec
    X = np.array([[1.0, 0.0, 0.0]])
    p = PinPath(PinMotionSpec(velocity=(1.0, 2.0, 0.0), start=0.5, stop=1.5), np.zeros(3))
    assert np.allclose(p.positions(X, 0.2), X)
    assert np.allclose(p.positions(X, 1.0), X + [0.5, 1.0, 0.0])
    assert np.allclose(p.positions(X, 9.0), X + [1.0, 2.0, 0.0])
    assert np.allclose(p.velocities(X, 1.5), 0.0) and np.allclose(p.velocities(X, 0.5), [1, 2, 0])
    spin = PinMotionSpec(times=(0.0, 1.0), translations=((0, 0, 0), (0, 0, 1)),
                         rotations=((0, 0, 0), (0, 0, np.pi / 2)))
    q = PinPath(spin, center=np.zeros(3))
    assert np.allclose(q.positions(X, 1.0), [[0.0, 1.0, 1.0]])        # turned a quarter, lifted
    assert np.allclose(q.positions(X, 0.5), [[np.sqrt(0.5), np.sqrt(0.5), 0.5]])
    assert np.allclose(q.velocities(X, 0.0), [[0.0, np.pi / 2, 1.0]])
    assert q.end == 1.0 and p.end == 1.5


@pytest.mark.parametrize("integrator", ["backward_euler", "bdf2", "implicit_midpoint", "rk4"])
def test_a_free_grid_with_an_initial_velocity_moves_exactly(integrator):
    v0 = np.array([0.3, -0.2, 0.5])
    raw = strip({"velocity": [0, 0, 0]}, integrator, step=1e-4, end=0.002,
                initial_velocity=v0.tolist())
    raw["cloth"][0]["pins"] = []
    sim = make_sim(raw)
    X = sim.model.rest_positions
    for _ in range(20):
        sim.step()
    x = gather_positions(sim)
    # a rigid translation strains nothing: forces are round-off, every scheme
    # (BDF-2 from its backward-Euler start) integrates x = X + v0 t exactly
    assert np.abs(x - (X + v0 * sim.state.t)).max() <= 1e-14
    v = np.zeros_like(X)
    v[sim.layout.owned_input] = sim.state.v[: sim.n_owned]
    assert np.abs(sim.comm.sum(v) - v0).max() <= 1e-10
    sim.destroy()


def test_initial_angular_velocity_about_the_centre_of_mass_and_pins_at_rest():
    w = np.array([0.0, 0.0, 2.0])
    raw = strip({"velocity": [V, 0, 0]}, initial_velocity=[0.1, 0, 0],
                initial_angular_velocity=w.tolist())
    model = build_model(config_from_dict(raw, ".", "t"))
    x, v = model.start_positions(), model.start_velocities()
    centre = (model.vertex_mass[:, None] * x).sum(axis=0) / model.vertex_mass.sum()
    free = model.pin_group < 0
    assert np.allclose(v[free], [0.1, 0, 0] + np.cross(w, x[free] - centre), atol=1e-15)
    assert np.all(v[model.grips[0].vertices] == 0.0)                # clamped: at rest
    assert np.allclose(v[model.grips[1].vertices], [V, 0, 0])       # the grip: its velocity


def hanging(loads, step=1.0, steps=12, **time):
    """A 0.2 m square hanging from its top edge in the x-z plane (springs), in
    equilibrium after a few huge backward-Euler steps solved by Newton."""
    raw = {"cloth": [{"name": "sheet",
                      "mesh": {"grid": {"size": [0.2, 0.2], "resolution": [5, 5]},
                               "center": [0, 0, 1], "rotation": [90, 0, 0]},
                      "pins": [{"edge": "top"}], "loads": loads,
                      "material": {"density": 0.1, "stretch": 20.0, "shear": 2.0,
                                   "bending": 0.0}}],
           "effects": ["gravity", "membrane", "loads"],
           "time": {"end": step * steps, "step": step, "newton_iterations": 40,
                    "newton_tolerance": 1e-12, **time},
           "solver": {"ksp_rtol": 1e-13, "ksp_norm_type": "unpreconditioned"},
           "output": {"file": "unused.h5", "every": step * steps, "preview": False}}
    return raw


def test_a_point_load_on_a_hanging_sheet_is_carried_by_the_pins():
    F = np.array([0.01, 0.0, -0.05])
    sim = make_sim(hanging([{"corner": "bottom_left", "force": F.tolist()}]))
    for _ in range(12):
        d = sim.step()
    weight = sim.model.vertex_mass.sum() * np.array([0, 0, -9.81])
    reaction = np.array([d["reaction_0_x"], d["reaction_0_y"], d["reaction_0_z"]])
    # static equilibrium: the pins hold the weight and the load; Newton to 1e-12
    # and 1 s steps leave accelerations ~1e-10 of g (kinetic energy below)
    assert d["kinetic_energy"] < 1e-18
    assert np.allclose(reaction, -(weight + F), rtol=0, atol=1e-9 * np.linalg.norm(weight))
    sim.destroy()


def test_a_line_load_is_lumped_by_the_edge_lengths():
    raw = hanging([{"edge": "bottom", "line_force": [0, 0, -2.0]},
                   {"indices": [6, 7], "forces": [[1, 0, 0], [0, 1, 0]]}])
    loads = build_model(config_from_dict(raw, ".", "t")).loads
    total = np.zeros((25, 3))
    np.add.at(total, loads.vertices, loads.forces)
    # 2 N/m over 0.2 m: 0.4 N; each of the 4 edges of 0.05 m carries 0.1 N, half
    # to each end: 0.1 N on the interior vertices of the edge, 0.05 N on its corners
    assert np.allclose(total[:5, 2], [-0.05, -0.1, -0.1, -0.1, -0.05])
    assert np.allclose(total[6], [1, 0, 0]) and np.allclose(total[7], [0, 1, 0])
    assert total.sum(axis=0) == pytest.approx([1.0, 1.0, -0.4])


def _load_potential(sim):
    term = next(t for t in sim.terms if t.name == "force:loads")
    return float(sim.comm.sum(np.array([term.energy(sim.state.x)]))[0])


def test_a_loaded_passive_scene_keeps_its_energy_with_the_loads_potential():
    # implicit midpoint conserves energy up to a bounded oscillation (1.7 % of
    # the largest kinetic energy here): with the load's potential -F . x
    # counted, the total stays at its start and the guard (on) never fires;
    # the potential's change is 20 times that oscillation, so a total without
    # it would not be conserved
    raw = hanging([{"corner": "bottom_left", "force": [0, 0, -0.05]}], step=0.005, steps=60,
                  integrator="implicit_midpoint", newton_iterations=10)
    sim = make_sim(raw)
    e0, u0 = sum(sim.energies()), _load_potential(sim)
    diags = [sim.step() for _ in range(60)]
    drift = max(abs(d["total_energy"] - e0) for d in diags)
    assert drift <= 0.05 * max(d["kinetic_energy"] for d in diags)
    assert abs(_load_potential(sim) - u0) > 20 * drift
    assert sim.energy_warnings == 0 and sim.state.energy_reference is not None
    sim.destroy()


def test_a_ramped_load_drives_the_scene_until_its_ramp_ends():
    raw = hanging([{"corner": "bottom_left", "force": [0, 0, -0.05], "ramp": 2.5}], steps=4)
    sim = make_sim(raw)
    assert sim.energy_guard.drive_end == 2.5 and sim.state.energy_reference is None
    for _ in range(3):
        sim.step()                                  # t = 3 s: passive from here
    assert sim.state.energy_reference is not None
    sim.destroy()


def test_moving_grips_keep_the_guard_waiting():
    sim = make_sim(strip({"velocity": [V, 0, 0], "stop": 0.02}, end=0.05))
    assert sim.energy_guard.drive_end == pytest.approx(0.02)
    sim.destroy()
    sim = make_sim(strip({"velocity": [V, 0, 0]}, end=0.05))
    assert sim.energy_guard.drive_end == np.inf     # never passive: never a reference
    sim.destroy()


def test_the_example_of_the_docs_is_a_valid_scene():
    import re
    from pathlib import Path

    import yaml
    text = (Path(__file__).resolve().parents[1] / "docs" / "loads_and_grips.md").read_text()
    raw = yaml.safe_load(re.search(r"```yaml\n(.*?)```", text, flags=re.S).group(1))
    model = build_model(config_from_dict(raw, ".", "example"))
    assert [g.name for g in model.grips] == ["strip.pins.0", "strip.pins.1", "strip.pins.2"]
    assert model.loads.forces.sum(axis=0) == pytest.approx([0, 0, -0.01 - 0.03 - 0.1 * 0.1])
