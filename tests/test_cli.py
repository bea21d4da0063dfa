"""The command line end to end, under its own mpiexec (rank 0 of the test job
launches it; see conftest.run_cli)."""
import math

import h5py
import numpy as np
import pytest

from conftest import ROOT, run_cli

pytestmark = pytest.mark.rank0_only

SQUARE = ROOT / "configs" / "hanging_square.yaml"


def small_square(tmp, name, *extra):
    """The hanging square, coarser (21 x 21) so the suite stays fast."""
    return [SQUARE, "--output", tmp / f"{name}.h5", "--quiet",
            "--set", "cloth.0.mesh.grid.resolution=[21, 21]", *extra]


def read_frames(path):
    with h5py.File(path, "r") as f:
        k = int(f.attrs["frames_written"])
        return f["frames/positions"][:k], f["frames/time"][:k], dict(f.attrs)


def test_rank_invariance_1_2_3(tmp_path):
    # flexion springs on (bending), 100 steps, tight unpreconditioned tolerance
    args = ["--set", "time.end=2.0", "--set", "output.every=0.1",
            "--set", "solver.ksp_rtol=1e-12", "--set", "solver.ksp_norm_type=unpreconditioned"]
    frames = {}
    for n in (1, 2, 3):
        p = run_cli(["run", *small_square(tmp_path, f"r{n}", *args)], ranks=n)
        assert p.returncode == 0, p.stderr
        pos, times, attrs = read_frames(tmp_path / f"r{n}.h5")
        frames[n] = pos
        assert attrs["status"] == "completed"
        assert int(attrs["steps"]) >= 100
        # the solve really used one block-Jacobi block per rank ...
        assert int(attrs["block_jacobi_blocks"]) == n
        # ... and row ownership is balanced (METIS imbalance <= 5 %)
        rows = np.asarray(attrs["rows_per_rank"])
        assert rows.size == n and rows.max() <= 1.05 * rows.mean()
    L = 0.5 * math.sqrt(2.0)     # the cloth's size (diagonal of the 0.5 m square)
    assert frames[1].shape[0] == 21
    for n in (2, 3):
        assert frames[n].shape == frames[1].shape
        # every frame: max |x_N - x_1| <= 1e-8 L
        dev = np.abs(frames[n] - frames[1]).max(axis=(1, 2))
        assert dev.max() <= 1e-8 * L, dev


@pytest.mark.parametrize("setting, key", [
    ("cloth.0.mesh={file: no_such_mesh.obj}", "cloth.0.mesh.file"),
    ("cloth.0.material.density=-0.1", "cloth.0.material.density"),
    ("effects=[gravity, membrane, magic]", "effects"),
    ("solver.ksp_rtoll=1e-8", "solver.ksp_rtoll"),
    ("time.step=fast", "time.step"),
])
def test_bad_config_exit_2(tmp_path, setting, key):
    out = tmp_path / "bad.h5"
    p = run_cli(["run", SQUARE, "--output", out, "--set", setting], ranks=2, timeout=120)
    assert p.returncode == 2, (p.returncode, p.stderr)
    lines = [ln for ln in p.stderr.splitlines() if ln.startswith("distcloth: config error")]
    assert len(lines) == 1, p.stderr            # one line, printed once (rank 0)
    assert key in lines[0]
    assert "Traceback" not in p.stderr
    assert not out.exists()                     # no half-written output


def test_unknown_petsc_option_on_command_line(tmp_path):
    out = tmp_path / "bad.h5"
    p = run_cli(["run", *small_square(tmp_path, "bad"), "-distcloth_ksp_rtoll", "1e-8"], ranks=2)
    assert p.returncode == 2 and "-distcloth_ksp_rtoll" in p.stderr
    assert not out.exists()


def test_command_line_petsc_option_wins(tmp_path):
    # scene says rtol 1e-6; the command line's 1e-2 must be what the solver used
    p = run_cli(["run", *small_square(tmp_path, "cl", "--set", "time.end=0.2"),
                 "-distcloth_ksp_rtol", "1e-2"], ranks=2)
    assert p.returncode == 0, p.stderr
    with h5py.File(tmp_path / "cl.h5", "r") as f:
        assert "rtol 0.01" in str(f.attrs["solver"])


