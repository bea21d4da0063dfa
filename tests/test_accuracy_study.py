"""The accuracy study's engine (distcloth/study/{metrics,sweep,accuracy}.py),
in process on every rank of the test job.

* free fall against its exact trajectory x(t) = X + g t^2/2: backward Euler's
  discrete solution is X + g h^2 n(n+1)/2 (test_physics.py), so its position
  error at t = n h is exactly g h t/2 at every vertex, whatever the mesh;
  implicit midpoint is exact; measured across two steps and two resolutions
  against an exact reference on a third, finer, differently triangulated mesh;
* barycentric mapping between meshes is exact for affine fields;
* a resumed sweep does not rerun a finished variant;
* two runs of the same sweep give identical errors.
"""
import math
import os

import numpy as np
import pytest
from scipy.spatial import Delaunay

from distcloth.study import metrics, sweep
from distcloth.config.load import apply_overrides
from distcloth.study.accuracy import analyse

G = 9.81


@pytest.fixture(scope="module")
def dcomm():
    from distcloth.linalg.petsc import init_petsc
    init_petsc([])
    from distcloth.parallel.comm import Comm
    return Comm()


def square_scene(effects=("gravity",), end=0.2, every=0.04, resolution=5):
    return {
        "cloth": [{"name": "sq", "mesh": {"grid": {"size": [0.5, 0.5],
                                                   "resolution": [resolution, resolution]},
                                          "center": [0, 0, 1]},
                   "pins": [] if effects == ("gravity",) else [{"edge": "top"}],
                   "material": {"density": 0.1, "stretch": 10.0, "shear": 1.0, "bending": 1e-6}}],
        "effects": list(effects),
        "time": {"end": end, "step": 0.02, "integrator": "backward_euler"},
        # an exact solve: with gravity alone the matrix is M and CG converges in one iteration
        "solver": {"ksp_rtol": 1e-12, "ksp_norm_type": "unpreconditioned"},
        "output": {"file": "unused.h5", "every": every, "preview": False},
    }


def sweep_in(raw, vary, directory, comm, **kw):
    variants = sweep.plan(raw, sweep.parse_vary(vary), **kw)
    return sweep.run_sweep(variants, raw, ".", "test.yaml", comm, str(directory))


def exact_free_fall(times, n=17):
    """The exact answer on a 17 x 17 Delaunay mesh of the same square (not a variant's mesh)."""
    u = np.linspace(-0.25, 0.25, n)
    X, Y = np.meshgrid(u, u)
    rest = np.column_stack([X.ravel(), Y.ravel(), np.ones(X.size)])
    tri = Delaunay(rest[:, :2]).simplices.astype(np.int64)
    pos = np.repeat(rest[None], len(times), axis=0)
    pos[:, :, 2] -= 0.5 * G * np.asarray(times)[:, None] ** 2
    return {"time": np.asarray(times), "positions": pos, "rest_positions": rest,
            "triangles": tri, "diagnostics": {}}


def test_affine_field_maps_exactly_between_meshes():
    rng = np.random.default_rng(3)
    coarse = exact_free_fall([0.0], n=5)
    pts = np.column_stack([rng.uniform(-0.25, 0.25, (200, 2)), np.ones(200)])
    pts = np.vstack([pts, exact_free_fall([0.0], n=17)["rest_positions"]])   # boundary points too
    idx, w, miss = metrics.interpolation(coarse["rest_positions"], coarse["triangles"], pts)
    A = rng.standard_normal((3, 3))
    b = rng.standard_normal(3)
    field = coarse["rest_positions"] @ A.T + b
    mapped = metrics.apply_map(field[None], idx, w)[0]
    # barycentric interpolation reproduces affine fields up to round-off (|field| ~ 1)
    assert miss < 1e-12
    np.testing.assert_allclose(mapped, pts @ A.T + b, rtol=0, atol=1e-12)


