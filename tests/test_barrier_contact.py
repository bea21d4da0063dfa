"""Body contact as a barrier of the step (physics/contact_barrier.py and
the barrier Newton of integrate/implicit.py):

* the barrier and friction kernels are the derivatives they claim to be;
* a sheet resting on the floor sits at the gap where the barrier holds its
  weight, the root of kappa |b'(s)| = m g (known in closed form of the
  settings: the same for every vertex);
* Coulomb friction on an incline (gravity tilted by theta): below the
  friction angle the sheet creeps no faster than the static speed; above it,
  it slides with a = g (sin theta - mu cos theta), backward Euler's discrete
  motion under that constant force;
* the tablecloth on the sphere at the stiff 1000 N/m membrane with 20 ms
  steps runs to its end with the energy guard on and no halving, never
  closer to a body than its contact distance;
* 1, 2 and 3 ranks agree;
* the scenes the barrier cannot serve are refused before any work.
"""
import math

import h5py
import numpy as np
import pytest
from mpi4py import MPI
from scipy.optimize import brentq

from distcloth.integrate.implicit import _cut_per_vertex
from distcloth.physics.contact_barrier import (HALF_WIDTH_SLOPE, KEEP_GAP, barrier,
                                               barrier_curvature, barrier_slope, slip_damping,
                                               slip_force, slip_potential)
from conftest import ROOT, run_cli
from test_physics import discrete_free_fall, gather_positions, grid_scene, make_sim


