"""Strain limiting (distcloth/strain_limiter.py, physics/strain_limits.py):
the bound holds at every step on a soft hanging square, the limiter never
adds energy, pins never move, and the result is the same on 1, 2 and 3
ranks.

The scene: a 0.5 m square of soft mass-spring cloth (10 N/m, 0.1 kg/m², the
stop-and-go paper's hanging square) hanging from its two top corners, 15 x 15
vertices, symplectic Euler at h = 1 ms (the explicit regime of Vassilev et
al. 2001; Eq. 4 allows 2.9 ms here).  Unlimited, the springs at the corners
stretch past 40 %.
"""
from __future__ import annotations

import h5py
import numpy as np
import pytest
from mpi4py import MPI

from conftest import run_cli
from test_physics import gather_positions, grid_scene, make_sim

N = 15
BOUND = 0.1
CORNERS = [N * (N - 1), N * N - 1]      # the top row's two ends (v max)


def hanging(method="provot", rule=None, limit=True, end=0.3, integrator="symplectic_euler",
            h=0.001, pins=None, rotation=(90.0, 0.0, 0.0), model="mass_spring"):
    spec = {"method": method, "weft": BOUND, "warp": BOUND, "shear": BOUND}
    if rule is not None:
        spec["rule"] = rule
    effects = ["gravity", "membrane", "bending"] + (["strain_limiting"] if limit else [])
    return grid_scene(
        cloth=[{"name": "sq", "mesh": {"grid": {"size": [0.5, 0.5], "resolution": [N, N]},
                                       "center": [0, 0, 1], "rotation": list(rotation)},
                "pins": pins or {"indices": CORNERS},
                "material": {"model": model, "density": 0.1, "stretch": 10.0,
                             "bending": 1e-6}}],
        effects=effects, strain_limiting=spec,
        time={"end": end, "step": h, "integrator": integrator})


def edge_strain(sim, x):
    """Largest engineering strain of the structural and shear springs, from
    global positions (independent of the limiter's own bookkeeping)."""
    m = sim.model
    keep = m.spring_kind != 2                      # not flexion
    s = m.spring_vertices[keep]
    length = np.linalg.norm(x[s[:, 1]] - x[s[:, 0]], axis=1)
    return float((length / m.spring_rest_length[keep] - 1.0).max())


def run(sim, steps):
    """(largest strain over the steps, final global positions)."""
    worst = 0.0
    for _ in range(steps):
        sim.step()
        worst = max(worst, edge_strain(sim, gather_positions(sim)))
    return worst, gather_positions(sim)


def test_corners_are_the_top_corners():
    sim = make_sim(hanging(limit=False))
    top = sim.model.rest_positions[:, 2].max()
    x = sim.model.rest_positions[CORNERS]
    assert np.allclose(x[:, 2], top) and abs(x[0, 0] - x[1, 0]) == pytest.approx(0.5)


def test_unlimited_square_stretches_well_past_the_bound():
    sim = make_sim(hanging(limit=False))
    worst, _ = run(sim, 300)
    assert worst > 0.3, worst


@pytest.mark.parametrize("method,rule,model", [("provot", None, "mass_spring"),
                                              ("velocity", "average", "mass_spring"),
                                              ("provot", None, "fem"),
                                              ("velocity", "average", "fem")])
def test_bound_holds_at_every_step_and_ranks_agree(method, rule, model):
    # bound + 0.5 % at every step (asked); the passes stop at bound + 0.1 %
    # (strain_limiting.tolerance), the velocity method a little below it.  FE
    # cloth is limited on the same edges (its mesh edges and cell diagonals)
    sim = make_sim(hanging(method, rule, model=model))
    worst, x = run(sim, 300)
    assert worst <= BOUND + 0.005, worst
    pinned = sim.model.rest_positions[CORNERS]
    assert np.array_equal(x[CORNERS], pinned)          # pins never move
    # the same run on this rank alone: the partition must not matter beyond
    # round-off (Jacobi passes with averaging; sums in a different order)
    alone = make_sim(hanging(method, rule, model=model), comm=MPI.COMM_SELF)
    _, x1 = run(alone, 300)
    assert np.abs(x - x1).max() < 1e-9, np.abs(x - x1).max()


