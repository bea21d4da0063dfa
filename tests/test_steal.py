"""Work stealing in the distributed traversal (distcloth/parallel/steal.py).

* On frozen snapshots of three scenes (two stacked crumpled sheets, a strip
  folded in six layers, a cloth sheet through the torso mesh collider) the
  vertex-face and edge-edge pairs within the thickness equal the serial set
  with stealing off, on (default and fine-grained tasks) and on with random
  injected delays: on the suite's 2 ranks in process, and on 1, 3 and 4
  ranks (oversubscribed) in a child mpiexec.  The total number of tests run
  over the ranks is the same in every mode (the static assignment's, i.e.
  every test ran exactly once).
* Static mode sends no message; a problem owned entirely by rank 0 gets
  stolen from; consecutive phases on one detector never see each other's
  messages (epochs).
* A 30-problem slice of scripts/steal_stress.py (random trees, ownership,
  a, b, chunk, delays) on 3 ranks: no deadlock, lost or duplicated test.
"""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
THICK = 0.004
SCENES = ("sheets", "strip", "torso")
MODES = {
    "static": dict(stealing=False),
    "steal": dict(stealing=True),
    "fine": dict(stealing=True, a=2.0, b=2, chunk=8),
    "delay": dict(stealing=True, a=1.0, b=2, chunk=16,
                  steal_options=dict(delay=5e-4, delay_prob=0.3, seed=5)),
}


def _grid_cfg(name, size, res, center, thickness=THICK):
    from distcloth.config.load import config_from_dict
    raw = {"cloth": [{"name": name, "mesh": {"grid": {"size": size, "resolution": res},
                                             "center": center},
                      "thickness": thickness}],
           "effects": ["gravity", "membrane", "self_collision"],
           "output": {"file": "unused.h5"}}
    return config_from_dict(raw, str(ROOT), name)


def folded(x, length_axis=1, panel=0.08, gap=0.0025, start=None, seed=0, bump=3e-4):
    """Accordion folds: the coordinate along ``length_axis`` beyond ``start``
    is folded into panels of ``panel`` stacked ``gap`` apart (sharp folds),
    plus a small smooth bump field so no two layers are exactly parallel."""
    rng = np.random.default_rng(seed)
    x = np.asarray(x, dtype=np.float64).copy()
    s = x[:, length_axis] - x[:, length_axis].min()
    start = 0.0 if start is None else start
    u = np.maximum(s - start, 0.0)
    k = np.floor(u / panel)
    r = u - k * panel
    along = np.where(k % 2 == 0, r, panel - r)
    fold = s > start
    x[fold, length_axis] = x[:, length_axis].min() + start + along[fold]
    x[fold, 2] += k[fold] * gap
    kk = rng.normal(size=(5, 2)) * 40.0
    ph = rng.uniform(0, 2 * np.pi, 5)
    x[:, 2] += bump * np.sin(x[:, :2] @ kk.T + ph).sum(axis=1) / 5
    return x


def scene(name):
    """(config, snapshot positions of the cloth, mesh colliders)."""
    from distcloth.scene import build_model
    if name == "sheets":
        from test_collision_parallel import _scene, snapshot
        cfg = _scene()
        return cfg, snapshot(build_model(cfg)), []
    if name == "strip":
        cfg = _grid_cfg("strip", [0.08, 0.48], [5, 31], [0.0, 0.0, 0.1])
        return cfg, folded(build_model(cfg).rest_positions), []
    if name == "torso":
        from distcloth.collision.colliders import load_mesh_collider
        cfg = _grid_cfg("cape", [0.5, 0.36], [21, 15], [0.0, 0.0, 0.6])
        x = np.asarray(build_model(cfg).rest_positions, dtype=np.float64).copy()
        x[:, 2] += 0.01 * np.sin(9.0 * x[:, 0]) * np.cos(11.0 * x[:, 1])
        return cfg, x, [load_mesh_collider(str(ROOT / "configs/meshes/torso.obj"))]
    raise ValueError(name)


def _positions(x, colliders):
    return np.concatenate([x] + [c.vertices(0.0) for c in colliders]) if colliders else x


def serial_pairs(name):
    """The reference: one process, one cloth object, run_tests on all root
    tests, then the same narrow phase (no MPI)."""
    from distcloth.collision.geometry import CollisionGeometry
    from distcloth.collision.proximity import edge_edge_contacts, vertex_face_contacts
    from distcloth.collision.traverse import run_tests
    from distcloth.scene import build_model
    cfg, x, colliders = scene(name)
    model = build_model(cfg)
    rest = np.concatenate([model.rest_positions] + [c.vertices(0.0) for c in colliders])
    g = CollisionGeometry(model.triangles, model.num_vertices,
                          np.zeros(len(model.triangles), np.int64), 1,
                          [(c.n_vertices, c.triangles) for c in colliders], rest=rest)
    xx = _positions(x, colliders)
    trees = g.trees(xx, xx, THICK)
    rows = run_tests(trees, g.root_tests(trees, True))
    vf, ee = g.primitive_pairs(g.triangle_pairs(rows), xx, xx, THICK)
    a = vertex_face_contacts(xx, g.tri, vf, THICK)
    b = edge_edge_contacts(xx, g.edges, ee, THICK)
    return (np.stack([a.vertex, a.face], 1).reshape(-1, 2),
            np.stack([b.edge_a, b.edge_b], 1).reshape(-1, 2))