def test_kernels_are_their_derivatives():
    w = 2e-3
    s = np.linspace(1e-5, 1.5 * w, 401)
    e = 1e-9
    # central differences: truncation O(e^2 b''') and round-off O(1e-16 b / e)
    # are far below 1e-6 relative on this range
    np.testing.assert_allclose(barrier_slope(s, w), (barrier(s + e, w) - barrier(s - e, w)) / (2 * e),
                               rtol=1e-5, atol=1e-12)
    np.testing.assert_allclose(barrier_curvature(s, w),
                               (barrier_slope(s + e, w) - barrier_slope(s - e, w)) / (2 * e),
                               rtol=1e-5, atol=1e-9)
    assert np.all(barrier(s[s >= w], w) == 0.0) and np.all(barrier_slope(s[s >= w], w) == 0.0)
    assert np.all(barrier_slope(s[s < w], w) < 0.0) and np.all(barrier_curvature(s[s < w], w) > 0.0)
    assert -barrier_slope(np.array([w / 2]), w)[0] == pytest.approx(HALF_WIDTH_SLOPE * w)
    eps = 1e-3
    y = np.linspace(0.0, 3 * eps, 301)
    d = 1e-8
    yy = y[1:]
    np.testing.assert_allclose(slip_force(yy, eps), (slip_potential(yy + d, eps)
                                                     - slip_potential(yy - d, eps)) / (2 * d),
                               rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(slip_damping(y[1:], eps), slip_force(y[1:], eps) / y[1:], rtol=1e-12)
    assert slip_damping(np.array([0.0]), eps)[0] == pytest.approx(2 / eps)
    assert np.all(slip_force(y[y >= eps], eps) == 1.0)


THICKNESS = 0.004          # d: the sheet's contact distance to the floor
STIFFNESS = 10.0           # contact.barrier_stiffness (the default)


def _floor_scene(gravity=(0.0, 0.0, -9.81), mu=0.0, end=0.4, step=0.01, z=None):
    w = THICKNESS / 2
    return grid_scene(
        cloth=[{"name": "sheet", "mesh": {"grid": {"size": [0.2, 0.2], "resolution": [5, 5]},
                                          "center": [0.0, 0.0, THICKNESS + 1.2 * w if z is None
                                                     else z]},
                "material": {"model": "fem", "density": 0.1, "stretch": 100.0, "bending": 1e-6,
                             "damping": 0.0},
                "thickness": THICKNESS}],
        effects=["gravity", "membrane", "bending", "collisions"],
        gravity=list(gravity),
        colliders=[{"name": "floor", "shape": "plane", "normal": [0, 0, 1], "offset": 0.0,
                    "friction": mu}],
        time={"end": end, "step": step},
        contact={"model": "barrier", "velocity_tolerance": 1e-7, "barrier_stiffness": STIFFNESS})


def _rest_gap():
    """The gap s where kappa |b'(s)| = m g: |b'(s)| = HALF_WIDTH_SLOPE w / STIFFNESS."""
    w = THICKNESS / 2
    target = HALF_WIDTH_SLOPE * w / STIFFNESS
    return brentq(lambda s: -barrier_slope(np.array([s]), w)[0] - target, 1e-9 * w, w * (1 - 1e-12))


def test_a_sheet_rests_where_the_barrier_holds_its_weight():
    sim = make_sim(_floor_scene(end=0.5), comm=MPI.COMM_WORLD)
    for _ in range(50):
        sim.step()
    x = gather_positions(sim)
    rejected = sim.state.rejections
    sim.destroy()
    gap = x[:, 2] - THICKNESS
    # backward Euler settles the drop of 0.2 w into the barrier within the
    # half second; Newton converged to 1e-7 m/s leaves the gap within
    # h * 1e-7 = 1e-9 m of the step's solution: 1e-8 m is the margin
    np.testing.assert_allclose(gap, _rest_gap(), atol=1e-8)
    assert 0 < _rest_gap() < THICKNESS / 2
    assert rejected == 0


def _incline_run(theta, mu, steps=50, h=0.01):
    g = 9.81
    gravity = (g * math.sin(theta), 0.0, -g * math.cos(theta))
    # placed at the gap that holds its weight's normal part: no bounce
    w = THICKNESS / 2
    target = HALF_WIDTH_SLOPE * w / STIFFNESS * math.cos(theta)
    s0 = brentq(lambda s: -barrier_slope(np.array([s]), w)[0] - target, 1e-9 * w, w * (1 - 1e-12))
    sim = make_sim(_floor_scene(gravity, mu, end=steps * h, step=h, z=THICKNESS + s0),
                   comm=MPI.COMM_WORLD)
    x0 = gather_positions(sim)
    for _ in range(steps):
        sim.step()
    x = gather_positions(sim)
    sim.destroy()
    return (x - x0)[:, 0], x[:, 2] - THICKNESS


def test_friction_holds_below_the_friction_angle():
    t = 0.5
    slide, gap = _incline_run(math.atan(0.3), mu=0.5)
    # stuck, the smoothed law lets a vertex creep at the speed where
    # f1(y) = tan(theta) / mu = 0.6, y = eps (1 - sqrt(0.4)) = 0.37 eps:
    # 0.19 mm in 0.5 s; sliding would be ~0.1 m
    assert np.all(np.abs(slide) < 1e-3 * t)
    assert np.all(slide > 0.0)
    assert np.all(gap > 0.0)


def test_friction_slides_with_coulomb_deceleration_above_it():
    theta, mu, steps, h = math.radians(45.0), 0.5, 50, 0.01
    slide, gap = _incline_run(theta, mu, steps, h)
    a = 9.81 * (math.sin(theta) - mu * math.cos(theta))
    expected = a * discrete_free_fall("backward_euler", h, steps)
    # beyond the static speed (1 mm/s, passed in the first step) friction is
    # exactly mu lambda and lambda the weight's normal part: backward Euler's
    # motion under the constant force, up to the first step's smoothing
    # (less than eps h = 1e-5 m) and Newton's tolerance
    np.testing.assert_allclose(slide, expected, rtol=1e-3)
    assert np.all(gap > 0.0)


def _sphere_scene(resolution, step, end, **time):
    return grid_scene(
        cloth=[{"name": "tablecloth",
                "mesh": {"grid": {"size": [1.0, 1.0], "resolution": [resolution, resolution]},
                         "center": [0.0, 0.0, 0.6]},
                "mass_lumping": "uniform", "thickness": 0.005,
                "material": {"model": "fem", "density": 0.15, "stretch": 2666.6666666666665,
                             "nu_weft": 1 / 3, "G": 1000.0, "bending": 1e-6,
                             "bending_model": "dihedral", "damping": 0.0}}],
        effects=["gravity", "membrane", "bending", "collisions"],
        colliders=[{"name": "ball", "shape": "sphere", "center": [0, 0, 0.25], "radius": 0.25,
                    "friction": 0.5},
                   {"name": "floor", "shape": "plane", "normal": [0, 0, 1], "offset": 0.0,
                    "friction": 0.5}],
        time={"end": end, "step": step, "integrator": "backward_euler", **time},
        solver={"ksp_rtol": 1e-8},
        contact={"model": "barrier"})


def _gaps(x):
    ball = np.linalg.norm(x - [0, 0, 0.25], axis=1) - 0.25 - 0.005
    return np.minimum(ball, x[:, 2] - 0.005)


def test_the_stiff_tablecloth_lands_on_the_sphere_with_20_ms_steps():
    # the peer benchmark's S2 at 15 x 15: with constraints, backward Euler at
    # 20 ms was stopped by the energy guard after the landing
    # (docs/integrators.md); with the barrier it runs with the guard on
    sim = make_sim(_sphere_scene(15, 0.02, 0.8), comm=MPI.COMM_WORLD)
    e0 = sum(sim.energies())
    closest, highest, touching = np.inf, -np.inf, 0.0
    for _ in range(40):
        touching = max(touching, sim.step()["contacts"])
        closest = min(closest, float(np.min(_gaps(gather_positions(sim)))))
        highest = max(highest, sum(sim.energies()) - e0)
    rejected = sim.state.rejections
    z = gather_positions(sim)[:, 2]
    sim.destroy()
    assert rejected == 0
    assert touching > 20                  # the diagnostics count the vertices in the band
    assert closest > 0.0                  # never within the contact distance
    assert highest <= 1e-3                # backward Euler, converged: only loses energy
    assert np.min(z) < 0.2                # draped over the sphere, below its equator
    assert np.max(z) == pytest.approx(0.505, abs=2.5e-3)   # on the sphere's top, in the band


def test_the_newton_line_search_evaluates_phi_once_at_each_point():
    # Phi at an iterate is the value its line search accepted (one Phi a
    # step): evaluating it again there is a whole potential's cost, ~5 % of an
    # iteration at 100k vertices (docs/benchmarks.md)
    sim = make_sim(_sphere_scene(9, 0.02, 0.3), comm=MPI.COMM_WORLD)
    seen, repeats = [], 0
    potential = sim.ctx.potential

    def counted(x, v, *args, **kwargs):
        nonlocal repeats
        key = (np.asarray(x).tobytes(), np.asarray(v).tobytes())
        repeats += key in seen
        seen.append(key)
        return potential(x, v, *args, **kwargs)

    sim.ctx.potential = counted
    newton = [sim.step()["newton_iterations"] for _ in range(12)]
    sim.destroy()
    assert sum(newton) >= len(newton) + 6     # the landing takes several iterations a step
    assert len(seen) >= sum(newton)           # every iteration tries a point
    assert repeats == 0


def test_a_vertex_closing_on_a_body_holds_back_only_itself():
    # the flat 9 x 9 sheet 95 mm above the sphere's top, moved 0.2 m down:
    # the vertices over the sphere would pass into it, the rest not
    sim = make_sim(_sphere_scene(9, 0.02, 0.3), comm=MPI.COMM_WORLD)
    ctx = sim.ctx
    n = ctx.n_owned
    x = sim.state.x.copy()
    down = np.zeros_like(x)
    down[:, 2] = -0.2
    own = ctx.barrier.step_bound(x, down)
    cut, fraction = _cut_per_vertex(ctx, x, down, -down[:n], 1.0)
    held = MPI.COMM_WORLD.allreduce(int(np.sum(own < 1.0)))
    free = MPI.COMM_WORLD.allreduce(int(np.sum(own == 1.0)))
    # the one held back goes its own way, a tenth of its gap short (the
    # centre's exactly: the tangent of the sphere's top is its distance);
    # the others all of theirs, and the ghosts carry their owners' cut
    np.testing.assert_allclose(cut[:n], down[:n] * own[:, None], rtol=0, atol=1e-15)
    centre = np.linalg.norm(x[:n, :2], axis=1) < 1e-9
    np.testing.assert_allclose(own[centre], (1.0 - KEEP_GAP) * (0.6 - 0.505) / 0.2, rtol=1e-9)
    np.testing.assert_array_equal(ctx.local_array(cut[:n]), cut)
    # a cut that does not lower Phi (its gradient along the move): not taken
    same, whole = _cut_per_vertex(ctx, x, down, down[:n], 1.0)
    least = -MPI.COMM_WORLD.allreduce(-float(np.min(own)), op=MPI.MAX)
    sim.destroy()
    assert held >= 5 and free >= 40
    assert np.all(_gaps(x[:n] + cut[:n]) >= KEEP_GAP * _gaps(x[:n]) - 1e-12)
    np.testing.assert_array_equal(same, down)
    assert whole == least                  # cut as a whole, by the least fraction
    assert 0.95 <= fraction <= 1.0         # the cut moves are (nearly) free


def test_a_stop_at_a_large_step_onto_a_body_names_the_barrier():
    # the same landing at 33 ms with contact as constraints and no Newton
    # retry: the linearised landing step gains energy (docs/integrators.md,
    # "Large steps onto a body"); the stop says which contact model takes it
    from distcloth.simulation import SimulationError
    raw = _sphere_scene(9, 1 / 30, 1.0, energy_retry_newton=1)
    raw["contact"] = {"model": "constraints"}
    sim = make_sim(raw, comm=MPI.COMM_WORLD)
    with pytest.raises(SimulationError, match=r"step \d+: energy gain: .*; contact.model: "
                                              r"barrier takes large steps onto a body"):
        for _ in range(30):
            sim.step()
    sim.destroy()


def _ranks_scene(out):
    raw = _sphere_scene(9, 0.01, 0.2)
    raw["cloth"][0]["mesh"]["center"] = [0.0, 0.0, 0.52]
    raw["contact"]["velocity_tolerance"] = 1e-8
    raw["solver"] = {"ksp_rtol": 1e-12, "ksp_norm_type": "unpreconditioned"}
    raw["output"] = {"file": str(out), "every": 0.2, "preview": False}
    return raw


def test_ranks_agree(comm, shared_tmp):
    # Newton converged to 1e-8 m/s and CG to 1e-12: positions after 20 steps
    # of landing and sliding agree to 1e-8 m between 1 and 2 ranks in
    # process, and 3 ranks (a separate run) with them
    sims = {}
    for name, c in (("one", MPI.COMM_SELF), ("two", comm)):
        sim = make_sim(_ranks_scene(shared_tmp / "unused.h5"), comm=c)
        for _ in range(20):
            sim.step()
        sims[name] = gather_positions(sim)
        contacts = sim.comm.sum(np.array([float(np.sum(
            _gaps(sim.owned_positions()) < sim.contact.barrier.width))]))[0]
        sim.destroy()
    assert contacts >= 4                 # the vertices over the sphere's top are in the band
    np.testing.assert_allclose(sims["one"], sims["two"], atol=1e-8)
    if comm.rank == 0:
        import yaml
        scene = shared_tmp / "ranks.yaml"
        scene.write_text(yaml.safe_dump(_ranks_scene(shared_tmp / "three.h5")))
        p = run_cli(["run", scene, "--quiet", "--overwrite"], ranks=3, timeout=300)
        assert p.returncode == 0, p.stderr
        with h5py.File(shared_tmp / "three.h5", "r") as f:
            x3 = f["frames/positions"][-1]
        np.testing.assert_allclose(x3, sims["one"], atol=1e-8)


@pytest.mark.parametrize("change, key", [
    ({"time": {"integrator": "implicit_midpoint"}}, "time.integrator"),
    ({"time": {"integrator": "symplectic_euler", "step": 0.0001}}, "time.integrator"),
    ({"colliders": [{"name": "body", "shape": "mesh", "file": "meshes/torso.obj",
                     "method": "image"}]}, "colliders.0.method"),
])
def test_scenes_the_barrier_cannot_serve_are_refused(tmp_path, change, key):
    import yaml
    raw = _floor_scene()
    raw.pop("solver")
    for k, v in change.items():
        if isinstance(v, dict):
            raw[k] = {**raw.get(k, {}), **v}
        else:
            raw[k] = v
    raw["output"] = {"file": str(tmp_path / "x.h5"), "every": 0.1, "preview": False}
    scene = tmp_path / "s.yaml"
    scene.write_text(yaml.safe_dump(raw))
    if "colliders" in change:
        (tmp_path / "meshes").mkdir()
        (tmp_path / "meshes/torso.obj").write_text((ROOT / "configs/meshes/torso.obj").read_text())
    p = run_cli(["check", scene], ranks=None, timeout=60)
    assert p.returncode == 2, p.stdout + p.stderr
    assert key in p.stderr and "barrier" in p.stderr and "Traceback" not in p.stderr
    assert not (tmp_path / "x.h5").exists()