def test_common_times_match_seconds_not_steps():
    ia, ib = metrics.common_times(np.arange(11) * 0.02, np.arange(21) * 0.01)
    np.testing.assert_array_equal(ia, np.arange(11))
    np.testing.assert_array_equal(ib, np.arange(0, 21, 2))
    ia, ib = metrics.common_times(np.array([0.0, 0.03]), np.array([0.0, 0.02, 0.04]))
    np.testing.assert_array_equal(ia, [0])


def test_free_fall_errors_equal_the_analytic_error(dcomm, shared_tmp):
    raw = square_scene()
    out = sweep_in(raw, ["time.step=0.02,0.01", "resolution=5,9",
                         "time.integrator=backward_euler,implicit_midpoint"],
                   shared_tmp / "ff", dcomm, noise_floor=False)
    assert all(o.status == "completed" for o in out)
    rows = None
    if dcomm.rank == 0:
        from distcloth.io.h5read import read_result
        rows = []
        for o in out:
            if o.variant.role != "variant":
                continue
            res = read_result(o.path)
            m = metrics.compare(res, exact_free_fall(res["time"]), drape=False)
            rows.append((dict(o.variant.settings), m))
    rows = dcomm.broadcast(rows)
    assert len(rows) == 8
    for settings, m in rows:
        h = float(settings["time.step"])
        assert m["frames_compared"] == 6                      # t = 0, 0.04, ..., 0.2
        np.testing.assert_allclose(m["times"], np.arange(6) * 0.04, rtol=0, atol=1e-12)
        if settings["time.integrator"] == "backward_euler":
            expected = 0.5 * G * h * m["times"]
            # exact solves: only round-off of positions ~1 m and of t^2 sums (1e-12 m)
            np.testing.assert_allclose(m["rms"], expected, rtol=1e-9, atol=1e-12)
            np.testing.assert_allclose(m["com_error"], expected, rtol=1e-9, atol=1e-12)
            assert m["final_error"] == pytest.approx(0.5 * G * h * 0.2, rel=1e-9)
            assert m["final_max_error"] == pytest.approx(0.5 * G * h * 0.2, rel=1e-9)
            # E_n - E_0 = -M g^2 h t_n / 2 (M = 0.1 kg/m^2 * 0.25 m^2); the drift is
            # measured from the first recorded step (t = h) to the end
            drift = -0.025 * G ** 2 * h * (0.2 - h) / 2
            assert m["energy_drift"] == pytest.approx(drift, rel=1e-7)
            # diverges (RMS > 1 cm) once g h t / 2 > 0.01: t > 0.102 s (h = 0.02), 0.204 s (h = 0.01)
            assert m["time_to_divergence"] == (pytest.approx(0.12) if h == 0.02 else math.inf)
        else:   # implicit midpoint is exact for constant acceleration
            assert m["rms_max"] < 1e-12
        assert m["map_miss"] < 1e-12                          # every material point is on the mesh


def _file_times(outcomes):
    return {o.variant.name: os.stat(o.path).st_mtime_ns for o in outcomes if o.status == "completed"}


@pytest.fixture(scope="module")
def resumed(dcomm, tmp_path_factory):
    """A sweep interrupted after its first variant, then run whole; and the same
    whole sweep run afresh elsewhere."""
    base = dcomm.broadcast(str(tmp_path_factory.mktemp("resume")))
    raw = square_scene(effects=("gravity", "membrane", "bending"), end=0.1, every=0.02, resolution=7)
    first = sweep_in(raw, ["time.step=0.02"], f"{base}/a", dcomm, noise_floor=False)
    before = _file_times(first)
    whole = sweep_in(raw, ["time.step=0.02,0.01"], f"{base}/a", dcomm)
    fresh = sweep_in(raw, ["time.step=0.02,0.01"], f"{base}/b", dcomm)
    return first, before, whole, fresh


def test_resumed_sweep_does_not_rerun_finished_variants(resumed):
    first, before, whole, _ = resumed
    done = first[0].variant.name
    by_name = {o.variant.name: o for o in whole}
    assert by_name[done].ran is False
    assert os.stat(by_name[done].path).st_mtime_ns == before[done]
    # the new step and the new (finer) reference and noise floor did run
    assert [o.ran for o in whole] == [False, True, True, True]
    assert all(o.status == "completed" for o in whole)


