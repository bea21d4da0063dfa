"""Initial-state hooks of the stability cases: they change a built Model's
start positions or velocities (never its rest shape), deterministically from
a seed, so every rank builds the same start state without communicating.

* ``crumple``: a smooth random displacement of the whole sheet;
* ``invert``: some triangles flipped through their opposite edge;
* ``degenerate``: some vertices moved to within a tiny height of the line of
  two neighbours (nearly zero-area triangles);
* ``launch``: a uniform initial velocity (the impact case).
"""
from __future__ import annotations

import numpy as np

from ..model import Model


def _start(model: Model) -> np.ndarray:
    return model.start_positions().astype(np.float64).copy()


def _frame(x: np.ndarray):
    """Centroid, two in-plane axes and the normal of a near-flat point set
    (principal axes), and the set's extent along the first axis."""
    c = x.mean(axis=0)
    _, _, vt = np.linalg.svd(x - c, full_matrices=False)
    extent = float(np.ptp((x - c) @ vt[0]))
    return c, vt[0], vt[1], vt[2], extent


def crumple(model: Model, seed: int = 1, out_of_plane: float = 0.15, in_plane: float = 0.03,
            modes: int = 4) -> None:
    """Start from the flat sheet plus a smooth random field: a sum of
    products of sines with modes up to ``modes`` along each in-plane axis and
    coefficients decaying like 1/(i^2 + j^2) (smooth, so no self-intersection),
    scaled so its largest out-of-plane and in-plane parts are these fractions
    of the sheet's extent. The in-plane part strains the membrane: the cloth
    starts with elastic energy to release."""
    x = _start(model)
    c, e1, e2, nrm, extent = _frame(x)
    u = (x - c) @ e1
    v = (x - c) @ e2
    u = (u - u.min()) / max(np.ptp(u), 1e-300)
    v = (v - v.min()) / max(np.ptp(v), 1e-300)
    rng = np.random.default_rng(seed)
    i = np.arange(1, modes + 1)
    decay = 1.0 / (i[:, None] ** 2 + i[None, :] ** 2)                  # (modes, modes)
    field = np.zeros((x.shape[0], 3))
    for comp in range(3):
        coef = rng.normal(size=(modes, modes)) * decay
        phase = rng.uniform(0.0, 2 * np.pi, size=(2, modes))
        su = np.sin(np.pi * i[None, :] * u[:, None] + phase[0])         # (n, modes)
        sv = np.sin(np.pi * i[None, :] * v[:, None] + phase[1])
        field[:, comp] = np.einsum("ni,ij,nj->n", su, coef, sv)
    field /= np.maximum(np.abs(field).max(axis=0), 1e-300)
    disp = (extent * in_plane * (field[:, :1] * e1 + field[:, 1:2] * e2)
            + extent * out_of_plane * field[:, 2:3] * nrm)
    model.initial_positions = x + disp


def _interior_free_vertices(model: Model) -> np.ndarray:
    """Vertices with a closed ring of triangles (interior), not pinned."""
    tri = model.triangles
    n = model.num_vertices
    e = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
    edges, count = np.unique(e, axis=0, return_counts=True)
    boundary = np.zeros(n, dtype=bool)
    boundary[edges[count == 1].ravel()] = True
    held = np.zeros(n, dtype=bool)
    held[model.pinned] = True
    if model.slide_vertices is not None:
        held[model.slide_vertices] = True
    return np.nonzero(~boundary & ~held)[0]


def _vertex_triangles(tri: np.ndarray, n: int):
    """CSR of the triangles around each vertex, ascending: (starts (n+1,), triangle ids)."""
    flat = tri.ravel()
    order = np.argsort(flat, kind="stable")
    starts = np.searchsorted(flat[order], np.arange(n + 1))
    return starts, order // 3


def _independent_vertices(model: Model, fraction: float, seed: int) -> np.ndarray:
    """About ``fraction`` of the interior free vertices, no two in a common
    triangle (each move then changes a triangle no other move touches)."""
    cand = np.random.default_rng(seed).permutation(_interior_free_vertices(model))
    want = max(1, int(round(fraction * model.num_vertices)))
    tri = model.triangles
    starts, tri_ids = _vertex_triangles(tri, model.num_vertices)
    blocked = np.zeros(model.num_vertices, dtype=bool)
    chosen = []
    for p in cand:       # greedy, hence sequential: each pick blocks its one-ring
        if blocked[p]:
            continue
        chosen.append(p)
        blocked[tri[tri_ids[starts[p]:starts[p + 1]]].ravel()] = True
        if len(chosen) == want:
            break
    return np.array(chosen, dtype=np.int64)


