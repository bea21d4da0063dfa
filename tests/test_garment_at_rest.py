"""scripts/garment_at_rest.py on a tiny synthetic garment: two square panels
welded along one edge, a third (one triangle) piercing the first, a box of a
body just under one corner.  Serial (each rank its own files; rank 0 only)."""
from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

from distcloth.io import ResultWriter

ROOT = Path(__file__).resolve().parents[1]
L = 0.1          # panel size, m


def _script():
    spec = importlib.util.spec_from_file_location("garment_at_rest",
                                                  ROOT / "scripts" / "garment_at_rest.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


class Box:
    """A static mesh collider: the closed box lo..hi, outward triangles."""
    name, shape, moving = "body", "mesh", False

    def __init__(self, lo, hi):
        c = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], float)
        self._x = np.asarray(lo) + c * (np.asarray(hi) - np.asarray(lo))
        quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4),
                 (1, 5, 7, 3)]
        self.triangles = np.array([t for a, b, c_, d in quads for t in ((a, b, c_), (a, c_, d))])

    def vertices(self, t):
        return self._x


def _write(path, rest, triangles, frames, times, diag_names, diags, attrs, colliders=(),
           arrays=None, status="completed"):
    n = rest.shape[0]
    w = ResultWriter(str(path), None, rest_positions=rest, triangles=triangles,
                     owned_input=np.arange(n), part=np.zeros(n, np.int32),
                     config_text=CONFIG, attrs=attrs, stage_names=["solve"],
                     diagnostic_names=diag_names, colliders=colliders, arrays=arrays)
    for k, (x, t) in enumerate(zip(frames, times)):
        for s, row in enumerate(diags[k]):
            w.write_step(int(row["step"]), float(row["time"]),
                         {m: row[m] for m in diag_names}, {"solve": 0.1}, {"solve": 1})
        w.write_frame(int(t), float(t), x)
    w.close(status)


CONFIG = """scene: tiny
cloth:
- name: tiny
  thickness: 0.003
colliders:
- name: body
  shape: mesh
  thickness: 0.0
"""


@pytest.mark.skipif(MPI.COMM_WORLD.rank != 0, reason="serial files; rank 0 checks them")
def test_tiny_garment(tmp_path, capsys):
    g = _script()
    sq = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float) * L
    # pattern: panel A (0-3), panel B (4-7) laid 2 L to the right, triangle C (8-10)
    rest = np.concatenate([sq, sq + [2 * L, 0, 0],
                           [[0.3 * L, 0.5 * L, -0.2 * L], [0.7 * L, 0.5 * L, -0.2 * L],
                            [0.5 * L, 0.5 * L, 0.3 * L]]])
    pat_tri = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7], [8, 9, 10]])
    # B's left edge (4, 7) sewn to A's right edge (1, 2)
    pv = np.array([0, 1, 2, 3, 1, 4, 5, 2, 6, 7, 8])
    welded_tri = pv[pat_tri]
    # at rest: A as cut, B stretched 20 % across (x), C upright through A
    # B from x = L to 2.2 L: 1.2 L wide (20 %)
    x = np.concatenate([sq, [[2.2 * L, 0, 0], [2.2 * L, L, 0]], rest[8:]])
    sew_diag = ["stitch_gap", "kinetic_energy"]
    _write(tmp_path / "g_sewing.h5", rest, pat_tri, [rest], [0.0], sew_diag,
           [[{"step": 7, "time": 0.07, "stitch_gap": 4e-4, "kinetic_energy": 0.0}]],
           {"scene": "tiny", "ranks": 1, "phase": "sewing"})
    drape = ["residual", "window_motion", "stops", "potential_energy", "kinetic_energy"]
    rows = [{"step": k, "time": float(k), "residual": 10.0 / k, "stops": k // 2,
             "window_motion": 0.002 if k == 2 else np.nan, "potential_energy": 0.0,
             "kinetic_energy": 0.0} for k in (1, 2, 3)]
    body = Box([-0.1 * L, -0.1 * L, -L], [0.1 * L, 0.1 * L, 0.001])   # vertex 0 1 mm deep
    _write(tmp_path / "g.h5", _first_rest(rest, pv), welded_tri,
           [x], [3.0], drape, [rows], {"scene": "tiny", "ranks": 1,
                                       "drape_method": "stop_and_go"},
           colliders=[body], arrays={"garment/pattern_vertex": pv,
                                     "garment/seam_lines": np.array([[1, 2]])},
           status="failed")

    row = g.garment_at_rest(str(tmp_path / "g.h5"))
    assert row["pattern"] == 11 and row["welded"] == 9
    assert row["sew_steps"] == 7 and row["sew_time"] == pytest.approx(0.07)
    assert row["stitch_gap"] == pytest.approx(4e-4)
    assert row["iterations"] == 3 and row["stops"] == 1
    assert row["residual"] == pytest.approx(10 / 3) and row["motion"] == pytest.approx(0.002)
    assert row["strain_match"] == "rows equal"
    # B against its own panel: 20 %; the welded rest positions would say it is compressed
    assert row["strain_max"] == pytest.approx(0.2, abs=1e-12)
    (b,) = row["bodies"]
    assert b["d"] == pytest.approx(0.003) and b["min"] == pytest.approx(-0.001, abs=1e-9)
    assert (b["inside"], b["deep"]) == (1, 1)
    assert row["crossings"] == 2          # C through both triangles of A

    # a sewing file alone, a missing one, the table
    (tmp_path / "s_sewing.h5").write_bytes((tmp_path / "g_sewing.h5").read_bytes())
    g.main([str(tmp_path / "g_sewing.h5"), str(tmp_path / "g.h5"),
            str(tmp_path / "s_sewing.h5"), str(tmp_path / "none.h5"), "--markdown"])
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("| file |") and len([r for r in out if r.startswith("| g.h5")]) == 1
    assert any("a sewing file only" in r and "no main file s.h5" in r for r in out)
    assert any(r.endswith("none.h5: no such file") for r in out)


def _first_rest(rest, pv):
    """The welded file's rest positions: each welded vertex's first pattern vertex."""
    first = np.full(pv.max() + 1, pv.size)
    np.minimum.at(first, pv, np.arange(pv.size))
    return rest[first]


def test_principal_strain_rigid_and_shear():
    g = _script()
    rng = np.random.default_rng(1)
    rest = rng.random((50, 3, 3))
    q, _ = np.linalg.qr(rng.standard_normal((3, 3)))
    np.testing.assert_allclose(g.principal_strain(rest, rest @ q.T + 1.0), 0.0, atol=1e-9)
    # simple shear gamma in the plane: principal stretch gamma/2 + sqrt(1 + gamma^2/4)
    flat = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]]], float)
    gamma = 0.3
    sheared = flat.copy()
    sheared[0, 2, 0] = gamma
    expected = gamma / 2 + np.sqrt(1 + gamma ** 2 / 4) - 1
    assert g.principal_strain(flat, sheared)[0] == pytest.approx(expected)