def test_rerun_reproduces_errors_exactly(resumed, dcomm):
    _, _, whole, fresh = resumed
    values = None
    if dcomm.rank == 0:
        a, _ = analyse(whole)
        b, _ = analyse(fresh)
        values = [[r.get(k) for k in metrics.SCALAR_METRICS] for r in a], \
                 [[r.get(k) for k in metrics.SCALAR_METRICS] for r in b]
    a, b = dcomm.broadcast(values)
    assert len(a) == 4
    # same rank count, same partition, same reduction order: bit for bit
    assert repr(a) == repr(b)
    # and the errors are real numbers, not all zero (the comparison could not pass vacuously)
    assert all(row[0] > 0 for row in a[:2])


# --- drape measures: shapes whose shadow is known --------------------------------

def grid_square(n=21, side=1.0):
    """A flat side x side square in the z = 0 plane, n x n vertices, two triangles per cell."""
    u = np.linspace(-side / 2, side / 2, n)
    X, Y = np.meshgrid(u, u)
    rest = np.column_stack([X.ravel(), Y.ravel(), np.zeros(X.size)])
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1))
    v = (j * n + i).ravel()
    tri = np.vstack([np.column_stack([v, v + 1, v + n + 1]), np.column_stack([v, v + n + 1, v + n])])
    return rest, tri


def tilt(x, a):
    """Rotate about the x axis by a (rad)."""
    c, s = math.cos(a), math.sin(a)
    return x @ np.array([[1, 0, 0], [0, c, -s], [0, s, c]]).T


def test_shadow_area_of_flat_tilted_and_folded_squares():
    rest, tri = grid_square()
    cell = 1.0 / metrics.SHADOW_CELLS
    # the raster counts whole cells along the outline: at most half a cell per side
    tol = 2 * cell
    assert metrics.shadow_area(rest, tri, cell) == pytest.approx(1.0, abs=tol)
    for a in (0.3, 0.7, 1.2):
        assert metrics.shadow_area(tilt(rest, a), tri, cell) == pytest.approx(math.cos(a), abs=tol)
    # a square turned in its plane keeps its area (outline slanted across the cells)
    c, s = math.cos(0.4), math.sin(0.4)
    turned = rest @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]).T
    assert metrics.shadow_area(turned, tri, cell) == pytest.approx(1.0, abs=tol)
    # folded in half along y = 0 (the upper half laid 1 cm above the lower): half its area,
    # not the convex hull's; and projected along another "up", the same as rotating the cloth
    folded = rest.copy()
    top = folded[:, 1] > 0
    folded[top, 1] *= -1
    folded[top, 2] = 0.01
    assert metrics.shadow_area(folded, tri, cell) == pytest.approx(0.5, abs=tol)
    assert metrics.shadow_area(rest[:, [2, 0, 1]], tri, cell, up=(1, 0, 0)) == pytest.approx(1.0, abs=tol)
    # vertical: no shadow
    assert metrics.shadow_area(tilt(rest, math.pi / 2), tri, cell) == pytest.approx(0.0, abs=tol)


def test_drape_measures_and_their_differences():
    rest, tri = grid_square()
    a = 0.5
    frames = np.stack([rest + [0, 0, 0.3], tilt(rest, a) + [0, 0, 0.3]])
    disc = math.pi * 0.25 ** 2
    d = metrics.drape_measures(frames, rest, tri, support_area=disc)
    np.testing.assert_allclose(d["shadow_area"], [1.0, math.cos(a)], atol=0.005)
    # Cusick: (A_shadow - A_disc) / (A_cloth - A_disc); flat cloth -> 1
    np.testing.assert_allclose(d["drape_coefficient"], (d["shadow_area"] - disc) / (1.0 - disc), rtol=1e-12)
    np.testing.assert_allclose(d["com_height"], [0.3, 0.3], atol=1e-12)   # tilted about its centre
    np.testing.assert_allclose(d["vertical_extent"], [0.0, math.sin(a)], atol=1e-12)
    no_disc = metrics.drape_measures(frames, rest, tri)
    np.testing.assert_allclose(no_disc["drape_coefficient"], no_disc["shadow_area"], rtol=1e-12)
    diff = metrics.compare_drape(d, {m: v[[0, 0]] for m, v in d.items()})
    assert diff["vertical_extent_final_diff"] == pytest.approx(math.sin(a))
    assert diff["shadow_area_max_diff"] == pytest.approx(1.0 - d["shadow_area"][1])
    assert diff["com_height_max_diff"] == pytest.approx(0.0, abs=1e-12)
    assert metrics.support_disc_area({"colliders": [{"shape": "sphere", "radius": 0.25},
                                                    {"shape": "plane"}]}) == pytest.approx(disc)
    assert metrics.support_disc_area({"colliders": [{"shape": "plane"}]}) == 0.0


