"""Sewing and welding garments: the weld's bookkeeping, the rest shape a
welded garment keeps, the sewing phase end to end, rank invariance over it,
and seam shrinkage (pucker)."""
from __future__ import annotations

import h5py
import numpy as np
import pytest
import yaml
from mpi4py import MPI
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from conftest import run_cli
from distcloth.config.load import config_from_dict
from distcloth.garment.weld import canonical_vertex, hinge_triangles, unfold_hinges, weld_groups
from distcloth.parallel.comm import Comm
from distcloth.physics.bending import hinge_angles, hinges
from distcloth.run import run
from distcloth.scene import build_model
from distcloth.simulation import Simulation


def two_panels(tmp, gap=0.04, width=0.2, height=0.2):
    """Two rectangles side by side in the z = 0 plane, ``gap`` apart, their
    facing sides sewn (b's left side walked backwards meets a's right side)."""
    pattern = {"units_in_meter": 1, "panels": {
        "a": {"vertices": [[0, 0], [width, 0], [width, height], [0, height]]},
        "b": {"vertices": [[0, 0], [width, 0], [width, height], [0, height]],
              "translation": [width + gap, 0, 0]}},
        "seams": [["a:1", "b:3"]]}
    path = tmp / "two.yaml"
    path.write_text(yaml.safe_dump(pattern, sort_keys=False))
    return path


def scene(tmp, pattern, **over):
    raw = {"scene": "sewing", "cloth": [{
        "name": "g", "mesh": {"pattern": str(pattern), "edge_length": 0.025, "up_axis": "z"},
        "material": {"model": "fem", "density": 0.15, "stretch": 500.0, "bending": 1e-5,
                     "damping": 0.001, "bending_model": "dihedral"},
        "thickness": 0.002}],
        "effects": ["gravity", "membrane", "bending", "damping", "self_collision"],
        "time": {"end": 0.3, "step": 0.01, "integrator": "backward_euler"},
        "solver": {"ksp_rtol": 1e-10},
        "garment": {"sewing": {"duration": 0.1, "max_duration": 0.6}},
        "output": {"file": str(tmp / "out.h5"), "every": 0.05, "preview": False}}
    for key, value in over.items():
        raw[key] = value
    return raw


def test_weld_groups_follow_chains_and_keep_order():
    # 0-3 and 3-5 join three vertices; 6 is a dart tip sewn to itself
    new_of, first = weld_groups(7, np.array([[0, 3], [5, 3], [6, 6]]))
    assert new_of.tolist() == [0, 1, 2, 0, 3, 0, 4]
    assert first.tolist() == [0, 1, 2, 4, 6]
    assert canonical_vertex(7, np.array([[5, 3], [0, 3]])).tolist() == [0, 1, 2, 0, 4, 0, 6]


def test_unfolded_hinge_is_flat_and_keeps_both_triangles():
    # two triangles of different panels (rest corners far apart in space,
    # rotated differently) sharing a welded edge: unfolded flat, each keeps
    # its own shape (edge lengths to round-off)
    tri = np.array([[0, 1, 2], [1, 0, 3]])
    rest = np.array([[[0, 0, 0], [1, 0, 0], [0.3, 0.8, 0]],
                     [[5, 5, 5], [5, 5, 4], [5.6, 5, 4.5]]], dtype=float)   # B: edge 1 -> 0
    hinge, ta, ha, tb, hb = hinge_triangles(tri)
    assert np.array_equal(hinge, hinges(tri))
    pts = unfold_hinges(rest, ta, ha, tb, hb)
    x = pts.reshape(-1, 3)
    assert abs(hinge_angles(x, np.arange(4).reshape(1, 4))[0]) < 1e-12
    b = rest[1]
    for (i, j), (p, q) in (((0, 3), (1, 2)), ((1, 3), (0, 2))):
        assert abs(np.linalg.norm(x[i] - x[j]) - np.linalg.norm(b[p] - b[q])) < 1e-12
    assert np.cross(x[1] - x[0], x[2] - x[0])[2] * np.cross(x[3] - x[0], x[1] - x[0])[2] > 0


