"""Skin-following regions (docs/bodies.md): points attached to a moving
mesh, the band along labelled pattern edges, a cloth region riding a
rigidly moving body and a walking shoulder, a sewn skirt's waistband held
after the weld, and the configuration errors."""
from __future__ import annotations

import h5py
import numpy as np
import pytest
import yaml
from mpi4py import MPI

from conftest import ROOT, run_cli
from test_animated_body import _shoulder_raw
from test_physics import grid_scene, make_sim
from distcloth.body.attachment import attach, follow
from distcloth.collision.colliders import RigidMotion, rotvec_to_matrix
from distcloth.collision.contact import make_collider
from distcloth.collision.mesh_query import MeshProximity
from distcloth.config.load import config_from_dict
from distcloth.config.schema import ConfigError
from distcloth.garment.piece import pattern_piece
from distcloth.parallel.comm import Comm
from distcloth.run import run
from distcloth.scene.skin_follow import pattern_band


def _mesh():
    rng = np.random.default_rng(3)
    x = rng.normal(size=(30, 3))
    tri = np.array([rng.choice(30, 3, replace=False) for _ in range(20)])
    return x, tri, rng


def test_attached_points_move_rigidly_with_a_rigid_mesh():
    x, tri, rng = _mesh()
    face = rng.integers(0, tri.shape[0], 50)
    w = rng.dirichlet(np.ones(3), 50)
    points = rng.normal(size=(50, 3))
    offsets = attach(points, x, tri, face, w)
    # at the attachment: the points themselves (round-off of one frame change)
    assert np.abs(follow(x, tri, face, w, offsets) - points).max() < 1e-13
    R, p = rotvec_to_matrix(np.array([0.3, -1.1, 0.7])), np.array([0.5, -2.0, 1.0])
    moved = follow(x @ R.T + p, tri, face, w, offsets)
    assert np.abs(moved - (points @ R.T + p)).max() < 1e-12


def test_a_stretched_triangle_keeps_the_height_above_it():
    # a unit right triangle in z = 0 stretched 2x along x: a point 5 cm above
    # its centroid stays 5 cm above the stretched triangle's centroid
    x = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    tri = np.array([[0, 1, 2]])
    w = np.full((1, 3), 1 / 3)
    offsets = attach(np.array([[1 / 3, 1 / 3, 0.05]]), x, tri, np.array([0]), w)
    y = follow(x * [2.0, 1.0, 1.0], tri, np.array([0]), w, offsets)
    assert np.allclose(y, [[2 / 3, 1 / 3, 0.05]], atol=1e-15)


def test_the_band_along_labelled_edges():
    piece = pattern_piece(str(ROOT / "configs/garments/skirt.yaml"), 0.03)
    band = pattern_band(piece, ["waist"], 0.03, "key")
    wider = pattern_band(piece, ["waist"], 0.08, "key")
    assert band.size and set(band) < set(wider)
    for pm in piece.mesh.panels:
        edges = {e.label: k for k, e in enumerate(pm.panel.edges)}
        waist = pm.edge_vertices[edges["waist"]] + pm.offset
        hem = pm.edge_vertices[edges["hem"]] + pm.offset
        assert np.isin(waist, band).all()
        assert not np.isin(hem, wider).any()
        # the skirt's panels are 51 cm tall, the waist at the top: the band is
        # the vertices within 3 cm of it (its centre dips 0.5 to 1 cm)
        v = pm.vertices[np.intersect1d(band, np.arange(pm.vertices.shape[0]) + pm.offset)
                        - pm.offset]
        assert v[:, 1].min() > 0.51 - 0.03 - 0.011
    with pytest.raises(ConfigError, match="hem, side, waist"):
        pattern_band(piece, ["belt"], 0.03, "cloth.0.follow_skin.edges")


def test_a_region_rides_a_rigidly_moving_body(comm):
    # a cloth lying on a torso that turns and shifts: the vertices within
    # 5 cm of it where the run starts are moved exactly as the body's rigid
    # motion moves them, at every step, while the rest is simulated
    times, shifts, turns = [0.0, 0.1], [[0, 0, 0], [0.03, 0.0, 0.01]], [[0, 0, 0], [0, 0, 0.4]]
    raw = grid_scene(
        cloth=[{"name": "c", "mesh": {"grid": {"size": [0.6, 0.6], "resolution": [13, 13]},
                                      "center": [0.0, 0.0, 0.72]},
                "material": {"model": "fem", "density": 0.15, "stretch": 100.0, "bending": 1e-5,
                             "damping": 0.002},
                "thickness": 0.003, "follow_skin": {"within": 0.05}}],
        effects=["gravity", "membrane", "bending", "damping", "collisions"],
        colliders=[{"name": "body", "shape": "mesh", "friction": 0.4,
                    "file": str(ROOT / "configs/meshes/torso.obj"),
                    "motion": {"times": times, "translations": shifts, "rotations": turns}}],
        time={"end": 0.15, "step": 0.005})
    sim = make_sim(raw, comm=comm)
    grip = sim.model.grips[-1]
    assert grip.name == "c.follow_skin"
    # the region is what the body reaches: some vertices, not all
    assert 0 < grip.vertices.size < 13 * 13 // 2
    local = sim.layout.input_to_local()[grip.vertices]
    mine = local[(local >= 0) & (local < sim.n_owned)]
    inputs = sim.layout.local_input[mine]
    x0 = sim.model.start_positions()[inputs]
    motion = RigidMotion(times, shifts, turns)
    free = np.setdiff1d(np.arange(sim.n_owned), mine)
    moved = 0.0
    for _ in range(30):
        sim.step()
        R, p = motion.transform(sim.state.t)
        # round-off of the attachment frames and of the velocity-change solve;
        # a rank may own no region vertex, or no other (three ranks): initial=0
        assert np.abs(sim.state.x[mine] - (x0 @ R.T + p)).max(initial=0.0) < 1e-10
        moved = max(moved, float(np.abs(sim.state.x[free]
                                        - sim.model.start_positions()[
                                            sim.layout.local_input[free]]).max(initial=0.0)))
    # the rest fell and slid: simulated, not held
    assert comm.allreduce(moved, op=MPI.MAX) > 0.01
    sim.destroy()


