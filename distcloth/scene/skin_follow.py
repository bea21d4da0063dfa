"""Skin-following regions (EG07 tutorial, Part 2 §2.3; docs/bodies.md): a
tight part of a garment, a waistband or a cuff, moves with the body's
surface at its offset instead of being simulated.

Its vertices become one more grip (scene/grips.py) whose path is the body:
each vertex keeps its position in the frame of the body triangle closest to
it when it was attached (body/attachment.py).  The region is chosen where
the scene is read (a band along labelled pattern edges, or the whole piece)
and attached where the run starts, a sewn garment at its weld, to the
vertices of the region then within ``within`` of the body.  Built on every
rank from the replicated model: the same grip everywhere.
"""
from __future__ import annotations

import numpy as np

from ..body.animated import VELOCITY_DT
from ..body.attachment import attach, follow
from ..body.regions import submesh
from ..collision.colliders import MeshCollider, SkinnedMeshCollider
from ..collision.mesh_query import MeshProximity
from ..config.schema import ConfigError
from .grips import Grip, group_of_vertices


def pattern_band(piece, labels, band: float, key: str) -> np.ndarray:
    """Sorted vertices of a pattern piece (garment/piece.py, its numbering)
    within ``band`` (m, in the flat panel) of an edge labelled one of
    ``labels``; ConfigError at ``key`` for a label the pattern does not have."""
    have = sorted({e.label for pm in piece.mesh.panels for e in pm.panel.edges if e.label})
    for label in labels:
        if label not in have:
            raise ConfigError(key, label, "an edge label of the pattern ("
                              + (", ".join(have) or "it has none") + ")")
    chosen = []
    for pm in piece.mesh.panels:
        for e, edge in enumerate(pm.panel.edges):
            if edge.label not in labels:
                continue
            line = pm.vertices[pm.edge_vertices[e]]
            near = _distance_to_polyline(pm.vertices, line) <= band
            chosen.append(np.flatnonzero(near) + pm.offset)
    return np.unique(np.concatenate(chosen)) if chosen else np.zeros(0, np.int64)


def _distance_to_polyline(points: np.ndarray, line: np.ndarray) -> np.ndarray:
    """(n,) distance of 2D points to the polyline through ``line`` (m, 2)."""
    a, b = line[:-1], line[1:]
    ab = b - a
    s = np.einsum("nsi,si->ns", points[:, None] - a[None], ab) / np.einsum("si,si->s", ab, ab)
    closest = a[None] + np.clip(s, 0.0, 1.0)[..., None] * ab[None]
    return np.linalg.norm(points[:, None] - closest, axis=2).min(axis=1)


class SkinPath:
    """The path of a grip attached to a mesh collider at time t0: its vertices
    (sorted global indices) keep their offsets in the frames of their closest
    triangles then.  A skinned body is skinned only on those triangles."""

    def __init__(self, collider: MeshCollider, vertices: np.ndarray, points: np.ndarray,
                 t0: float, drive_end: float, closest=None):
        """``closest``: (face, weights) of the points' closest points at t0, if
        the caller has them (MeshProximity.closest)."""
        face, w = (closest if closest is not None
                   else MeshProximity(collider).closest(points, t0)[:2])
        used = np.zeros(collider.triangles.shape[0], dtype=bool)
        used[face] = True
        self.surface = collider
        if isinstance(collider, SkinnedMeshCollider):
            ids, tri = submesh(collider.body.triangles, used)
            self.surface = SkinnedMeshCollider(collider.body.part(ids, tri), collider.A,
                                               collider.b, collider.motion)
            face = np.cumsum(used)[face] - 1
        self.triangles = np.ascontiguousarray(self.surface.triangles)
        self.face, self.weights = face, w
        self.vertices = np.asarray(vertices, dtype=np.int64)
        self.offsets = attach(points, self.surface.vertices(t0), self.triangles, face, w)
        self.end = float(drive_end)

    def _rows(self, vertices) -> np.ndarray:
        return np.searchsorted(self.vertices, np.asarray(vertices, dtype=np.int64))

    def positions(self, X: np.ndarray, t: float, vertices=None) -> np.ndarray:
        r = self._rows(vertices)
        return follow(self.surface.vertices(t), self.triangles, self.face[r], self.weights[r],
                      self.offsets[r])

    def velocities(self, X: np.ndarray, t: float, vertices=None) -> np.ndarray:
        """Central differences over the skin velocities' interval (body/animated.py)."""
        return (self.positions(X, t + VELOCITY_DT, vertices)
                - self.positions(X, t - VELOCITY_DT, vertices)) / (2.0 * VELOCITY_DT)


def region_candidates(cfg, model, garments) -> list[np.ndarray | None]:
    """Per piece, the vertices (model numbering) of its skin-following region
    before the distance to the body is known; None for pieces without one."""
    out = []
    for p, (spec, info) in enumerate(zip(cfg.cloth, model.pieces)):
        follow_spec = spec.follow_skin
        if follow_spec is None:
            out.append(None)
        elif follow_spec.edges:
            out.append(pattern_band(garments[p].pattern, follow_spec.edges, follow_spec.band,
                                    f"cloth.{p}.follow_skin.edges") + info.vertex_start)
        else:
            out.append(np.arange(info.vertex_start, info.vertex_stop, dtype=np.int64))
    return out


def add_skin_grips(cfg, model, t: float) -> None:
    """Attach every piece's skin-following region at time t to its collider
    (the model's start positions are where it is then) and hold it as a grip
    named <piece>.follow_skin.  ConfigError naming ``within`` when no vertex
    of a region is close enough to the body."""
    candidates = model.follow_regions
    if candidates is None:
        return
    # the rig's imports (0.3 s) only for scenes with a region (contact.py imports them too)
    from ..collision.contact import make_collider
    x = model.start_positions()
    colliders = {c.name: (k, c) for k, c in enumerate(cfg.colliders)}
    grips = list(model.grips)
    for p, (spec, cand) in enumerate(zip(cfg.cloth, candidates)):
        if cand is None:
            continue
        follow_spec = spec.follow_skin
        k, cspec = colliders[follow_spec.collider]
        body = make_collider(cspec, True, f"colliders.{k}")
        if model.pattern_vertex is not None:
            cand = np.unique(model.pattern_vertex[cand])
        face, w, dist = MeshProximity(body.body).closest(x[cand], t)
        # a vertex pinned already keeps its pin
        keep = (dist <= follow_spec.within) & ~np.isin(cand, model.pinned)
        near = cand[keep]
        if near.size == 0:
            raise ConfigError(f"cloth.{p}.follow_skin.within", follow_spec.within,
                              f"a distance reaching collider {cspec.name!r}: the region's "
                              f"closest vertex is {dist.min():.4g} m from it at t = {t:g} s")
        path = SkinPath(body.body, near, x[near], t, body.drive_end, (face[keep], w[keep]))
        grips.append(Grip(f"{spec.name}.follow_skin", near, None, path))
        model.pinned = np.union1d(model.pinned, near).astype(np.int64)
        if model.slide_vertices is not None and model.slide_vertices.size:
            free = ~np.isin(model.slide_vertices, near)    # followed: held in every direction
            model.slide_vertices, model.slide_axes = (model.slide_vertices[free],
                                                      model.slide_axes[free])
        v = np.array(model.start_velocities(), dtype=np.float64)
        v[near] = path.velocities(x[near], t, near)
        model.initial_velocities = v
    model.grips = grips
    model.pin_group = group_of_vertices(grips, model.num_vertices)
