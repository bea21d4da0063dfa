"""Welding a sewn garment: every group of stitched vertices becomes one
vertex, and the panels one connected mesh.

The topology changes once, so the welded garment is a new Model (the
driver partitions it again).  What a single rest shape cannot hold is kept
per element: each triangle's rest corners stay those of its own flat panel
(a sewn garment has no flat rest shape as a whole), and each hinge is
unfolded flat across its edge from its two triangles' rest corners, so a
seam hinge rests flat, as an opened seam lies on the table.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from ..model import FLEXION, Model
from ..scene.grips import group_of_vertices


@dataclass(frozen=True)
class SeamMaterial:
    """What a sewn seam adds: a strip of ``width`` along the seam line of
    ``stretch`` times the fabric's modulus (springs along the seam's edges,
    their rest length shortened by ``shrinkage``), and ``bending`` times the
    fabric's bending stiffness on the hinges across it."""
    stretch: float = 1.0
    width: float = 0.01
    bending: float = 1.0
    shrinkage: float = 0.0


def weld_groups(n: int, pairs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(new index of each vertex, the smallest old index of each new vertex):
    vertices joined by pairs, directly or through others, share a new index;
    new indices follow the order of the groups' smallest old index."""
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    graph = coo_matrix((np.ones(pairs.shape[0]), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    first = np.full(label.max() + 1 if n else 0, n, dtype=np.int64)
    np.minimum.at(first, label, np.arange(n))
    order = np.argsort(first, kind="stable")
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    return rank[label], first[order]


def canonical_vertex(n: int, pairs: np.ndarray) -> np.ndarray:
    """The vertex each vertex becomes when the pairs are welded, in the
    unwelded numbering (the smallest index of its group)."""
    new_of, first = weld_groups(n, pairs)
    return first[new_of]


def hinge_triangles(triangles: np.ndarray):
    """Hinges of a consistently oriented mesh as ``physics.bending.hinges``
    orders them, with (triangle A, its half-edge, triangle B, its half-edge)."""
    tri = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    src, dst = tri.ravel(), tri[:, [1, 2, 0]].ravel()
    opp = tri[:, [2, 0, 1]].ravel()
    n = int(tri.max()) + 1 if tri.size else 1
    key = np.minimum(src, dst) * n + np.maximum(src, dst)
    order = np.argsort(key, kind="stable")
    ks = key[order]
    starts = np.flatnonzero(np.concatenate([[True], ks[1:] != ks[:-1]])) if ks.size else \
        np.zeros(0, np.int64)
    counts = np.diff(np.concatenate([starts, [ks.shape[0]]]))
    if np.any(counts > 2):
        e = int(ks[starts[np.flatnonzero(counts > 2)[0]]])
        raise ValueError(f"the welded garment has an edge ({e // n}, {e % n}) shared by "
                         f"more than two triangles: three panels sewn along one line")
    two = starts[counts == 2]
    first, second = order[two], order[two + 1]
    if np.any(src[second] != dst[first]):
        h = int(first[np.flatnonzero(src[second] != dst[first])[0]])
        raise ValueError(f"the welded garment is not consistently oriented at edge "
                         f"({src[h]}, {dst[h]}): a stitch joins a panel's outside to "
                         f"another's inside (right_wrong where right to right was meant?)")
    hinge = np.stack([src[first], dst[first], opp[first], opp[second]], axis=1)
    return hinge, first // 3, first % 3, second // 3, second % 3


def unfold_hinges(rest_triangles, tri_a, half_a, tri_b, half_b) -> np.ndarray:
    """(nh, 4, 3) rest points of each hinge: edge and A's third corner from A's
    rest corners, B's third corner laid flat on the other side of the edge at
    the distances it has in B (along the edge as a fraction of it)."""
    ra, rb = rest_triangles[tri_a], rest_triangles[tri_b]
    rows = np.arange(ra.shape[0])
    x0, x1, x2 = (ra[rows, (half_a + k) % 3] for k in range(3))
    b1, b0, b3 = (rb[rows, (half_b + k) % 3] for k in range(3))   # B runs the edge backwards
    eb = b1 - b0
    lb = np.linalg.norm(eb, axis=1)
    along = np.einsum("ij,ij->i", b3 - b0, eb) / lb
    height = np.linalg.norm((b3 - b0) - (along / lb)[:, None] * eb, axis=1)
    e = x1 - x0
    le = np.linalg.norm(e, axis=1)
    u = e / le[:, None]
    w = (x2 - x0) - np.einsum("ij,ij->i", x2 - x0, u)[:, None] * u
    w /= np.linalg.norm(w, axis=1)[:, None]
    x3 = x0 + (along / lb * le)[:, None] * u - height[:, None] * w
    return np.stack([x0, x1, x2, x3], axis=1)


def _seam_lines(model: Model, new_of, rest, material: SeamMaterial, modulus):
    """Welded seam edges from consecutive pairs of each stitch; rest length the
    shorter side's (the longer is gathered onto it) less the shrinkage."""
    pairs, index = model.stitch_pairs, model.stitch_index
    same = index[1:] == index[:-1]
    a0, a1 = pairs[:-1][same], pairs[1:][same]
    line = np.stack([new_of[a0[:, 0]], new_of[a1[:, 0]]], axis=1)
    keep = line[:, 0] != line[:, 1]
    la = np.linalg.norm(rest[a1[:, 0]] - rest[a0[:, 0]], axis=1)
    lb = np.linalg.norm(rest[a1[:, 1]] - rest[a0[:, 1]], axis=1)
    length = np.minimum(la, lb)[keep] * (1.0 - material.shrinkage)
    # a strip of width w and modulus E between two points l apart: k = E w / l
    k = material.stretch * modulus[a0[keep, 0]] * material.width / np.maximum(length, 1e-12)
    return line[keep], length, k


def weld_model(model: Model, x: np.ndarray, v: np.ndarray, material: SeamMaterial,
               modulus: np.ndarray, bending: np.ndarray, damping_ratio: np.ndarray) -> Model:
    """The welded Model of a sewn garment at positions x, velocities v (global,
    input order).  ``modulus``, ``bending``, ``damping_ratio``: per unwelded
    vertex, its piece's membrane modulus (N/m), bending stiffness (N m) and
    spring damping ratio (s), for the seam springs and the flexion springs
    across seams (mass-spring)."""
    n = model.num_vertices
    pairs = model.stitch_pairs
    new_of, first = weld_groups(n, pairs)
    m = first.size
    mass = np.bincount(new_of, weights=model.vertex_mass, minlength=m)
    area = np.bincount(new_of, weights=model.vertex_area, minlength=m)
    # positions: the group's mean; velocities: its momentum over its mass
    count = np.bincount(new_of, minlength=m).astype(np.float64)
    x_new = np.stack([np.bincount(new_of, weights=x[:, k], minlength=m) for k in range(3)], 1)
    x_new /= count[:, None]
    p = model.vertex_mass[:, None] * v
    v_new = np.stack([np.bincount(new_of, weights=p[:, k], minlength=m) for k in range(3)], 1)
    v_new /= mass[:, None]

    tri = new_of[model.triangles]
    keep = (tri[:, 0] != tri[:, 1]) & (tri[:, 1] != tri[:, 2]) & (tri[:, 2] != tri[:, 0])
    rest_tri = (model.rest_triangles if model.rest_triangles is not None
                else model.rest_positions[model.triangles])[keep]
    tri = tri[keep]
    hinge, ta, ha, tb, hb = hinge_triangles(tri)
    hinge_rest = unfold_hinges(rest_tri, ta, ha, tb, hb)
    # a hinge across a seam: its edge's unwelded vertices differ between its two triangles
    old_tri = model.triangles[keep]
    rows = np.arange(hinge.shape[0])
    edge_a = np.sort(np.stack([old_tri[ta, ha], old_tri[ta, (ha + 1) % 3]], 1), axis=1)
    edge_b = np.sort(np.stack([old_tri[tb, hb], old_tri[tb, (hb + 1) % 3]], 1), axis=1)
    across = np.any(edge_a != edge_b, axis=1)
    hinge_scale = np.where(across, material.bending, 1.0)
    if model.hinge_scale is not None and model.hinge_vertices is not None:
        hinge_scale = hinge_scale * _carry_hinge_scale(model, new_of, hinge)

    springs = new_of[model.spring_vertices]
    live = springs[:, 0] != springs[:, 1]
    spring_vertices = springs[live]
    rest_len, k, c = (model.spring_rest_length[live], model.spring_stiffness[live],
                      model.spring_damping[live])
    kind = model.spring_kind[live]
    if np.any(model.spring_kind == FLEXION) and across.any():
        # mass-spring bending: flexion springs across the seams, which the
        # panels' own meshes could not have
        span = np.linalg.norm(hinge_rest[across, 3] - hinge_rest[across, 2], axis=1)
        owner = model.triangles[keep][ta[across], 0]
        kf = material.bending * 4.0 * bending[owner] / np.square(span)
        spring_vertices = np.concatenate([spring_vertices, hinge[across][:, 2:]])
        rest_len = np.concatenate([rest_len, span])
        k = np.concatenate([k, kf])
        c = np.concatenate([c, damping_ratio[owner] * kf])
        kind = np.concatenate([kind, np.full(int(across.sum()), FLEXION, dtype=np.int8)])

    lines, line_rest, line_k = _seam_lines(model, new_of, model.rest_positions, material, modulus)
    pinned = np.unique(new_of[model.pinned])
    slide_v, slide_a = model.slide_vertices, model.slide_axes
    if slide_v is not None and slide_v.size:
        slide_v = new_of[slide_v]
        drop = np.isin(slide_v, pinned)
        slide_v, slide_a = slide_v[~drop], slide_a[~drop]
    pattern_vertex = new_of if model.pattern_vertex is None else new_of[model.pattern_vertex]
    grips = [replace(g, vertices=np.unique(new_of[g.vertices])) for g in model.grips]
    loads = model.loads
    if loads is not None:
        loads = replace(loads, vertices=new_of[loads.vertices])
    return replace(
        model, rest_positions=model.rest_positions[first], triangles=tri,
        vertex_mass=mass, vertex_area=area, spring_vertices=spring_vertices,
        spring_rest_length=rest_len, spring_stiffness=k, spring_damping=c,
        spring_kind=kind.astype(np.int8), pinned=pinned, pieces=_welded_pieces(model, new_of, keep),
        initial_positions=x_new, initial_velocities=v_new,
        hinge_vertices=hinge if model.hinge_vertices is not None else None,
        hinge_rest=hinge_rest if model.hinge_vertices is not None else None,
        hinge_scale=hinge_scale if model.hinge_vertices is not None else None,
        shell_stencil=None, shell_present=None, shell_jump_stencil=None,
        flexion_lines=None if model.flexion_lines is None else new_of[model.flexion_lines],
        twist_cells=None if model.twist_cells is None else new_of[model.twist_cells],
        flexion_hinges=None if model.flexion_hinges is None else new_of[model.flexion_hinges],
        slide_vertices=slide_v, slide_axes=slide_a,
        grips=grips, pin_group=group_of_vertices(grips, first.shape[0]), loads=loads,
        triangle_weft=None if model.triangle_weft is None else model.triangle_weft[keep],
        triangle_scale=None if model.triangle_scale is None else model.triangle_scale[keep],
        uv_index=None if model.uv_index is None else model.uv_index[keep],
        rest_triangles=rest_tri, stitch_pairs=None, stitch_gap=None, stitch_index=None,
        same_vertex=None, seam_lines=lines, seam_rest_length=line_rest, seam_stiffness=line_k,
        pattern_vertex=pattern_vertex)


def _carry_hinge_scale(model: Model, new_of, hinge) -> np.ndarray:
    """Factors the unwelded hinges had (fused regions), found by their welded
    edge and wing vertices; new hinges (across seams) get 1."""
    old = new_of[model.hinge_vertices]
    n = int(max(old.max(initial=0), hinge.max(initial=0))) + 1

    def key(h):
        lo, hi = np.minimum(h[:, 0], h[:, 1]), np.maximum(h[:, 0], h[:, 1])
        return lo * n + hi

    old_key = key(old)
    if old_key.size == 0:
        return np.ones(hinge.shape[0])
    order = np.argsort(old_key, kind="stable")
    want = key(hinge)
    at = np.minimum(np.searchsorted(old_key[order], want), old_key.size - 1)
    return np.where(old_key[order[at]] == want, model.hinge_scale[order[at]], 1.0)


def _welded_pieces(model: Model, new_of, keep):
    """Piece ranges in the welded numbering (welding never joins two
    garments: stitches are within one pattern, and groups take their
    smallest index, so each piece stays a contiguous range)."""
    tri_new_start = np.concatenate([[0], np.cumsum(keep)])
    out = []
    for info in model.pieces:
        vs = int(new_of[info.vertex_start:info.vertex_stop].min())
        ve = int(new_of[info.vertex_start:info.vertex_stop].max()) + 1
        out.append(replace(info, vertex_start=vs, vertex_stop=ve,
                           triangle_start=int(tri_new_start[info.triangle_start]),
                           triangle_stop=int(tri_new_start[info.triangle_stop])))
    return out


__all__ = ["SeamMaterial", "canonical_vertex", "hinge_triangles", "unfold_hinges", "weld_groups",
           "weld_model"]