def distributed_pairs(name):
    """Collective: {mode: (vf, ee, total tests, total steals)} of one scene,
    all modes on one detector (consecutive phases)."""
    from distcloth.parallel.collide import build_collisions
    from distcloth.parallel.comm import Comm, partition_on_root
    from distcloth.parallel.partition import build_layout
    from distcloth.scene import build_model
    comm = Comm()
    cfg, x, colliders = scene(name)
    model = build_model(cfg)
    xadj, adjncy = model.matrix_graph()
    part = partition_on_root(comm, xadj, adjncy)
    layout = build_layout(xadj, adjncy, model.spring_vertices, part, comm.rank, comm.size)
    det = build_collisions(comm, model, layout, colliders, self_collision=True)
    xx = _positions(x, colliders)
    out = {}
    for mode, opts in MODES.items():
        det.stealing = opts["stealing"]
        det.a = opts.get("a", 2.0)
        det.b = opts.get("b", 8)
        det.chunk = opts.get("chunk", 256)
        det.steal_options = opts.get("steal_options", {})
        vf, ee = det.proximity_pairs(xx, THICK)
        st = det.last_phase_stats
        tot = comm.sum(np.array([st["tests"], st["tasks_stolen"], st["msgs_sent"]], np.int64))
        out[mode] = (vf, ee, int(tot[0]), int(tot[1]), int(tot[2]))
    return out


@pytest.mark.parametrize("name", SCENES)
def test_pairs_equal_serial_on_suite_ranks(name):
    bvf, bee = serial_pairs(name)
    assert bvf.shape[0] + bee.shape[0] > 50            # the snapshot has many close pairs
    got = distributed_pairs(name)
    tests = {m: got[m][2] for m in MODES}
    for mode, (vf, ee, _, _, msgs) in got.items():
        assert np.array_equal(vf, bvf), mode
        assert np.array_equal(ee, bee), mode
    assert len(set(tests.values())) == 1, tests         # every test ran exactly once
    assert got["static"][4] == 0                        # static: no messages


def test_all_work_on_rank0_gets_stolen():
    from distcloth.collision.bvh import build_from_boxes
    from distcloth.collision.traverse import Forest, canonical, default_root_tests, run_tests
    from distcloth.parallel.comm import Comm
    from distcloth.parallel.steal import run_tasks
    comm = Comm()
    rng = np.random.default_rng(1)
    c = rng.uniform(0, 1, (3000, 3))
    forest = Forest([build_from_boxes(c - 0.03, c + 0.03)])
    tests = default_root_tests(1)
    ref = canonical(run_tests(forest, tests))
    stolen = 0
    for attempt in range(3):                            # consecutive epochs on one communicator
        # rank 0 naps between chunks now and then, so the thieves get their turn
        rows, st = run_tasks(comm, forest, tests, np.zeros(1, np.int64), chunk=64, timeout=60,
                             delay=5e-4, delay_prob=0.2, seed=attempt)
        allrows = np.concatenate(comm.gather_objects(rows))
        assert allrows.shape[0] == ref.shape[0]           # no duplicate
        assert np.array_equal(canonical(allrows), ref)    # nothing lost
        stolen += int(comm.sum(np.array([st["tasks_stolen"]]))[0])
        assert st["wall"] >= st["busy"] >= 0.0 and st["idle"] >= 0.0
    if comm.size > 1:
        assert stolen > 0


def _child(ranks, *args, timeout=240):
    from conftest import clean_env
    cmd = ["mpiexec", "--oversubscribe", "-n", str(ranks), sys.executable, *map(str, args)]
    return subprocess.run(cmd, env=clean_env(), cwd=ROOT, capture_output=True, text=True,
                          timeout=timeout)


@pytest.mark.rank0_only
@pytest.mark.parametrize("ranks", [1, 3, 4])
def test_pairs_equal_serial_on_1_3_4_ranks(tmp_path, ranks):
    out = tmp_path / f"steal{ranks}.npz"
    p = _child(ranks, __file__, out)
    assert p.returncode == 0, p.stderr[-3000:]
    got = np.load(out)
    for name in SCENES:
        bvf, bee = serial_pairs(name)
        tests = set()
        for mode in MODES:
            assert np.array_equal(got[f"{name}/{mode}/vf"], bvf), (name, mode)
            assert np.array_equal(got[f"{name}/{mode}/ee"], bee), (name, mode)
            tests.add(int(got[f"{name}/{mode}/tests"]))
        assert len(tests) == 1, (name, tests)


@pytest.mark.rank0_only
def test_stress_slice():
    p = _child(3, ROOT / "scripts" / "steal_stress.py", "--n", "30", "--seed", "500",
               "--timeout", "60")
    assert p.returncode == 0, (p.stdout[-2000:], p.stderr[-3000:])
    assert "deadlocks 0, lost_tests 0, dup_tests 0, lost_rows 0, dup_rows 0, wrong_rows 0" \
        in p.stdout, p.stdout


if __name__ == "__main__":      # worker: mpiexec -n R python tests/test_steal.py OUT.npz
    from mpi4py import MPI
    sys.path.insert(0, str(ROOT / "tests"))
    arrays = {}
    for name in SCENES:
        for mode, (vf, ee, tests, stolen, msgs) in distributed_pairs(name).items():
            arrays[f"{name}/{mode}/vf"] = vf
            arrays[f"{name}/{mode}/ee"] = ee
            arrays[f"{name}/{mode}/tests"] = tests
    if MPI.COMM_WORLD.Get_rank() == 0:
        np.savez(sys.argv[1], **arrays)
