"""METIS partitioning and the per-rank layout (EG07 tutorial, Part 1 §5.4-5.5).

Pure serial: every test builds the layouts of all ranks of a given size in one
process and checks them against expectations computed independently from the
spring list, so it passes run on any number of MPI ranks at once.
"""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.spatial import Delaunay

from distcloth.model import Model
from distcloth.parallel.metis import part_graph_kway
from distcloth.parallel.partition import build_layout, describe_partition, partition_vertices


# ---------------------------------------------------------------- graphs

def grid_springs(nu: int, nv: int) -> np.ndarray:
    """Mass-spring grid (row-major, vertex = j*nu + i): structural springs to the
    right and up, shear along both quad diagonals, flexion two apart."""
    idx = np.arange(nu * nv).reshape(nv, nu)
    pairs = [
        (idx[:, :-1], idx[:, 1:]),        # structural, along u
        (idx[:-1, :], idx[1:, :]),        # structural, along v
        (idx[:-1, :-1], idx[1:, 1:]),     # shear, one diagonal
        (idx[:-1, 1:], idx[1:, :-1]),     # shear, the other
        (idx[:, :-2], idx[:, 2:]),        # flexion, along u
        (idx[:-2, :], idx[2:, :]),        # flexion, along v
    ]
    return np.concatenate([np.c_[a.ravel(), b.ravel()] for a, b in pairs]).astype(np.int64)


def delaunay_springs(n: int, seed: int = 1) -> np.ndarray:
    """Edges of a Delaunay triangulation of random points (each edge once)."""
    points = np.random.default_rng(seed).random((n, 2))
    tri = Delaunay(points).simplices
    edges = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    return np.unique(np.sort(edges, axis=1), axis=0).astype(np.int64)


