"""Distributed detection over the replicated BVH (distcloth/parallel/collide.py):
on a frozen snapshot the primitive pairs within the thickness found on any
rank count equal the serial brute-force set, and the self-intersection count
equals the exact oracle's."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
THICK = 0.004


def _scene():
    from distcloth.config.load import config_from_dict
    piece = lambda name, z, shift: {
        "name": name, "mesh": {"grid": {"size": [0.2, 0.2], "resolution": [13, 13],
                                        "pattern": "alternating"},
                               "center": [shift, 0.5 * shift, z]}}
    raw = {"cloth": [piece("a", 0.0, 0.0), piece("b", 0.003, 0.004)],
           "effects": ["gravity", "membrane", "self_collision"],
           "output": {"file": "unused.h5"}}
    return config_from_dict(raw, str(ROOT), "pairs")


def snapshot(model, seed=3):
    """Two stacked sheets, crumpled a little: a smooth random bump field of
    amplitude ~ the gap, so the layers come within the thickness in patches,
    touch in places and pass through each other in a few."""
    rng = np.random.default_rng(seed)
    x = np.asarray(model.rest_positions, dtype=np.float64).copy()
    k = rng.normal(size=(6, 2)) * 25.0
    ph = rng.uniform(0, 2 * np.pi, size=6)
    amp = rng.uniform(0.0005, 0.0015, size=6)
    bump = (amp[None] * np.sin(x[:, :2] @ k.T + ph[None])).sum(axis=1)
    x[:, 2] += bump * np.where(np.arange(x.shape[0]) < x.shape[0] // 2, 1.0, -1.0)
    return x


def brute_force(x, tri, edges):
    from distcloth.collision.proximity import edge_edge_contacts, vertex_face_contacts
    nv, nt, ne = x.shape[0], tri.shape[0], edges.shape[0]
    vf = np.stack(np.meshgrid(np.arange(nv), np.arange(nt), indexing="ij"), -1).reshape(-1, 2)
    i, j = np.triu_indices(ne, 1)
    ee = np.stack([i, j], axis=1)
    a = vertex_face_contacts(x, tri, vf, THICK)
    b = edge_edge_contacts(x, edges, ee, THICK)
    return (np.stack([a.vertex, a.face], 1).reshape(-1, 2),
            np.stack([b.edge_a, b.edge_b], 1).reshape(-1, 2))


def distributed(comm_world=None):
    from distcloth.parallel.comm import Comm, partition_on_root
    from distcloth.parallel.collide import build_collisions
    from distcloth.parallel.partition import build_layout
    from distcloth.scene import build_model
    comm = Comm()
    model = build_model(_scene())
    xadj, adjncy = model.matrix_graph()
    part = partition_on_root(comm, xadj, adjncy)
    layout = build_layout(xadj, adjncy, model.spring_vertices, part, comm.rank, comm.size)
    det = build_collisions(comm, model, layout, self_collision=True)
    x = snapshot(model)
    owned = det.gather(x[layout.owned_input])        # round trip through the all-gather
    assert np.array_equal(owned, x)
    vf, ee = det.proximity_pairs(x, THICK)
    return model, det, x, vf, ee, det.count_intersections(x)


def test_pairs_equal_serial_brute_force():
    from serial_oracles import count_self_intersections
    model, det, x, vf, ee, hits = distributed()
    g = det.geometry
    bvf, bee = brute_force(x, g.tri, g.edges)
    assert bvf.shape[0] > 50 and bee.shape[0] > 50      # the snapshot has many close pairs
    assert np.array_equal(vf, bvf)
    assert np.array_equal(ee, bee)
    assert hits == count_self_intersections(x, g.tri) > 0


def test_shared_ccd_hits_equal_serial():
    # the distributed CCD narrow phase (each rank a block of the candidate
    # rows, hits all-gathered in rank order) gives every rank the serial
    # stencils bitwise: the layers of the snapshot pass through each other
    # when swept from x to a flattened copy
    from distcloth.collision.impulses import clean_pairs, collisions
    model, det, x, vf, ee, hits = distributed()
    g = det.geometry
    x1 = x.copy()
    x1[:, 2] = np.where(np.arange(x.shape[0]) < x.shape[0] // 2, 0.002, 0.0)
    inv = np.ones(x.shape[0])
    cvf, cee = clean_pairs(*det.candidates(x, x1, THICK), g.tri, g.edges, inv)
    want = collisions(x, x1, g.tri, g.edges, cvf, cee, 1e-6)
    got = det.shared_hits(x, x1, g.tri, g.edges, cvf, cee, 1e-6)
    assert want[0].shape[0] > 20
    for a, b in zip(want, got):
        assert a.dtype == b.dtype and np.array_equal(a, b)


@pytest.mark.rank0_only
@pytest.mark.parametrize("ranks", [1, 3])
def test_pairs_independent_of_rank_count(tmp_path, ranks):
    import subprocess
    from conftest import clean_env
    out = tmp_path / f"pairs{ranks}.npz"
    cmd = ["mpiexec", "--oversubscribe", "-n", str(ranks), sys.executable, __file__, str(out)]
    p = subprocess.run(cmd, env=clean_env(), cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr[-3000:]
    got = np.load(out)
    model, det, x, vf, ee, hits = distributed_serial()
    bvf, bee = brute_force(x, det.geometry.tri, det.geometry.edges)
    assert np.array_equal(got["vf"], bvf) and np.array_equal(got["ee"], bee)
    assert int(got["hits"]) > 0


def distributed_serial():
    """The same snapshot's geometry on this process alone (no collectives)."""
    from distcloth.collision.geometry import CollisionGeometry
    from distcloth.scene import build_model

    class _Det:
        pass
    model = build_model(_scene())
    det = _Det()
    det.geometry = CollisionGeometry(model.triangles, model.num_vertices,
                                     np.zeros(len(model.triangles), np.int64), 1)
    return model, det, snapshot(model), None, None, None