def _one_triangle_each(model: Model, vertices: np.ndarray, seed: int):
    """For each vertex p, one incident triangle (drawn from the seed): its
    other two corners (a, b)."""
    tri = model.triangles
    starts, tri_ids = _vertex_triangles(tri, model.num_vertices)
    count = starts[vertices + 1] - starts[vertices]
    rng = np.random.default_rng(seed + 1)
    pick = np.array([rng.integers(c) for c in count], dtype=np.int64)
    rows = tri[tri_ids[starts[vertices] + pick]]
    others = rows[rows != vertices[:, None]].reshape(-1, 2)
    return others[:, 0], others[:, 1]


def _line_frame(x, p, a, b):
    """Foot of p on the line ab and the offset of p from it."""
    ab = x[b] - x[a]
    u = ab / np.linalg.norm(ab, axis=1, keepdims=True)
    ap = x[p] - x[a]
    foot = x[a] + np.einsum("ij,ij->i", ap, u)[:, None] * u
    return foot, x[p] - foot


def invert(model: Model, fraction: float = 0.05, seed: int = 2, depth: float = 0.5) -> int:
    """Flip one triangle at each chosen vertex p through its opposite edge ab:
    p goes to the other side of the line ab, at ``depth`` times its distance
    from it (the triangle's orientation reverses, its neighbours around p are
    strongly distorted). Not a full mirror (depth 1): on a grid that lands p
    exactly on the vertex across ab, two vertices in one place. Returns how
    many triangles start with their normal against the rest normal."""
    x = _start(model)
    p = _independent_vertices(model, fraction, seed)
    a, b = _one_triangle_each(model, p, seed)
    foot, off = _line_frame(x, p, a, b)
    x[p] = foot - depth * off
    model.initial_positions = x
    return count_inverted(model)


def degenerate(model: Model, fraction: float = 0.05, seed: int = 3, height: float = 1e-4) -> int:
    """Move each chosen vertex p to ``height`` times the edge length ab off
    the line of its neighbours a, b (on its own side): the triangle (p, a, b)
    is nearly degenerate, its area 1e-4 of a normal one. Returns how many
    triangles start with less than 1e-3 of their rest area."""
    x = _start(model)
    p = _independent_vertices(model, fraction, seed)
    a, b = _one_triangle_each(model, p, seed)
    foot, off = _line_frame(x, p, a, b)
    lab = np.linalg.norm(x[b] - x[a], axis=1, keepdims=True)
    unit = off / np.linalg.norm(off, axis=1, keepdims=True)
    x[p] = foot + height * lab * unit
    model.initial_positions = x
    area0 = _areas(model.rest_positions, model.triangles)
    return int(np.sum(_areas(x, model.triangles) < 1e-3 * area0))


def launch(model: Model, velocity) -> None:
    """Every vertex starts with the same velocity (pinned ones are held by their pins)."""
    model.initial_velocities = np.broadcast_to(np.asarray(velocity, dtype=np.float64),
                                               (model.num_vertices, 3)).copy()


def _normals(x, tri):
    return np.cross(x[tri[:, 1]] - x[tri[:, 0]], x[tri[:, 2]] - x[tri[:, 0]])


def _areas(x, tri):
    return 0.5 * np.linalg.norm(_normals(x, tri), axis=1)


def count_inverted(model: Model) -> int:
    """Triangles whose start normal points against their rest normal."""
    n0 = _normals(model.rest_positions, model.triangles)
    n1 = _normals(model.start_positions(), model.triangles)
    return int(np.sum(np.einsum("ij,ij->i", n0, n1) < 0.0))


def mean_edge_length(model: Model) -> float:
    """Mean length of the unique triangle edges at rest."""
    tri = model.triangles
    e = np.unique(np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]),
                          axis=1), axis=0)
    x = model.rest_positions
    return float(np.mean(np.linalg.norm(x[e[:, 1]] - x[e[:, 0]], axis=1)))