# --- chaos: the noise floor's divergence decides --------------------------------

def test_chaos_follows_the_noise_floor():
    from distcloth.study import accuracy_report as rep
    calm = rep.chaos({"time_to_divergence": math.inf, "rms_max": 1e-7}, 0.01)
    assert not calm["chaotic"] and rep.ranking_metric(calm["chaotic"]) == "rms_mean"
    assert "not chaotic" in rep.chaos_sentences(calm)[0]
    wild = rep.chaos({"time_to_divergence": 0.6, "rms_max": 0.05}, 0.01)
    assert wild["chaotic"] and wild["auto"] and rep.ranking_metric(True) == "com_max_error"
    text = rep.chaos_sentences(wild)[0]
    assert "t = 0.6 s" in text and "predictability horizon" in text and "chosen automatically" in text
    told = rep.chaos({"time_to_divergence": math.inf, "rms_max": 1e-7}, 0.01, forced=True)
    assert told["chaotic"] and not told["auto"]


# --- axes: --alone around the base scene, the pc shorthand ----------------------

def test_alone_axes_compare_with_the_base_scene():
    raw = square_scene(resolution=9)
    plan = sweep.plan(raw, sweep.parse_vary(["time.step=0.02,0.01"]),
                      alone=sweep.parse_vary(["pc=jacobi", "resolution=5"]))
    roles = [(v.role, v.label(), v.base, v.alone) for v in plan]
    assert roles[:2] == [("variant", "time.step=0.02", True, False), ("variant", "time.step=0.01", False, False)]
    assert roles[2:4] == [("variant", "pc=jacobi", False, True), ("variant", "resolution=5", False, True)]
    ref = plan[4]
    # the base scene's own mesh (9 x 9) is finer than the --alone one, so the reference keeps it
    assert ref.role == "reference" and "time.step=0.0025" in ref.overrides
    assert not any("resolution" in o for o in ref.overrides)
    # no product variant is the base scene: it is added
    plan = sweep.plan(raw, {}, alone=sweep.parse_vary(["pc=jacobi"]))
    assert [v.label() for v in plan] == ["base scene", "pc=jacobi", "reference", "noise"]


def test_limiter_and_combo_shorthands_expand_to_scene_keys():
    raw = sweep.normalise_scene(square_scene(effects=("gravity", "membrane", "bending")))
    assert sweep.expand(raw, "limiter", "velocity") == (
        "effects=[gravity, membrane, bending, strain_limiting]", "strain_limiting.method=velocity")
    assert sweep.expand(raw, "limiter", "off") == ("effects=[gravity, membrane, bending]",)
    with pytest.raises(ValueError, match="limiter=pbd"):
        sweep.expand(raw, "limiter", "pbd")
    # one variant, several keys, shorthands inside; its values may hold commas
    combo = "cloth.0.material.stretch=10;limiter=provot;time.step=0.001;resolution=[5, 7]"
    [value] = sweep.parse_vary([f"combo={combo}"])["combo"]
    assert sweep.expand(raw, "combo", value) == (
        "cloth.0.material.stretch=10", "effects=[gravity, membrane, bending, strain_limiting]",
        "strain_limiting.method=provot", "time.step=0.001",
        "cloth.0.mesh.grid.resolution=[5, 7]")
    with pytest.raises(ValueError, match="combo="):
        sweep.expand(raw, "combo", "time.step")
    # the variants resolve to valid scenes
    plan = sweep.plan(raw, {}, alone={"combo": [value]}, noise_floor=False)
    resolved = apply_overrides(raw, plan[1].overrides)
    assert resolved["strain_limiting"]["method"] == "provot"
    assert resolved["cloth"][0]["material"]["stretch"] == 10


