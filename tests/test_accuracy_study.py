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
            m = metrics.compare(res, exact_free_fall(res["time"]))
            rows.append((dict(o.variant.settings), m))
    rows = dcomm.bcast(rows)
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
    base = dcomm.bcast(str(tmp_path_factory.mktemp("resume")))
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
    a, b = dcomm.bcast(values)
    assert len(a) == 4
    # same rank count, same partition, same reduction order: bit for bit
    assert repr(a) == repr(b)
    # and the errors are real numbers, not all zero (the comparison could not pass vacuously)
    assert all(row[0] > 0 for row in a[:2])