@pytest.mark.parametrize("method,rule", [("provot", None), ("velocity", "average")])
def test_limiter_never_adds_energy(method, rule):
    # a square pinned along its top edge, released horizontal: it swings down,
    # its springs far past the bound without limiting; damping is off, backward
    # Euler at 5 ms.  The total energy never rises (tolerance: 1e-12 of the
    # energy scale M g L, round-off of sums of ~1e3 terms).  The energy of the
    # proposed state is also measured just before and just after the limiter
    # each step.  A single application can add a little: positions follow the
    # corrected velocities (x += h dv), so a slow vertex held back by the pins
    # loses less kinetic energy (v^2 / 2) than it keeps in height (g h v) when
    # v < 2 g h; measured at most 3.5e-5 M g L here (15 x 15, both methods),
    # bounded at 1e-4 M g L, far below what the step's own damping takes: the
    # total never rises (docs/strain_limiting.md)
    h = 0.005
    raw = hanging(method, rule, integrator="backward_euler", h=h, pins={"edge": "top"},
                  rotation=(0.0, 0.0, 0.0))
    sim = make_sim(raw)
    stage = sim.pipeline.stages["strain_limiting"]
    limit = stage.fn
    changes = []

    def energy(state, result):
        x = state.x.copy()
        x[: sim.n_owned] = result.x
        sim.ghosts.update(x)
        grav, elastic = sim.potential_energies(x)
        kinetic = 0.5 * float(sim.comm.sum(np.array([np.sum(
            sim.mass[: sim.n_owned, None] * result.v ** 2)]))[0])
        return kinetic + grav + elastic

    def measured(state, result, contacts, h):
        before = energy(state, result)
        report = limit(state, result, contacts, h)
        changes.append((energy(state, result) - before, report.springs))
        return report

    stage.fn = measured
    total = [sum(sim.energies())]
    for _ in range(int(round(0.6 / h))):
        total.append(sim.step()["total_energy"])
    scale = float(sim.model.vertex_mass.sum()) * 9.81 * 0.5
    d = np.array(changes)
    assert d[:, 1].max() > 0                         # the limiter did act
    assert np.diff(total).max() <= 1e-12 * scale, np.diff(total).max()
    assert d[:, 0].max() <= 1e-4 * scale, (d[:, 0].max(), scale)


def test_directional_rule_as_the_paper_states_it():
    # Vassilev et al. 2001 §3.2: v_dir = g dt (no body); a spring along v_dir
    # whose ends separate: the rear end (p1 when cos alpha > 0) takes the front
    # end's tangential velocity; a spring across v_dir: Eq. 5, both take the
    # average; an anchored end holds and the other end takes its velocity
    from distcloth.physics.strain_limits import velocity_pass
    x = np.array([[0.0, 0, 1.0], [0, 0, 0.0], [1.0, 0, 0], [2.2, 0, 0], [0, 5.0, 0], [0, 6.2, 0]])
    v = np.array([[0.0, 0, -1.0], [0, 0, -3.0], [-1.0, 0, 0], [2.0, 0, 0], [0, 0.5, 0], [0, 2.0, 0]])
    springs = np.array([[0, 1], [2, 3], [4, 5]])
    rest = np.array([1.0, 1.0, 1.0])
    limit = 1.1 * rest
    limit[0] = 0.9                       # the first spring is over its bound too
    mass = np.ones(6)
    anchored = np.array([False, False, False, False, True, False])
    vdir = np.tile([0.0, 0.0, -9.81 * 0.01], (3, 1))
    dv, active = velocity_pass(x, v, springs, limit, mass, anchored, vdir, np.zeros(3))
    assert active == 3
    out = v + dv
    # along v_dir (p1 = vertex 0 above vertex 1, u = -z, cos = 1): vertex 0
    # catches up with vertex 1's -3 m/s, vertex 1 keeps its velocity
    assert np.allclose(out[0], [0, 0, -3.0]) and np.allclose(out[1], v[1])
    # across it (cos = 0): both take the average 0.5 m/s along x
    assert np.allclose(out[2], [0.5, 0, 0]) and np.allclose(out[3], [0.5, 0, 0])
    # vertex 4 is anchored: it keeps 0.5 m/s, vertex 5 takes it
    assert np.allclose(out[4], v[4]) and np.allclose(out[5], [0, 0.5, 0])