if __name__ == "__main__":       # worker: mpiexec -n R python tests/test_collision_parallel.py OUT
    from mpi4py import MPI
    _, _, _, vf, ee, hits = distributed()
    if MPI.COMM_WORLD.Get_rank() == 0:
        np.savez(sys.argv[1], vf=vf, ee=ee, hits=hits)


def _box_pairs_brute_force(g, x0, x1, pad):
    """Every vertex-face and edge-edge pair (not sharing a vertex, not all
    kinematic) whose swept boxes grown by pad overlap, by enumeration."""
    lo, hi = np.minimum(x0, x1) - pad, np.maximum(x0, x1) + pad

    def boxes(ids):                                   # (m, k) vertex ids -> (m, 3) boxes
        return lo[ids].min(axis=1), hi[ids].max(axis=1)

    def overlap(a, b):
        return np.all((a[0][:, None] <= b[1][None]) & (b[0][None] <= a[1][:, None]), axis=2)

    v = np.arange(g.n_vertices)[:, None]
    kin = g.kinematic
    hit = overlap(boxes(v), boxes(g.tri))
    hit &= ~(g.tri[None] == v[:, :, None]).any(axis=2)
    hit &= ~(kin[:, None] & kin[g.tri].all(axis=1)[None])
    vf = np.argwhere(hit)
    hit = np.triu(overlap(boxes(g.edges), boxes(g.edges)), 1)
    a, b = g.edges[:, None, :, None], g.edges[None, :, None, :]
    hit &= ~(a == b).any(axis=(2, 3))
    allkin = kin[g.edges].all(axis=1)
    hit &= ~(allkin[:, None] & allkin[None])
    return vf, np.argwhere(hit)


def test_candidates_equal_box_brute_force():
    """The vertex-face and edge-edge candidates of the traversal (each taken
    from its primitives' owner triangles only) are exactly every pair whose
    swept boxes overlap: two sheets on two ranks' objects and a kinematic
    collider mesh, moving, in any order of the triangle pairs."""
    from distcloth.collision.geometry import CollisionGeometry
    from distcloth.collision.traverse import run_tests
    from distcloth.scene import build_model
    model = build_model(_scene())
    x0 = snapshot(model)
    rng = np.random.default_rng(7)
    body = x0[: x0.shape[0] // 2][::3] + np.array([0.01, 0.0, -0.004])   # a coarse collider
    btri = np.array([[i, i + 1, i + 2] for i in range(0, body.shape[0] - 2, 2)])
    tri = np.asarray(model.triangles, dtype=np.int64)
    owner = (np.arange(tri.shape[0]) * 7) % 2
    rest = np.concatenate([x0, body])
    g = CollisionGeometry(tri, model.num_vertices, owner, 2, [(body.shape[0], btri)], rest=rest)
    x1 = rest + rng.normal(scale=0.002, size=rest.shape)
    trees = g.trees(rest, x1, THICK)
    tp = g.triangle_pairs(run_tests(trees, g.root_tests(trees, True)))
    flip = rng.random(tp.shape[0]) < 0.5
    tp[flip] = tp[flip][:, ::-1]
    vf, ee = g.primitive_pairs(tp[rng.permutation(tp.shape[0])], rest, x1, THICK)
    bvf, bee = _box_pairs_brute_force(g, rest, x1, THICK)
    assert bvf.shape[0] > 1000 and bee.shape[0] > 1000
    assert (vf[:, 0] >= model.num_vertices).any()       # collider vertices against cloth faces
    assert np.array_equal(vf, bvf)
    assert np.array_equal(ee, bee)
