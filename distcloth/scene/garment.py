"""Pattern pieces in the scene: meshed, placed, layered, fused, and the
arrays the Model needs to sew them (docs/garments.md)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..config.schema import ClothSpec, ConfigError, SceneConfig
from ..collision.colliders import load_collider_mesh
from ..garment.mesh import MeshError
from ..garment.start_check import ClosedMesh, body_intersections, describe, self_intersections
from ..garment.pattern import PatternError
from ..garment.piece import PatternPiece, frame_of, pattern_piece
from ..garment.weld import canonical_vertex, hinge_triangles
from ..model import Model
from .springs import triangle_areas


@dataclass
class Garment:
    pattern: PatternPiece
    positions: np.ndarray          # (n, 3) placed, moved out by its layer
    triangles: np.ndarray          # (nt, 3)
    triangle_weft: np.ndarray      # (nt, 3)
    triangle_scale: np.ndarray     # (nt,) membrane factor: 1 + fused modulus / fabric's
    triangle_bending: np.ndarray   # (nt,) bending factor: 1 + fused bending / fabric's
    added_mass: np.ndarray         # (n,) fused interlinings' mass, kg


def pattern_piece_of(spec: ClothSpec, p: int, cfg: SceneConfig | None = None,
                     bodies=()) -> Garment:
    """Mesh and place piece p's pattern; pattern or meshing errors become
    ConfigErrors naming the file and the offending key of the pattern."""
    mesh = spec.mesh
    key = f"cloth.{p}.mesh.pattern"
    try:
        piece = pattern_piece(mesh.pattern, mesh.edge_length, mesh.up_axis, mesh.translation)
    except PatternError as exc:
        raise ConfigError(key, mesh.pattern, f"a valid sewing pattern; at {exc.path}: "
                          f"{exc.message}") from None
    except (MeshError, ValueError) as exc:
        raise ConfigError(key, mesh.pattern, f"a pattern that meshes at edge_length "
                          f"{mesh.edge_length:g} m: {exc}") from None
    positions = piece.positions
    turn = frame_of(mesh.up_axis)
    normals = np.stack([pm.panel.normal for pm in piece.mesh.panels]) @ turn.T
    counts = [pm.vertices.shape[0] for pm in piece.mesh.panels]
    if cfg is not None and cfg.garment.clearance > 0 and bodies:
        positions = _clear_bodies(positions, normals, counts, bodies, cfg.garment.clearance)
    gap = cfg.garment.layer_gap if cfg is not None else 0.0
    if spec.layer and gap > 0:
        # the initial-layering rule: an outer layer's panels start moved out
        # along their outside normals, rigidly (no strain), by layer * gap
        positions = positions + spec.layer * gap * np.repeat(normals, counts, axis=0)
    nt = piece.triangles.shape[0]
    scale, bending = np.ones(nt), np.ones(nt)
    added = np.zeros(positions.shape[0])
    if cfg is not None:
        scale, bending, added = _fused(cfg, spec, piece, positions)
    return Garment(piece, positions, piece.triangles, piece.triangle_weft, scale, bending, added)


def body_meshes(cfg: SceneConfig) -> list:
    """The scene's mesh colliders at time 0 as ClosedMesh queries (the bodies
    a garment is dressed on)."""
    out = []
    for i, spec in enumerate(cfg.colliders):
        if spec.shape == "mesh":
            mesh = load_collider_mesh(spec, key=f"colliders.{i}")
            out.append(ClosedMesh(mesh.vertices(0.0), mesh.triangles))
    return out


def _clear_bodies(positions, normals, counts, bodies, clearance: float, rounds: int = 6):
    """Pre-positioning: each panel moved rigidly along its outside normal until
    every vertex is at least ``clearance`` outside every body (a normal is not
    the direction of the nearest surface everywhere, so a few rounds)."""
    starts = np.concatenate([[0], np.cumsum(counts)])
    out = positions.copy()
    for _ in range(rounds):
        depth = np.max([clearance - b.signed_distance(out) for b in bodies], axis=0)
        short = np.array([depth[a:b].max(initial=-np.inf) for a, b in zip(starts[:-1],
                                                                           starts[1:])])
        if not np.any(short > 1e-6 * clearance):
            break
        move = np.where(short > 0, short * 1.05, 0.0)
        out += np.repeat(move[:, None] * normals, counts, axis=0)
    return out


def _fused(cfg: SceneConfig, spec: ClothSpec, piece: PatternPiece, positions):
    """The combined material of the fused regions naming this piece."""
    tri = piece.triangles
    nt = tri.shape[0]
    scale, bending = np.ones(nt), np.ones(nt)
    added = np.zeros(positions.shape[0])
    names = [pm.panel.name for pm in piece.mesh.panels]
    material = spec.material
    modulus = material.orthotropic()[0]
    for i, fused in enumerate(cfg.garment.fused):
        if fused.piece != spec.name:
            continue
        if fused.panel not in names:
            raise ConfigError(f"garment.fused.{i}.panel", fused.panel,
                              "a panel of the pattern (" + ", ".join(names) + ")")
        panel = names.index(fused.panel)
        pm = piece.mesh.panels[panel]
        inside = piece.triangle_panel == panel
        if fused.box_min is not None:
            centroid = pm.vertices[pm.triangles].mean(axis=1)
            lo, hi = np.asarray(fused.box_min), np.asarray(fused.box_max)
            local = np.all((centroid >= lo) & (centroid <= hi), axis=1)
            inside = np.zeros(nt, dtype=bool)
            inside[np.flatnonzero(piece.triangle_panel == panel)[local]] = True
            if not local.any():
                raise ConfigError(f"garment.fused.{i}.box", [list(lo), list(hi)],
                                  f"a box holding triangles of panel {fused.panel!r}")
        scale[inside] += fused.stretch / modulus
        bending[inside] += fused.bending / material.bending if material.bending > 0 else 0.0
        share = np.repeat(fused.density * triangle_areas(positions, tri[inside]) / 3.0, 3)
        added += np.bincount(tri[inside].ravel(), weights=share, minlength=positions.shape[0])
    return scale, bending, added


def garment_arrays(model: Model, cfg: SceneConfig, garments: list, offsets: list) -> None:
    """Fill the Model's garment arrays (grain, fused factors, stitches) for
    the pieces that are patterns; other pieces keep their material's weft."""
    nt = model.triangles.shape[0]
    weft = np.zeros((nt, 3))
    scale, tri_bending = np.ones(nt), np.ones(nt)
    pairs, index, stitch_count = [], [], 0
    for spec, info, garment, offset in zip(cfg.cloth, model.pieces, garments, offsets):
        rows = slice(info.triangle_start, info.triangle_stop)
        if garment is None:
            weft[rows] = spec.material.weft
            continue
        weft[rows] = garment.triangle_weft
        scale[rows] = garment.triangle_scale
        tri_bending[rows] = garment.triangle_bending
        pairs.append(garment.pattern.stitch_pairs + offset)
        index.append(garment.pattern.stitch_index + stitch_count)
        stitch_count += len(garment.pattern.stitches)
    model.triangle_weft = weft
    if np.any(scale != 1.0):
        model.triangle_scale = scale
    if model.hinge_vertices is not None and np.any(tri_bending != 1.0):
        _, tri_a, _, tri_b, _ = hinge_triangles(model.triangles)
        # a hinge inside a fused region: both its triangles are
        model.hinge_scale = np.minimum(tri_bending[tri_a], tri_bending[tri_b])
    n = model.num_vertices
    model.pattern_vertex = np.arange(n, dtype=np.int64)
    pairs = np.concatenate(pairs) if pairs else np.zeros((0, 2), np.int64)
    if pairs.shape[0] == 0:
        return
    model.stitch_pairs = pairs.astype(np.int64)
    model.stitch_index = np.concatenate(index).astype(np.int64)
    start = model.start_positions()
    model.stitch_gap = np.linalg.norm(start[pairs[:, 0]] - start[pairs[:, 1]], axis=1)
    model.same_vertex = canonical_vertex(n, pairs)


def check_garment_start(cfg: SceneConfig, model: Model, bodies: list) -> None:
    """Refuse a garment that starts inside a body or crossing itself, naming
    the offending vertices and triangles (every rank, on the same global
    model: the same answer everywhere)."""
    x = model.start_positions()
    for body, spec in zip(bodies, [c for c in cfg.colliders if c.shape == "mesh"]):
        report = body_intersections(x, model.triangles, body, None)
        if not report.ok:
            raise ConfigError("cloth", "start positions", f"a garment clear of collider "
                              f"{spec.name!r}: {describe(report)} (garment.clearance moves "
                              f"panels out; 0 keeps the pattern's placement)")
    crossing = self_intersections(x, model.triangles, model.same_vertex)
    if crossing.shape[0]:
        raise ConfigError("cloth", "start positions", "garment panels that do not cross each "
                          f"other: {describe(crossing)}")
