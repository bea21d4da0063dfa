"""Garments worn in layers: the layers under a garment as a collider of the solve.

Between layers the triangle pipeline alone used to keep an outer garment
outside an inner one, after a solve that did not see the inner layer: a
skirt lying on a dress, pressed onto it by its own tension, was moved
through the dress by every solve and put back by the pipeline's impulses,
which move a vertex without its neighbours, so each step left elastic energy
behind (0.2 to 1 J a step on the dress under the overskirt, the energy
guard halving most steps).  A garment lies on the ones under it as the
innermost lies on the body, so it meets them the same way: each outer
vertex near the surface of the layers under it is a contact of the solve
(Baraff and Witkin 1998 §5, the body's constraint S = I - n n^T with the
surface's normal velocity), the surface being the inner layers' triangles
where the step starts, moving with their start velocities through the step.

One way, as the pipeline's rule between layers (``impulses.pair_weights``):
the inner layer is an obstacle that is not pushed back, so a stack is
resolved from the body outwards.  The distance is signed by the side the
triangles face: a garment's triangles are counter-clockwise seen from its
outside (garment/mesh.py), so an outer layer belongs on their front, and a
vertex that a solve carries through the layer under it ends at phi < 0,
which the driver sees as a missed contact and solves again (two-sided, it
would end at phi > d on the wrong side, unseen, and the triangle pipeline
would put it back after every solve: the overskirt's vertices moved 10 to
17 mm in and out a step that way).  Where the closest point is on the
surface's boundary (a hem, a neckline) the distance stays unsigned: beside
an edge the side is not defined.  The surface has no inside for the
position fail-safe, which leaves it to the triangle pipeline, still run on
both layers.  Pure arrays, no MPI: the caller hands in the all-gathered
positions and velocities.
"""
from __future__ import annotations

import numpy as np

from .colliders import MeshCollider
from .mesh_query import MeshProximity
from .proximity import open_edges

# the surface's positions are its start positions moved on with its start
# velocities; two frames this far apart give that motion for any step within
EXTRAPOLATION = 1.0     # s


class LayerSurface:
    """The garments of the layers under ``layer``, as the vertices of ``layer``
    see them.  ``input_layer`` (N,): every cloth vertex's layer (input
    numbering); ``local_input`` (n_local,): the input vertex of each local row;
    ``triangles`` (m, 3): the cloth's triangles (input numbering)."""

    def __init__(self, layer: int, input_layer, local_input, triangles):
        input_layer = np.asarray(input_layer)
        tri = np.asarray(triangles, dtype=np.int64)
        self.layer = int(layer)
        # the local rows that meet this surface: the layer's own vertices
        self.asks = input_layer[np.asarray(local_input)] == layer
        self._anyone = bool(np.any(input_layer == layer))     # on any rank
        under = tri[np.all(input_layer[tri] < layer, axis=1)]
        self.vertices = np.unique(under)               # input vertices of the surface
        self.triangles = np.searchsorted(self.vertices, under)
        # the surface's boundary: its vertices, and its edges as keys i * n + j
        edges = open_edges(self.triangles)
        self._boundary_vertex = np.zeros(self.vertices.size, dtype=bool)
        self._boundary_vertex[edges.ravel()] = True
        self._boundary_edge = edges[:, 0] * self.vertices.size + edges[:, 1]
        self._proximity = None
        self._start = None        # (t0, x0, v0) of the surface's vertices

    @property
    def empty(self) -> bool:
        """No garment under this layer, or none in it (the same on every rank)."""
        return self.triangles.shape[0] == 0 or not self._anyone

    def move(self, positions, velocities, t: float) -> None:
        """The surface where a step starts at ``t``: the all-gathered cloth
        ``positions`` and ``velocities`` (N, 3, input numbering)."""
        x = np.asarray(positions, dtype=np.float64)[self.vertices]
        v = np.asarray(velocities, dtype=np.float64)[self.vertices]
        mesh = MeshCollider.sequence([x, x + EXTRAPOLATION * v], self.triangles,
                                     (t, t + EXTRAPOLATION))
        self._proximity = MeshProximity(mesh)
        self._start = (float(t), x, v)
        # the side of the surface: its area-weighted vertex normals at the
        # start, interpolated to the closest point (near a crease of the inner
        # layer a face's own normal can call a point in front of it behind)
        tri = self.triangles
        face = np.cross(x[tri[:, 1]] - x[tri[:, 0]], x[tri[:, 2]] - x[tri[:, 0]])
        vn = np.zeros_like(x)
        for k in range(3):
            np.add.at(vn, tri[:, k], face)
        self._normal = vn

    def query(self, points, t: float, max_distance: float = np.inf):
        """(phi, normal, velocity) of the first ``len(points)`` local rows, as a
        collider's query: the distance to the surface, signed by the side its
        triangles face, for the rows of this layer; +inf (no contact) for
        every other row, beyond ``max_distance`` and before the first ``move``."""
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        n = pts.shape[0]
        phi, normal, velocity = np.full(n, np.inf), np.zeros((n, 3)), np.zeros((n, 3))
        rows = np.flatnonzero(self.asks[:n])
        if self._proximity is None or rows.size == 0:
            return phi, normal, velocity
        face, w, dist = self._proximity.closest(pts[rows], t, max_distance)
        hit = face >= 0
        rows, face, w, dist = rows[hit], face[hit], w[hit], dist[hit]
        if rows.size == 0:
            return phi, normal, velocity
        t0, x0, v0 = self._start
        corners = self.triangles[face]                               # (k, 3)
        x = x0[corners] + min(max(t - t0, 0.0), EXTRAPOLATION) * v0[corners]   # (k, 3, 3)
        c = np.einsum("ij,ijk->ik", w, x)
        front = np.einsum("ij,ijk->ik", w, self._normal[corners])
        front /= np.maximum(np.linalg.norm(front, axis=1), 1e-300)[:, None]
        e = pts[rows] - c
        side = np.where(np.einsum("ij,ij->i", e, front) < 0.0, -1.0, 1.0)
        side[self._on_boundary(corners, w)] = 1.0                   # unsigned there
        tiny = 1e-12 * max(float(np.ptp(x0, axis=0).max(initial=0.0)), 1e-300)
        unit = np.where((dist > tiny)[:, None], e / np.maximum(dist, 1e-300)[:, None],
                        front * side[:, None])
        phi[rows] = side * dist
        normal[rows] = side[:, None] * unit          # from the surface towards its front
        velocity[rows] = np.einsum("ij,ijk->ik", w, v0[corners])
        return phi, normal, velocity

    def _on_boundary(self, corners, w) -> np.ndarray:
        """Closest points on a boundary edge or vertex of the surface."""
        zero = w == 0.0
        nzero = zero.sum(axis=1)
        out = np.zeros(corners.shape[0], dtype=bool)
        vert = nzero == 2
        out[vert] = self._boundary_vertex[corners[vert, np.argmax(w[vert], axis=1)]]
        edge = np.flatnonzero(nzero == 1)
        if edge.size:
            ends = np.sort(corners[edge][~zero[edge]].reshape(-1, 2), axis=1)
            key = ends[:, 0] * self.vertices.size + ends[:, 1]
            out[edge] = np.isin(key, self._boundary_edge)
        return out