def test_nan_on_one_rank_stops_all_and_keeps_frames(tmp_path):
    out = tmp_path / "nan.h5"
    p = run_cli(["run", *small_square(tmp_path, "nan", "--set", "output.every=0.02")],
                ranks=2, timeout=30, env_extra={"DISTCLOTH_INJECT_NAN": "1:7"})
    assert p.returncode != 0
    assert "step 7" in p.stderr and "NaN" in p.stderr
    pos, times, attrs = read_frames(out)
    assert attrs["status"] == "failed" and int(attrs["error_step"]) == 7
    assert "NaN" in str(attrs["error"])
    # the initial frame and steps 1..6 were written and are intact
    assert pos.shape[0] == 7 and np.all(np.isfinite(pos))
    assert np.allclose(times, 0.02 * np.arange(7))


def test_run_without_mpiexec_same_layout(tmp_path):
    a = run_cli(["run", *small_square(tmp_path, "serial", "--set", "time.end=0.4")], ranks=None)
    b = run_cli(["run", *small_square(tmp_path, "mpi", "--set", "time.end=0.4")], ranks=2)
    assert a.returncode == 0, a.stderr
    assert b.returncode == 0, b.stderr

    def layout(path):
        items = {}
        with h5py.File(path, "r") as f:
            f.visititems(lambda name, obj: items.__setitem__(name, getattr(obj, "shape", None)))
        return items

    assert layout(tmp_path / "serial.h5") == layout(tmp_path / "mpi.h5")
    pa, _, _ = read_frames(tmp_path / "serial.h5")
    pb, _, _ = read_frames(tmp_path / "mpi.h5")
    assert np.abs(pa - pb).max() <= 1e-6      # ksp_rtol 1e-6 of the scene


def test_gravity_only_never_calls_spring_stages(tmp_path):
    p = run_cli(["run", *small_square(tmp_path, "g", "--set", "effects=[gravity]",
                                      "--set", "time.end=0.2")], ranks=2)
    assert p.returncode == 0, p.stderr
    with h5py.File(tmp_path / "g.h5", "r") as f:
        calls = f["diagnostics/stage_calls"]
        assert calls["force:gravity"][:].sum() > 0
        for stage in ("force:membrane", "force:bending", "force:damping", "force:drag"):
            assert calls[stage][:].sum() == 0, stage


def test_explicit_step_refused_unless_forced(tmp_path):
    args = small_square(tmp_path, "ex", "--set", "time.integrator=symplectic_euler",
                        "--set", "time.end=0.04")
    p = run_cli(["run", *args], ranks=2)
    assert p.returncode == 2 and "time.step" in p.stderr and "Eq. 4" not in p.stderr.split("config error")[-1]
    p = run_cli(["run", *args, "--force"], ranks=2)
    assert "Eq. 4" in p.stderr       # Vassilev et al. 2001's bound, printed beside the limit


def test_output_reads_back_and_xdmf_matches(tmp_path):
    from distcloth.io.xdmf import check_xdmf
    p = run_cli(["run", *small_square(tmp_path, "x", "--set", "time.end=0.4",
                                      "--set", "output.preview=true")], ranks=2)
    assert p.returncode == 0, p.stderr
    h5 = tmp_path / "x.h5"
    with h5py.File(h5, "r") as f:
        n = f["mesh/rest_positions"].shape[0]
        assert n == 21 * 21
        assert f["frames/positions"].shape[1:] == (n, 3)
        assert f["mesh/triangles"][:].max() == n - 1
        assert "hanging_square" in f["config"][()].decode()
        k = int(f.attrs["frames_written"])
        assert k == f["frames/time"].shape[0] == 11
        for name in ("kinetic_energy", "elastic_energy", "ksp_iterations", "ksp_residual"):
            assert f["diagnostics"][name].shape[0] == 20
        # the first frame is the rest shape in input order
        assert np.allclose(f["frames/positions"][0], f["mesh/rest_positions"][:])
    assert check_xdmf(str(tmp_path / "x.xdmf")) == []
    assert (tmp_path / "x_frames.png").stat().st_size > 1000
    assert (tmp_path / "x_energy.png").stat().st_size > 1000


