"""Draping (Volino and Magnenat-Thalmann 2007): every method reaches the same
rest state, and stop-and-go needs far fewer iterations than plain dynamics
(the paper reports 100 against ~400 on its wrinkle relaxation; here 102
against 1411 iterations on a 9 x 9 square hanging along one edge, measured
on one rank)."""
import h5py
import numpy as np
import pytest

from conftest import ROOT, run_cli
from test_physics import gather_positions, grid_scene, make_sim


def drape(method, tol=1e-4, **keys):
    from distcloth.integrate.drape import Relaxation, drape_converged
    raw = grid_scene(time={"end": 1000.0, "step": 0.02})
    raw["cloth"][0]["pins"] = [{"edge": "top"}]
    raw["drape"] = {"method": method, "tolerance": tol, "max_iterations": 3000, **keys}
    sim = make_sim(raw)
    relax = Relaxation(sim, sim.cfg.drape)
    start = sum(sim.potential_energies())
    for k in range(1, 3001):
        diag = relax.iterate()
        if drape_converged(diag, sim.cfg.drape):
            break
    x = gather_positions(sim)
    sim.destroy()
    return k, diag, x, start


def test_drape_methods_agree_and_stop_and_go_is_fastest():
    results = {m: drape(m) for m in ("stop_and_go", "dynamic", "quasistatic", "newton")}
    ref = results["newton"][2]
    for method, (its, diag, x, start) in results.items():
        assert diag["residual"] <= 1e-4, method
        assert diag["potential_energy"] < start, method
        # forces below 1e-4 of each vertex's weight: positions agree to well under a millimetre
        assert np.abs(x - ref).max() <= 5e-4, method
        assert abs(diag["potential_energy"] - results["newton"][1]["potential_energy"]) \
            <= 1e-6 * abs(start), method
    assert results["stop_and_go"][1]["stops"] > 0
    assert results["stop_and_go"][0] * 3 < results["dynamic"][0]


@pytest.mark.rank0_only
def test_drape_command_writes_its_iterations(tmp_path):
    out = tmp_path / "d.h5"
    p = run_cli(["drape", ROOT / "configs" / "hanging_square.yaml", "--output", out, "--quiet",
                 "--set", "cloth.0.mesh.grid.resolution=[15, 15]",
                 "--set", "output.preview=false"], ranks=2)
    assert p.returncode == 0, p.stderr
    with h5py.File(out, "r") as f:
        assert f.attrs["status"] == "completed" and f.attrs["drape_method"] == "stop_and_go"
        r = f["diagnostics/residual"][:]
        assert r[-1] <= 1e-3 and r[0] > r[-1]
        assert f["diagnostics/stops"][-1] > 0
        assert f.attrs["frames_written"] >= 2


def test_motion_criterion_stops_when_nothing_moves():
    # the same hang, stopped by 'visible stability': no vertex moved 1 um over 10
    # iterations; at the force residual's 1e-4 the state is a fraction of a
    # millimetre from equilibrium, so the two stops agree to that
    ref = drape("stop_and_go")
    its, diag, x, _ = drape("stop_and_go", criterion="motion", motion_tolerance=1e-6, window=10)
    assert its % 10 == 0 and diag["window_motion"] <= 1e-6
    assert np.abs(x - ref[2]).max() <= 5e-4
    assert diag["residual"] <= 1e-2


def test_unbalanced_force_is_the_excess_over_the_friction_cone():
    from distcloth.collision.response import unbalanced_force
    n = np.tile([0.0, 0.0, 1.0], (5, 1))
    f = np.array([[0.3, 0.0, -1.0],     # pressed, inside the cone (mu = 0.5): held
                  [2.0, 0.0, -1.0],     # pressed, sliding: 2 - 0.5 * 1 left
                  [0.0, 0.0, 1.0],      # pulled away: all of it
                  [0.3, 0.0, -1.0],     # the same as the first, but not touching
                  [0.0, 0.4, -3.0]])    # pressed hard: held
    touching = np.array([True, True, True, False, True])
    r = unbalanced_force(f, touching, n, np.full(5, 0.5))
    assert r == pytest.approx([0.0, 1.5, 1.0, np.hypot(0.3, 1.0), 0.0], abs=1e-15)