def test_every_pc_value_maps_to_solver_options_that_run(dcomm, shared_tmp):
    """Each pc shorthand sets its PETSc options, and PETSc accepts them: one step each."""
    raw = square_scene(effects=("gravity", "membrane", "bending"), end=0.02, every=0.02)
    for pc, opts in sweep.PC_PRESETS.items():
        assert set(sweep.expand(sweep.normalise_scene(raw), "pc", pc)) == {f"{k}={v}" for k, v in opts.items()}
    with pytest.raises(ValueError, match="pc=ilu"):
        sweep.expand(raw, "pc", "ilu")
    variants = sweep.plan(raw, {}, alone={"pc": list(sweep.PC_PRESETS)}, noise_floor=False)
    out = sweep.run_sweep(variants, raw, ".", "test.yaml", dcomm, str(shared_tmp / "pc"))
    assert [o.status for o in out] == ["completed"] * (len(sweep.PC_PRESETS) + 2)
    solvers = None
    if dcomm.rank == 0:
        from distcloth.io.h5read import read_attrs
        solvers = {o.variant.label(): read_attrs(o.path)["solver"] for o in out}
    solvers = dcomm.broadcast(solvers)
    for pc in ("jacobi", "gamg", "hypre"):
        assert pc in solvers[f"pc={pc}"]


# --- the command: CSV + Markdown + plots, and a rerun that resumes -------------

SCENE_YAML = """\
scene: tiny
cloth:
  - name: sq
    mesh: {grid: {size: [0.5, 0.5], resolution: [5, 5]}, center: [0, 0, 1]}
    pins: [{edge: top}]
    material: {density: 0.1, stretch: 10.0, shear: 1.0, bending: 1.0e-6}
effects: [gravity, membrane, bending]
time: {end: 0.08, step: 0.02, integrator: backward_euler}
output: {file: unused.h5, every: 0.04, preview: false}
"""


@pytest.mark.rank0_only
def test_command_writes_csv_report_plots_and_resumes(tmp_path):
    import csv
    from conftest import run_cli
    scene = tmp_path / "tiny.yaml"
    scene.write_text(SCENE_YAML)
    study = tmp_path / "study"
    args = ["study", "accuracy", str(scene), "--vary", "time.step=0.02,0.01",
            "--alone", "pc=jacobi", "--dir", str(study)]
    p = run_cli(args, ranks=2)
    assert p.returncode == 0, p.stderr
    assert "[accuracy] [1/5] variant time.step=0.02: running" in p.stderr
    with open(study / "accuracy.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert [r["role"] for r in rows] == ["variant"] * 3 + ["reference", "noise"]
    assert all(r["status"] == "completed" for r in rows)
    assert float(rows[0]["rms_mean"]) > float(rows[1]["rms_mean"]) > 0     # a finer step is closer
    assert rows[0]["shadow_area_final_diff"] != ""
    text = (study / "accuracy.md").read_text()
    assert "## Findings" in text and "pc=jacobi instead of the base scene" in text
    assert "not chaotic" in text
    pngs = ["error_vs_wall.png", "error_vs_time.png", "stage_split.png", "drape.png"]
    assert all((study / n).stat().st_size > 1000 for n in pngs)
    before = {h5.name: h5.stat().st_mtime_ns for h5 in study.glob("*.h5")}
    assert len(before) == 5
    again = run_cli(args, ranks=2)
    assert again.returncode == 0, again.stderr
    assert again.stderr.count("not rerun") == 5 and "running" not in again.stderr
    assert {h5.name: h5.stat().st_mtime_ns for h5 in study.glob("*.h5")} == before
    with open(study / "accuracy.csv", newline="") as f:
        assert [r["rms_mean"] for r in csv.DictReader(f)] == [r["rms_mean"] for r in rows]