def test_check_validates_without_writing(tmp_path):
    out = tmp_path / "never.h5"
    p = run_cli(["check", SQUARE, "--set", f"output.file={out}"], ranks=2)
    assert p.returncode == 0, p.stderr
    assert "valid" in p.stderr
    assert not out.exists()


def test_mesh_file_scene_runs_on_two_ranks(tmp_path):
    # an OBJ cloth (configs/meshes/disc.obj) through the whole path
    p = run_cli(["run", ROOT / "configs" / "round_tablecloth.yaml", "--output", tmp_path / "d.h5",
                 "--quiet", "--set", "time.end=0.2", "--set", "output.preview=false"], ranks=2)
    assert p.returncode == 0, p.stderr
    with h5py.File(tmp_path / "d.h5", "r") as f:
        assert f["mesh/rest_positions"].shape == (527, 3)
        x = f["frames/positions"][: int(f.attrs["frames_written"])]
    assert np.all(np.isfinite(x)) and x[-1, :, 2].mean() < x[0, :, 2].mean()   # it fell


@pytest.mark.parametrize("bending", ["grid_lines", "dihedral", "isometric"])
def test_rank_invariance_continuum_membrane(tmp_path, bending):
    # FE membrane (StVK) with grid-line or hinge bending: elements crossing ranks
    # are evaluated on each rank that owns one of their vertices; 1 and 3 ranks
    # must agree
    args = ["--set", "time.end=1.0", "--set", "output.every=0.1",
            "--set", "cloth.0.material={model: fem, density: 0.1, E_weft: 10.0, bending: 1.0e-6, "
                     f"bending_model: {bending}}}",
            "--set", "solver.ksp_rtol=1e-12", "--set", "solver.ksp_norm_type=unpreconditioned"]
    frames = {}
    for n in (1, 3):
        p = run_cli(["run", *small_square(tmp_path, f"c{n}", *args)], ranks=n)
        assert p.returncode == 0, p.stderr
        frames[n] = read_frames(tmp_path / f"c{n}.h5")[0]
    L = 0.5 * math.sqrt(2.0)
    assert np.abs(frames[3] - frames[1]).max() <= 1e-8 * L


def test_explicit_limit_covers_continuum_membrane(tmp_path):
    # the Gershgorin bound comes from the assembled stiffness of every term, so an
    # FE membrane is checked too (it once escaped a spring-only bound)
    p = run_cli(["check", SQUARE, "--output", tmp_path / "c.h5", "--set", "time.integrator=rk4",
                 "--set", "cloth.0.material={model: fem, density: 0.1, E_weft: 10.0}"], ranks=2)
    assert p.returncode == 2 and "rk4 is unstable above" in p.stderr, p.stderr


def test_own_solver_settings_on_the_command_line(tmp_path):
    """-distcloth_mat_type and the other linear_system: keys are scene settings,
    checked like --set and never left to PETSc (which would call them unused)."""
    p = run_cli(["check", SQUARE, "--output", tmp_path / "c.h5", "-distcloth_mat_type", "dense"],
                ranks=2, timeout=120)
    lines = [ln for ln in p.stderr.splitlines() if ln.startswith("distcloth: config error")]
    assert p.returncode == 2 and lines == [
        "distcloth: config error: command line -distcloth_mat_type: 'dense' — one of baij | aij"]
    p = run_cli(["check", SQUARE, "--output", tmp_path / "c.h5", "-distcloth_mat_type", "aij",
                 "-distcloth_warm_start", "true",
                 "-distcloth_pc_rebuild_every", "3"], ranks=2, timeout=120)
    assert p.returncode == 0, p.stderr
    assert "aij matrix, " in p.stderr and "warm start" in p.stderr and "every 3 solves" in p.stderr
