"""Coincident vertices of a mesh file welded into one.

Exporters split a vertex wherever its UVs or normals differ (every OBJ or
glTF seam): the positions are equal but the triangles on either side no
longer share it, and the cloth would tear along the seam.  Vertices closer
than the tolerance become one (the lowest file index of each group keeps
its place in the order); what is left in several disconnected parts is
counted so that the caller can report it.
"""
from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree


def weld_coincident(vertices: np.ndarray, triangles: np.ndarray, tolerance: float):
    """(vertices, triangles, new index of every file vertex, vertices merged away)."""
    n = vertices.shape[0]
    pairs = cKDTree(vertices).query_pairs(tolerance, output_type="ndarray")
    if pairs.shape[0] == 0:
        return vertices, triangles, np.arange(n), 0
    graph = coo_matrix((np.ones(pairs.shape[0]), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    _, group = connected_components(graph, directed=False)
    # the first file vertex of each group represents it
    first = np.full(group.max() + 1, n, dtype=np.int64)
    np.minimum.at(first, group, np.arange(n))
    keep = np.sort(first)
    new_of_kept = np.empty(n, dtype=np.int64)
    new_of_kept[keep] = np.arange(keep.shape[0])
    file_index = new_of_kept[first[group]]
    return vertices[keep], file_index[triangles], file_index, n - keep.shape[0]


def count_parts(n: int, triangles: np.ndarray) -> int:
    """Connected parts of a triangle mesh of ``n`` vertices (through shared vertices)."""
    a = np.concatenate([triangles[:, 0], triangles[:, 1]])
    b = np.concatenate([triangles[:, 1], triangles[:, 2]])
    graph = coo_matrix((np.ones(a.shape[0]), (a, b)), shape=(n, n))
    return int(connected_components(graph, directed=False)[0])