def test_directional_rule_cannot_hold_a_pinned_cloth():
    # what docs/strain_limiting.md says about the paper's moving-body rule: the
    # rear end of a spring below a pin cannot catch up (the pin holds it), so
    # the springs under the pins keep separating, and catching up (momentum
    # from nowhere) adds energy; the average rule holds them (above).  The
    # energy guard would stop the run at step 81: off, to see the strain
    raw = hanging("velocity", "directional", end=0.1)
    raw["time"]["energy_guard"] = False
    sim = make_sim(raw)
    e0 = sum(sim.energies())
    worst, _ = run(sim, 100)
    assert worst > BOUND + 0.05, worst
    assert sum(sim.energies()) > e0


@pytest.mark.skipif(MPI.COMM_WORLD.rank != 0, reason="runs its own mpiexec from rank 0")
@pytest.mark.parametrize("method", ["provot", "velocity"])
def test_one_and_three_ranks_agree_through_the_command(tmp_path, method):
    import yaml
    raw = hanging(method, end=0.1)
    raw["output"] = {"file": "r.h5", "every": 0.1, "preview": False}
    scene = tmp_path / "hang.yaml"
    scene.write_text(yaml.safe_dump(raw))
    finals = []
    for ranks in (1, 3):
        out = tmp_path / f"r{ranks}.h5"
        proc = run_cli(["run", scene, "--quiet", "--output", out], ranks=ranks)
        assert proc.returncode == 0, proc.stderr[-2000:]
        with h5py.File(out, "r") as f:
            finals.append(f["frames/positions"][-1])
            assert np.nanmax(f["diagnostics/limited_springs"][:]) > 0
    assert np.abs(finals[0] - finals[1]).max() < 1e-9


@pytest.mark.parametrize("method", ["provot", "velocity"])
def test_contact_vertices_are_never_moved_by_the_limiter(method):
    # a soft cloth dropped on a sphere: the vertices in contact this step keep
    # the position and velocity the solve gave them; the others are limited
    raw = grid_scene(
        cloth=[{"name": "sq", "mesh": {"grid": {"size": [0.8, 0.8], "resolution": [17, 17]},
                                       "center": [0, 0, 0.27]},
                "material": {"model": "mass_spring", "density": 0.1, "stretch": 10.0,
                             "bending": 1e-6}, "thickness": 0.005}],
        effects=["gravity", "membrane", "bending", "collisions", "strain_limiting"],
        colliders=[{"name": "ball", "shape": "sphere", "center": [0, 0, 0], "radius": 0.25,
                    "friction": 0.3}],
        strain_limiting={"method": method, "weft": 0.05, "warp": 0.05, "shear": 0.1},
        time={"end": 1.0, "step": 0.005, "integrator": "backward_euler"})
    sim = make_sim(raw)
    stage = sim.pipeline.stages["strain_limiting"]
    limit = stage.fn
    held, moved = [0, 0], [0]

    def checked(state, result, contacts, h):
        x0, v0 = result.x.copy(), result.v.copy()
        report = limit(state, result, contacts, h)
        if contacts is not None and contacts.index.size:
            own = contacts.index[contacts.index < sim.n_owned]
            assert np.array_equal(result.x[own], x0[own])
            assert np.array_equal(result.v[own], v0[own])
            held[0] += own.size
        moved[0] += int(np.count_nonzero(np.any(result.x != x0, axis=1)))
        return report

    stage.fn = checked
    for _ in range(40):
        sim.step()
    assert sim.comm.sum(np.array([float(held[0]), float(moved[0])])).min() > 0


@pytest.mark.skipif(MPI.COMM_WORLD.rank != 0, reason="runs its own process from rank 0")
def test_too_few_passes_are_reported(tmp_path):
    import yaml
    raw = hanging("provot", end=0.1)
    raw["strain_limiting"]["passes"] = 1
    raw["output"] = {"file": "r.h5", "every": 0.1, "preview": False}
    scene = tmp_path / "hang.yaml"
    scene.write_text(yaml.safe_dump(raw))
    proc = run_cli(["run", scene, "--output", tmp_path / "r.h5"], ranks=None)
    assert proc.returncode == 0, proc.stderr[-2000:]
    log = proc.stdout + proc.stderr
    assert "warning: strain limiting left a spring at strain" in log
    assert "strain limiting did not reach its bound in" in log