def test_a_region_keeps_its_height_on_the_walking_shoulder(shared_tmp, comm):
    # the cloth dropped on the walking shoulder, its vertices within 5 cm of
    # the skin where it starts following it: an independent signed-distance
    # check finds each of them at its start distance from the moving skin
    # (to 0.05 mm: the skinned triangles stretch and turn under them, and
    # the closest point moves with them), while they travel 30 cm
    raw = _shoulder_raw(shared_tmp / "out.h5", end=0.3)
    raw["cloth"][0]["follow_skin"] = {"within": 0.05}
    cfg = config_from_dict(raw, str(shared_tmp), "scene.yaml")
    assert run(cfg, Comm(comm), quiet=True, progress=False) == 0
    with h5py.File(shared_tmp / "out.h5", "r") as f:
        assert f.attrs["status"] == "completed"
        assert list(f.attrs["grips"]) == ["cloth.follow_skin"]
        x, t = f["frames/positions"][:], f["frames/time"][:]
    prox = MeshProximity(make_collider(cfg.colliders[0], True).body)
    phi0, _, _ = prox.query(x[0], t[0], 1.0)
    region = np.flatnonzero(phi0 <= 0.05)
    assert region.size > 5
    for xk, tk in zip(x[1:], t[1:]):
        phi, _, _ = prox.query(xk, tk, 1.0)
        assert np.abs(phi[region] - phi0[region]).max() < 5e-5
    assert np.linalg.norm(x[-1, region] - x[0, region], axis=1).max() > 0.2


def test_a_sewn_waistband_is_held_from_the_weld(shared_tmp, comm):
    # the project's skirt on the resting body, its waist band following the
    # body from the weld: from then on the band does not move while the rest
    # of the skirt falls onto the hips
    with open(ROOT / "configs/skirt_on_body.yaml") as fh:
        raw = yaml.safe_load(fh)
    raw["cloth"][0]["follow_skin"] = {"edges": ["waist"], "band": 0.03, "within": 0.02}
    raw["time"]["end"] = 0.6
    raw["output"] = {"file": str(shared_tmp / "skirt.h5"), "every": 0.05, "preview": False}
    cfg = config_from_dict(raw, str(ROOT / "configs"), "skirt.yaml")
    assert run(cfg, Comm(comm), quiet=True, progress=False) == 0
    with h5py.File(shared_tmp / "skirt.h5", "r") as f:
        assert f.attrs["status"] == "completed"
        assert "skirt.follow_skin" in list(f.attrs["grips"])
        x = f["frames/positions"][:]
    still = np.linalg.norm(x[-1] - x[0], axis=1)
    held = still < 1e-9         # round-off of the attachment frames and the solve
    # the band's vertices close to the body: a ring round the waist (z up)
    assert 20 < held.sum() < 0.3 * x.shape[1]
    assert x[0, held, 2].min() > x[0, :, 2].max() - 0.06
    assert still[~held].max() > 0.005


@pytest.mark.rank0_only
@pytest.mark.parametrize("command, setting, key", [
    ("run", "cloth.0.follow_skin.edges=[waist]", "cloth.0.follow_skin.edges"),
    ("run", "cloth.0.follow_skin.collider=nobody", "cloth.0.follow_skin.collider"),
    ("run", "cloth.0.follow_skin.within=0.001", "cloth.0.follow_skin.within"),
    ("drape", "cloth.0.follow_skin.within=0.05", "cloth.0.follow_skin"),
])
def test_bad_regions_exit_2_before_work(tmp_path, command, setting, key):
    out = tmp_path / "out.h5"
    raw = _shoulder_raw(out)
    raw["cloth"][0]["follow_skin"] = {"within": 0.05}
    scene = tmp_path / "scene.yaml"
    scene.write_text(yaml.safe_dump(raw))
    p = run_cli([command, scene, "--set", setting], ranks=2, timeout=300)
    assert p.returncode == 2, (p.returncode, p.stderr)
    lines = [ln for ln in p.stderr.splitlines() if ln.startswith("distcloth: config error")]
    assert len(lines) == 1 and key in lines[0], p.stderr
    assert "Traceback" not in p.stderr and not out.exists()
