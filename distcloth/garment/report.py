"""Figures of a meshed pattern, as Markdown tables (the ones in docs/garments.md):

    python -m distcloth.garment.report PATTERN... [--edge 0.02]

Per panel: outline, vertex and triangle counts, the smallest angle, the
shortest, median and longest edge over the target, and the hinge-star
residual (how far the mesh is from those on which per-hinge bending, the
default on patterns, is the plate: physics/hinge_consistency.py, warned
above 0.3 for mesh files); per stitch: the two
sides' arc lengths and their mismatch, (a - b) / max(a, b).
"""
from __future__ import annotations

import argparse

import numpy as np

from ..physics.hinge_consistency import star_residual
from .mesh import GarmentMesh, mesh_pattern, triangle_angles
from .pattern import Pattern, SeamSide, load_pattern


def edge_lengths(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Length of every distinct edge of a triangle mesh."""
    e = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
    e = np.unique(np.sort(e, axis=1), axis=0)
    return np.linalg.norm(points[e[:, 0]] - points[e[:, 1]], axis=1)


def side_length(pattern: Pattern, side: SeamSide) -> float:
    panel = pattern.panel(side.panel)
    return float(sum(panel.edges[e].length() for e in side.edges))


def _side_name(side: SeamSide) -> str:
    edges = ",".join(map(str, side.edges))
    return f"{side.panel}:{edges}{' (reversed)' if side.reverse else ''}"


def panel_table(mesh: GarmentMesh) -> list[str]:
    h = mesh.target_edge
    rows = ["| panel | outline | vertices | triangles | min angle (°) | edge / h: min | median "
            "| max | hinge-star residual |", "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for p in mesh.panels:
        angle = triangle_angles(p.vertices, p.triangles).min()
        length = edge_lengths(p.vertices, p.triangles) / h
        flat = np.column_stack([p.vertices, np.zeros(p.vertices.shape[0])])
        rows.append(f"| {p.panel.name} | {p.n_outline} | {p.vertices.shape[0]} | "
                    f"{p.triangles.shape[0]} | {angle:.1f} | {length.min():.2f} | "
                    f"{np.median(length):.2f} | {length.max():.2f} | "
                    f"{star_residual(flat, p.triangles):.2f} |")
    total_v = sum(p.vertices.shape[0] for p in mesh.panels)
    total_t = sum(p.triangles.shape[0] for p in mesh.panels)
    rows.append(f"| all | | {total_v} | {total_t} | | | | | |")
    return rows


def seam_table(mesh: GarmentMesh) -> list[str]:
    rows = ["| # | side a | side b | label | a (cm) | b (cm) | mismatch | pairs |",
            "|---:|---|---|---|---:|---:|---:|---:|"]
    for k, s in enumerate(mesh.seams):
        a = side_length(mesh.pattern, s.stitch.a)
        b = side_length(mesh.pattern, s.stitch.b)
        rows.append(f"| {k} | {_side_name(s.stitch.a)} | {_side_name(s.stitch.b)} | "
                    f"{s.stitch.label or ''} | {100 * a:.2f} | {100 * b:.2f} | "
                    f"{100 * (a - b) / max(a, b):+.2f} % | {s.pairs.shape[0]} |")
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("patterns", nargs="+")
    parser.add_argument("--edge", type=float, default=0.02, help="target edge length, m")
    args = parser.parse_args(argv)
    for path in args.patterns:
        pattern = load_pattern(path)
        mesh = mesh_pattern(pattern, args.edge)
        print(f"\n### {pattern.name}, target edge {100 * args.edge:g} cm\n")
        print("\n".join(panel_table(mesh)))
        print()
        print("\n".join(seam_table(mesh)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