def test_coincident_seam_welds_at_once_into_a_flat_sheet_at_rest(tmp_path):
    # panels touching along the seam: every pair is closed at the start, so the
    # weld comes after the first sewing step; the welded sheet is one piece,
    # lies flat and has no elastic energy (its rest shape is the panels' own)
    comm = Comm(MPI.COMM_WORLD)
    pattern = two_panels(tmp_path if comm.rank == 0 else tmp_path, gap=0.0)
    raw = scene(tmp_path, pattern, effects=["membrane", "bending"])
    cfg = config_from_dict(raw, str(tmp_path), "sewing.yaml")
    model = build_model(cfg)
    pairs = model.stitch_pairs
    assert pairs.shape[0] == 9 and np.all(model.stitch_gap < 1e-12)
    from distcloth.sew import weld     # the driver's own weld, on this run's ranks
    sim = Simulation(cfg, model, comm, quiet=True)
    sim.prepare()
    welded = weld(sim, cfg, comm, quiet=True)
    m = welded.model
    assert m.num_vertices == model.num_vertices - pairs.shape[0]
    assert m.triangles.shape[0] == model.triangles.shape[0]
    graph = coo_matrix((np.ones(m.spring_vertices.shape[0]),
                        tuple(m.spring_vertices.T)), shape=(m.num_vertices,) * 2)
    assert connected_components(graph, directed=False)[0] == 1
    assert m.pattern_vertex.shape == (model.num_vertices,)
    assert np.array_equal(m.pattern_vertex[pairs[:, 0]], m.pattern_vertex[pairs[:, 1]])
    assert m.seam_lines.shape[0] == pairs.shape[0] - 1
    # elastic energy of the welded sheet where it lies: membrane, seam strip and
    # bending all at rest (round-off of a few hundred terms of ~1e-3 J scale)
    _, elastic = welded.potential_energies()
    assert abs(elastic) < 1e-12, elastic
    welded.destroy()


def test_sewing_closes_the_seam_and_the_run_goes_on_welded(tmp_path, comm):
    # a 4 cm gap closed over 0.1 s (no gravity while sewing): every pair within
    # the 1 mm tolerance, one connected garment after, and the main file maps
    # every pattern vertex to a simulated one
    shared = comm.bcast(str(tmp_path), root=0)
    from pathlib import Path
    shared = Path(shared)
    pattern = two_panels(shared) if comm.rank == 0 else shared / "two.yaml"
    comm.barrier()
    raw = scene(shared, pattern)
    cfg = config_from_dict(raw, str(shared), "sewing.yaml")
    assert run(cfg, Comm(comm), quiet=True, progress=False) == 0
    with h5py.File(shared / "out_sewing.h5", "r") as f:
        assert f.attrs["status"] == "completed"
        gap = f["diagnostics/stitch_gap"][:]
        assert gap[-1] <= 1e-3 and gap[0] > 0.03
        n_pattern = f["frames/positions"].shape[1]
    with h5py.File(shared / "out.h5", "r") as f:
        assert f.attrs["status"] == "completed"
        pv = f["garment/pattern_vertex"][:]
        n = f["frames/positions"].shape[1]
        tri = f["mesh/triangles"][:]
    assert pv.shape == (n_pattern,) and n == n_pattern - 9 and pv.max() == n - 1
    edges = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]]])
    graph = coo_matrix((np.ones(edges.shape[0]), tuple(edges.T)), shape=(n, n))
    assert connected_components(graph, directed=False)[0] == 1


@pytest.mark.rank0_only
def test_sewing_agrees_on_one_two_and_three_ranks(tmp_path):
    # the whole sewing phase (stitch springs, self-collision, weld) on 1, 2 and
    # 3 ranks: the frames agree to 1e-7 m, the solver's tolerance (CG to 1e-10
    # relative; the ranks' block-Jacobi preconditioners differ, so the
    # iterates differ at that level) amplified by a few dozen steps
    pattern = two_panels(tmp_path)
    frames = []
    for ranks in (1, 2, 3):
        raw = scene(tmp_path, pattern)
        raw["output"]["file"] = f"r{ranks}.h5"
        path = tmp_path / f"s{ranks}.yaml"
        path.write_text(yaml.safe_dump(raw))
        proc = run_cli(["run", path, "--quiet"], ranks=ranks, cwd=tmp_path)
        assert proc.returncode == 0, proc.stderr[-2000:]
        with h5py.File(tmp_path / f"r{ranks}_sewing.h5", "r") as f:
            frames.append(f["frames/positions"][:])
        with h5py.File(tmp_path / f"r{ranks}.h5", "r") as f:
            frames[-1] = (frames[-1], f["frames/positions"][:])
    for sew, main in frames[1:]:
        assert sew.shape == frames[0][0].shape and main.shape == frames[0][1].shape
        assert np.abs(sew - frames[0][0]).max() < 1e-7
        assert np.abs(main - frames[0][1]).max() < 1e-7