def graph_of(springs: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Symmetric CSR adjacency of the springs via scipy (independent of Model)."""
    i, j = springs[:, 0], springs[:, 1]
    ones = np.ones(2 * len(springs))
    a = sp.coo_matrix((ones, (np.r_[i, j], np.r_[j, i])), shape=(n, n)).tocsr()
    a.sum_duplicates()
    a.sort_indices()
    return a.indptr.astype(np.int64), a.indices.astype(np.int64)


def cut_edges(springs: np.ndarray, part: np.ndarray) -> int:
    undirected = np.unique(np.sort(springs, axis=1), axis=0)
    return int(np.count_nonzero(part[undirected[:, 0]] != part[undirected[:, 1]]))


GRAPHS = {
    "grid60x45": (60 * 45, grid_springs(60, 45)),
    "delaunay": (1500, delaunay_springs(1500)),
}


@pytest.fixture(params=list(GRAPHS))
def graph(request):
    n, springs = GRAPHS[request.param]
    xadj, adjncy = graph_of(springs, n)
    return n, springs, xadj, adjncy


# ---------------------------------------------------------------- METIS

@pytest.mark.parametrize("nparts", [2, 3, 4, 7])
def test_metis_partition_is_balanced_and_reports_its_cut(graph, nparts):
    n, springs, xadj, adjncy = graph
    part = partition_vertices(xadj, adjncy, nparts, seed=0)
    assert part.dtype == np.int32 and part.shape == (n,)
    counts = np.bincount(part, minlength=nparts)
    assert counts.shape == (nparts,) and counts.min() > 0
    assert counts.max() / counts.mean() - 1 <= 0.05

    # a real partition, far better than a random one (which cuts ~(1-1/k) of the
    # edges; the Delaunay points are in random order, so input-order blocks are too)
    assert cut_edges(springs, part) < 0.25 * len(np.unique(np.sort(springs, axis=1), axis=0))

    raw, objval = part_graph_kway(xadj, adjncy, nparts, seed=0)
    assert objval == cut_edges(springs, raw)


def test_metis_is_deterministic(graph):
    n, springs, xadj, adjncy = graph
    first = partition_vertices(xadj, adjncy, 4, seed=3)
    second = partition_vertices(xadj, adjncy, 4, seed=3)
    np.testing.assert_array_equal(first, second)


def test_metis_single_part_and_bad_input():
    xadj, adjncy = graph_of(grid_springs(4, 3), 12)
    part, cut = part_graph_kway(xadj, adjncy, 1)
    assert cut == 0 and np.array_equal(part, np.zeros(12, np.int32))
    with pytest.raises(ValueError):
        part_graph_kway(np.array([0, 1, 2]), np.array([5, 0]), 2)   # neighbour out of range
    with pytest.raises(ValueError):
        part_graph_kway(xadj, adjncy, 13)                           # more parts than vertices


def test_tiny_graph_still_gets_every_rank_some_vertices():
    # METIS leaves parts empty on a 2x2 grid split 4 ways
    xadj, adjncy = graph_of(grid_springs(2, 2), 4)
    part = partition_vertices(xadj, adjncy, 4)
    assert sorted(part.tolist()) == [0, 1, 2, 3]


# ---------------------------------------------------------------- layout

def all_layouts(xadj, adjncy, springs, part, size):
    return [build_layout(xadj, adjncy, springs, part, r, size) for r in range(size)]


@pytest.mark.parametrize("size", [2, 3, 4, 7])
def test_layouts_of_all_ranks_fit_together(graph, size):
    n, springs, xadj, adjncy = graph
    part = partition_vertices(xadj, adjncy, size, seed=0)
    layouts = all_layouts(xadj, adjncy, springs, part, size)

    # independent neighbour facts from the spring list
    s0, s1 = springs[:, 0], springs[:, 1]
    crossing = part[s0] != part[s1]
    has_offrank_neighbour = np.zeros(n, bool)
    has_offrank_neighbour[s0[crossing]] = True
    has_offrank_neighbour[s1[crossing]] = True
    counts = np.bincount(part, minlength=size)

    owned_all = np.concatenate([lay.owned_input for lay in layouts])
    np.testing.assert_array_equal(np.sort(owned_all), np.arange(n))   # each vertex owned once

    expected_ownership = np.r_[0, np.cumsum(counts)]
    springs_seen = np.zeros(len(springs), int)
    for r, lay in enumerate(layouts):
        assert lay.rank == r and lay.size == size
        np.testing.assert_array_equal(lay.ownership, expected_ownership)
        np.testing.assert_array_equal(lay.input_to_global, layouts[0].input_to_global)
        assert np.all(part[lay.owned_input] == r)
        # global rows contiguous per rank, in local order
        np.testing.assert_array_equal(lay.input_to_global[lay.owned_input],
                                      np.arange(lay.global_start, lay.global_stop))

        internal = lay.owned_input[:lay.n_internal]
        interface = lay.owned_input[lay.n_internal:]
        assert not has_offrank_neighbour[internal].any()
        assert has_offrank_neighbour[interface].all()
        assert np.all(np.diff(internal) > 0) and np.all(np.diff(interface) > 0)
        assert lay.n_interface == len(interface) > 0

        # ghosts: exactly the off-rank spring partners of owned vertices
        mine0, mine1 = part[s0] == r, part[s1] == r
        expected_ghosts = np.union1d(s1[mine0 & ~mine1], s0[mine1 & ~mine0])
        np.testing.assert_array_equal(np.sort(lay.ghost_input), expected_ghosts)
        assert np.all(np.diff(lay.input_to_global[lay.ghost_input]) > 0)

        # local springs: those touching an owned vertex, mapped back exactly
        np.testing.assert_array_equal(lay.local_spring_ids, np.flatnonzero(mine0 | mine1))
        assert lay.local_springs.min() >= 0 and lay.local_springs.max() < lay.n_local
        np.testing.assert_array_equal(lay.local_input[lay.local_springs],
                                      springs[lay.local_spring_ids])
        np.testing.assert_array_equal(lay.local_to_global[lay.local_springs],
                                      lay.input_to_global[springs[lay.local_spring_ids]])
        springs_seen[lay.local_spring_ids] += 1

        assert lay.edge_cut == cut_edges(springs, part)
        assert lay.imbalance == pytest.approx(counts.max() / counts.mean() - 1)
        line = describe_partition(lay)
        assert "\n" not in line and f"{size} ranks" in line and f"edge cut {lay.edge_cut}" in line

    # a cut spring lives on both its ranks, every other spring on one
    np.testing.assert_array_equal(springs_seen, np.where(crossing, 2, 1))


def test_layout_by_hand_on_a_chain():
    # path 0-1-2-3-4-5 split by hand: rank 1 holds both ends, rank 0 the middle
    springs = np.array([[0, 1], [1, 2], [2, 3], [3, 4], [4, 5]])
    xadj, adjncy = graph_of(springs, 6)
    part = np.array([1, 1, 0, 0, 1, 1], dtype=np.int32)
    l0, l1 = all_layouts(xadj, adjncy, springs, part, 2)

    assert l0.owned_input.tolist() == [2, 3] and l0.n_internal == 0
    assert l1.owned_input.tolist() == [0, 5, 1, 4] and l1.n_internal == 2
    assert l0.ownership.tolist() == [0, 2, 6]
    assert l0.input_to_global.tolist() == [2, 4, 0, 1, 5, 3]
    assert l0.ghost_input.tolist() == [1, 4] and l1.ghost_input.tolist() == [2, 3]
    assert l0.local_spring_ids.tolist() == [1, 2, 3]
    assert l0.local_springs.tolist() == [[2, 0], [0, 1], [1, 3]]
    assert l1.local_spring_ids.tolist() == [0, 1, 3, 4]
    assert l1.local_springs.tolist() == [[0, 2], [2, 4], [5, 3], [3, 1]]
    assert l0.edge_cut == 2 and l0.imbalance == pytest.approx(4 / 3 - 1)
    assert l1.input_to_local().tolist() == [0, 2, 4, 5, 3, 1]


def test_single_rank_has_no_interface_and_no_ghosts(graph):
    n, springs, xadj, adjncy = graph
    part = partition_vertices(xadj, adjncy, 1)
    (lay,) = all_layouts(xadj, adjncy, springs, part, 1)
    assert lay.n_internal == lay.n_owned == n and lay.n_ghost == 0
    np.testing.assert_array_equal(lay.owned_input, np.arange(n))
    np.testing.assert_array_equal(lay.input_to_global, np.arange(n))
    np.testing.assert_array_equal(lay.local_springs, springs)
    assert lay.edge_cut == 0 and lay.imbalance == 0.0


def test_layout_refuses_inconsistent_input():
    springs = grid_springs(4, 3)
    xadj, adjncy = graph_of(springs[:10], 12)          # graph missing most springs
    part = (np.arange(12) >= 6).astype(np.int32)
    with pytest.raises(ValueError):
        build_layout(xadj, adjncy, springs, part, 0, 2)
    with pytest.raises(ValueError):
        build_layout(xadj, adjncy, springs[:10], part + 1, 0, 2)   # rank 2 of 2


def test_model_matrix_graph_matches_the_springs():
    nu, nv = 7, 5
    n = nu * nv
    springs = grid_springs(nu, nv)
    ns = len(springs)
    model = Model(
        rest_positions=np.zeros((n, 3)), triangles=np.zeros((0, 3), np.int64),
        vertex_mass=np.ones(n), vertex_area=np.ones(n), spring_vertices=springs,
        spring_rest_length=np.ones(ns), spring_stiffness=np.ones(ns),
        spring_damping=np.zeros(ns), spring_kind=np.zeros(ns, np.int8),
        pinned=np.zeros(0, np.int64))
    xadj, adjncy = model.matrix_graph()
    expected_xadj, expected_adjncy = graph_of(springs, n)
    np.testing.assert_array_equal(xadj, expected_xadj)
    np.testing.assert_array_equal(adjncy, expected_adjncy)
    # an interior grid vertex: 8 neighbours in the 3x3 block + 4 flexion partners
    assert xadj[2 * nu + 3 + 1] - xadj[2 * nu + 3] == 12
