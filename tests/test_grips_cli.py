"""Grips, loads and the energy guard's warning through the command line,
under its own mpiexec (rank 0 of the test job launches it)."""
import h5py
import numpy as np
import pytest
import yaml

from conftest import ROOT, run_cli

pytestmark = pytest.mark.rank0_only

TENSILE = ROOT / "configs" / "tensile_grips.yaml"


def test_a_moving_grip_run_is_rank_invariant(tmp_path):
    # 10 steps of the tensile example (grip, line load, reactions), 1 and 2 ranks
    args = ["--set", "time.end=0.1", "--set", "output.every=0.05",
            "--set", "solver.ksp_rtol=1e-12", "--set", "solver.ksp_norm_type=unpreconditioned",
            "--quiet"]
    got = {}
    for n in (1, 2):
        out = tmp_path / f"r{n}.h5"
        p = run_cli(["run", TENSILE, "--output", out, *args], ranks=n)
        assert p.returncode == 0, p.stderr
        with h5py.File(out, "r") as f:
            assert f.attrs["status"] == "completed"
            assert list(f.attrs["grips"]) == ["strip.pins.0", "strip.pins.1"]
            got[n] = (f["frames/positions"][...],
                      np.array([f[f"diagnostics/reaction_{g}_{c}"][...] for g in (0, 1)
                                for c in "xyz"]))
    from distcloth.io.preview import write_previews
    drawn = write_previews(tmp_path / "r1.h5")
    assert str(tmp_path / "r1_reactions.png") in drawn and (tmp_path / "r1_reactions.png").stat().st_size
    pos1, reac1 = got[1]
    assert reac1[3, -1] > 0 > reac1[0, -1]          # the jaws pull the strip apart
    for n in (2,):
        # solver tolerance 1e-12 on a 0.1 m strip: positions within 1e-10 L,
        # reactions within 1e-8 of the largest
        assert np.abs(got[n][0] - pos1).max() <= 1e-11
        assert np.abs(got[n][1] - reac1).max() <= 1e-8 * np.abs(reac1).max()


def _gaining_scene(tmp_path, guard: bool):
    # the stability suite's large-step case: a 9 x 9 hanging square, one
    # linearised backward-Euler step of 0.1 s overstretches it and the energy
    # grows far past the guard's bound (tests/test_step_health.py) unless the
    # step is solved again with Newton
    scene = {"scene": "gain",
             "cloth": [{"name": "sq", "mesh": {"grid": {"size": [0.5, 0.5], "resolution": [9, 9]},
                                               "center": [0, 0, 1]},
                        "pins": [{"edge": "top"}],
                        "material": {"density": 0.1, "stretch": 10.0, "shear": 1.0,
                                     "bending": 1e-6}}],
             "effects": ["gravity", "membrane", "bending"],
             "time": {"end": 1.0, "step": 0.1, "energy_guard": guard,
                      "energy_retry_newton": 1},
             "output": {"file": str(tmp_path / "gain.h5"), "every": 0.5, "preview": False}}
    path = tmp_path / "gain.yaml"
    path.write_text(yaml.safe_dump(scene))
    return path


def test_an_energy_gain_with_the_guard_off_is_a_warning_not_a_plain_completion(tmp_path):
    p = run_cli(["run", _gaining_scene(tmp_path, False), "--quiet"], ranks=2)
    assert p.returncode == 0, p.stderr                      # still a finished run
    with h5py.File(tmp_path / "gain.h5", "r") as f:
        a = dict(f.attrs)
    assert a["status"] == "completed_with_warnings"
    (line,) = [w.decode() if isinstance(w, bytes) else w for w in a["warnings"]]
    step = int(a["warning_steps"][0])
    assert line.startswith(f"step {step} (t = ") and " J gained" in line
    assert "time.energy_guard is false" in line
    shown = run_cli(["inspect", tmp_path / "gain.h5"], ranks=None)
    assert shown.returncode == 0
    assert "status:     completed_with_warnings" in shown.stdout
    assert f"warnings:   step {step} (t = " in shown.stdout
    # the guard on: the same run stops at that step
    p = run_cli(["run", _gaining_scene(tmp_path, True), "--quiet", "--overwrite"], ranks=2)
    assert p.returncode == 1 and f"step {step}: energy gain" in p.stderr + p.stdout


def test_drape_refuses_a_moving_grip_and_bad_keys_are_one_line(tmp_path):
    def error_lines(p):
        return [ln for ln in p.stderr.splitlines() if ln.startswith("distcloth: config error")]

    p = run_cli(["drape", TENSILE, "--output", tmp_path / "d.h5"], ranks=2)
    assert p.returncode == 2
    (line,) = error_lines(p)
    assert line.startswith("distcloth: config error: cloth.0.pins.1.motion: ")
    assert not (tmp_path / "d.h5").exists()
    p = run_cli(["check", TENSILE, "--set", "cloth.0.pins.1.motion.stop=-1"], ranks=2)
    assert p.returncode == 2
    (line,) = error_lines(p)
    assert line.startswith("distcloth: config error: cloth.0.pins.1.motion.stop: -1")