def test_shrunk_seam_puckers_and_an_unshrunk_one_stays_flat(tmp_path, comm):
    # two 30 x 12 cm rectangles sewn along their long sides, no gravity, a
    # 0.1 mm seeded noise to break the symmetry, 1 s: with 5 % shrinkage the
    # seam line buckles out of plane (measured: amplitude 4.1 mm, wavelength
    # 9 cm, scripts/pucker_study.py); with 0 % it stays within the noise
    # (measured 0.05 mm).  Bounds: 2 mm, half the measured amplitude (the
    # buckling mode depends on the noise and the partition's round-off), and
    # 0.5 mm, five times the noise
    from pathlib import Path
    from distcloth.garment.pucker import pucker_pattern, pucker_scene, seam_waves
    shared = Path(comm.bcast(str(tmp_path), root=0))
    if comm.rank == 0:
        (shared / "p.yaml").write_text(yaml.safe_dump(pucker_pattern(), sort_keys=False))
    comm.barrier()
    waves = {}
    for shrinkage in (0.0, 0.05):
        out = shared / f"o{shrinkage}.h5"
        cfg = config_from_dict(pucker_scene(str(shared / "p.yaml"), shrinkage, str(out)),
                               str(shared), "p.yaml")
        assert run(cfg, Comm(comm), quiet=True, progress=False) == 0
        with h5py.File(out, "r") as f:
            x = f["frames/positions"][-1]
            seam = np.unique(f["garment/seam_lines"][:])
        waves[shrinkage] = seam_waves(x, seam[np.argsort(x[seam, 1])])
    assert waves[0.05][0] > 2e-3, waves
    assert waves[0.0][0] < 5e-4, waves
    assert np.isfinite(waves[0.05][1]) and waves[0.05][1] < 0.3, waves


def test_friction_is_scaled_while_sewing_only(tmp_path, comm):
    # panels slide into place while sewn (garment.sewing.friction of the
    # colliders' mu), the welded garment meets the full mu
    shared = comm.bcast(str(tmp_path), root=0)
    from pathlib import Path
    shared = Path(shared)
    pattern = two_panels(shared) if comm.rank == 0 else shared / "two.yaml"
    comm.barrier()
    raw = scene(shared, pattern,
                effects=["gravity", "membrane", "bending", "collisions"],
                colliders=[{"name": "floor", "shape": "plane", "offset": -0.05,
                            "normal": [0, 0, 1], "friction": 0.4}])
    raw["garment"]["sewing"]["friction"] = 0.25
    cfg = config_from_dict(raw, str(shared), "sewing.yaml")
    model = build_model(cfg)
    sim = Simulation(cfg, model, Comm(comm), quiet=True)
    assert sim.contact.colliders[0].friction == pytest.approx(0.1, rel=1e-15)
    sim.destroy()
    model.stitch_pairs = None          # as the welded model has none
    sim = Simulation(cfg, model, Comm(comm), quiet=True)
    assert sim.contact.colliders[0].friction == 0.4
    sim.destroy()


def test_outer_layers_are_sewn_after_the_inner_ones():
    # layer k's stitch ramp runs over [k d, (k + 1) d]: before it the pair keeps
    # its start gap, after it the rest length is zero
    from distcloth.physics.sewing import StitchTerm
    term = StitchTerm(np.array([[0, 1], [2, 3]]), np.array([0.2, 0.4]), 1000.0, 0.5,
                      np.ones(2), np.ones(2, dtype=bool), start=np.array([0.0, 0.5]))
    for t, rest in ((0.0, [0.2, 0.4]), (0.25, [0.1, 0.4]), (0.5, [0.0, 0.4]),
                    (0.75, [0.0, 0.2]), (1.0, [0.0, 0.0]), (2.0, [0.0, 0.0])):
        term.at_time(t)
        assert term.rest == pytest.approx(rest, abs=1e-15), t
