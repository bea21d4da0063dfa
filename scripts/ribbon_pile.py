#!/usr/bin/env python3
"""What the ribbon piles into: folds, layers, self-contacts, energy, a picture.

Reads a result file of configs/ribbon.yaml (or any run of a single grid
ribbon) serially and reports

* folds: direction reversals of the centreline along the ribbon's length
  (the mean of each grid row across the width), counted as turning points of
  its coordinate along the pile's main horizontal axis (the principal axis of
  the centreline's x-y positions) with a hysteresis of ``--fold-min`` (a
  wiggle smaller than that is not a fold);
* layers: vertical rays on an x-y grid of ``--ray-step`` spacing through the
  final frame's triangles; the largest number of crossings, where, and at
  what heights;
* self-contacts at the end: cloth vertex-face and edge-edge pairs that share
  no vertex and are closer than the cloth thickness (the serial BVH of
  distcloth/collision/bvh.py and traverse.py for candidates, the exact
  distances of proximity.py), and the crossing triangle pairs (tritri.py):
  those sharing no vertex, which the ``self_intersections`` diagnostic
  counts, and those sharing one, which it leaves out;
* the largest ``self_intersections`` diagnostic over the run;
* energy: the largest rise of the total energy above its running minimum,
  in J and as a fraction of the energy guard's scale S = KE + |U_elastic| +
  M |g| L (distcloth/energy_guard.py; M from the mesh and the density, L the
  rest bounding-box diagonal, KE and U_elastic from the first step's row),
  and the largest excess over the start energy (the guard's own measure);
* the largest strain (diagnostic ``max_strain``) over the run and at the end;
* the time the steps took: the sum of the stage times of rank 0 (the run's
  setup, numba compilation and the writing of previews are not in the file).

With ``--png``, a close-up of the final pile: a perspective view rendered
with a z-buffer (the painter's sort of matplotlib's 3D axes mixes up the
layers of a pile), the cloth coloured by height and Lambert-shaded, the
colliders from /colliders in light grey, clipped to a box around the cloth,
and beside it the map of the layer count.

    .venv/bin/python scripts/ribbon_pile.py out/ribbon.h5 --png docs/ribbon_pile.png
"""
from __future__ import annotations

import argparse
import json
import sys

import matplotlib
import numpy as np
import yaml
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.cm import ScalarMappable
from matplotlib.colors import Normalize
from matplotlib.figure import Figure
from numba import njit

from distcloth.collision import bvh as B
from distcloth.collision.proximity import (edge_edge_contacts, mesh_edges, point_triangle,
                                          vertex_face_contacts)
from distcloth.collision.traverse import cross_pairs, self_pairs
from distcloth.collision.tritri import self_intersecting_pairs
from distcloth.io.h5read import read_result


# ------------------------------------------------------------------ measures
def centreline(x, nu, nv):
    """(nv, 3): the mean of each grid row (rows run along the length)."""
    return x.reshape(nv, nu, 3).mean(axis=1)


def main_axis(points_xy):
    """Unit principal direction of 2-D points."""
    c = points_xy - points_xy.mean(axis=0)
    _, _, vt = np.linalg.svd(c, full_matrices=False)
    return vt[0]


def turning_points(p, tol):
    """Indices where the sequence ``p`` reverses direction by more than
    ``tol`` (a zigzag with hysteresis): each is a fold."""
    turns, direction, extreme = [], 0, 0
    for i in range(1, len(p)):
        if direction == 0:                       # not yet moved tol from the start
            if abs(p[i] - p[0]) > tol:
                direction, extreme = (1 if p[i] > p[0] else -1), i
        elif (p[i] - p[extreme]) * direction > 0:
            extreme = i                          # further the same way
        elif (p[extreme] - p[i]) * direction > tol:
            turns.append(extreme)                # back by more than tol: a fold
            direction, extreme = -direction, i
    return turns


@njit(cache=True)
def _ray_counts(x, tri, x0, y0, step, nx, ny, count, zmin, zmax):
    """Crossings of vertical rays at (x0 + i step, y0 + j step) with the triangles."""
    for t in range(tri.shape[0]):
        a = x[tri[t, 0]]; b = x[tri[t, 1]]; c = x[tri[t, 2]]
        det = (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1])
        if abs(det) < 1e-18:
            continue
        lo_x = min(a[0], b[0], c[0]); hi_x = max(a[0], b[0], c[0])
        lo_y = min(a[1], b[1], c[1]); hi_y = max(a[1], b[1], c[1])
        i0 = max(0, int(np.ceil((lo_x - x0) / step))); i1 = min(nx - 1, int(np.floor((hi_x - x0) / step)))
        j0 = max(0, int(np.ceil((lo_y - y0) / step))); j1 = min(ny - 1, int(np.floor((hi_y - y0) / step)))
        for i in range(i0, i1 + 1):
            px = x0 + i * step
            for j in range(j0, j1 + 1):
                py = y0 + j * step
                w1 = ((px - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (py - a[1])) / det
                w2 = ((b[0] - a[0]) * (py - a[1]) - (px - a[0]) * (b[1] - a[1])) / det
                w0 = 1.0 - w1 - w2
                if w0 >= 0.0 and w1 >= 0.0 and w2 >= 0.0:
                    z = w0 * a[2] + w1 * b[2] + w2 * c[2]
                    count[i, j] += 1
                    zmin[i, j] = min(zmin[i, j], z)
                    zmax[i, j] = max(zmax[i, j], z)


def layer_map(x, tri, step):
    """Layer counts on an x-y grid over the cloth: (count (nx, ny), xs, ys, zmin, zmax).
    The grid is shifted by an irrational fraction of a step so that no ray
    meets a mesh edge or vertex exactly (a shared edge would count twice)."""
    lo, hi = x[:, :2].min(axis=0), x[:, :2].max(axis=0)
    shift = step * np.array([0.5 * (np.sqrt(5.0) - 1.0), np.sqrt(2.0) - 1.0])
    x0, y0 = lo + shift - step
    nx = int(np.ceil((hi[0] - x0) / step)) + 2
    ny = int(np.ceil((hi[1] - y0) / step)) + 2
    count = np.zeros((nx, ny), dtype=np.int64)
    zmin = np.full((nx, ny), np.inf)
    zmax = np.full((nx, ny), -np.inf)
    _ray_counts(np.ascontiguousarray(x, dtype=np.float64), np.ascontiguousarray(tri, np.int64),
                x0, y0, step, nx, ny, count, zmin, zmax)
    return count, x0 + step * np.arange(nx), y0 + step * np.arange(ny), zmin, zmax


def self_contacts(x, tri, thickness):
    """(vertex-face pairs, edge-edge pairs) closer than ``thickness`` that share
    no vertex, and the crossing triangle pairs, at positions x (serial BVH)."""
    tri = np.ascontiguousarray(tri, dtype=np.int64)
    edges = mesh_edges(tri)
    pts = np.arange(x.shape[0], dtype=np.int64)[:, None]
    pad = float(thickness)      # boxes padded by d each: every pair within d is a candidate
    vb = B.build_bvh(pts, x, x, pad)
    fb = B.build_bvh(tri, x, x, pad)
    eb = B.build_bvh(edges, x, x, pad)
    vf = vertex_face_contacts(x, tri, cross_pairs(vb, fb), thickness)
    ee = edge_edge_contacts(x, edges, self_pairs(eb), thickness)
    tb = B.build_bvh(tri, x, x, 0.0)
    crossing = self_intersecting_pairs(x, tri, self_pairs(tb))
    a, b = tri[crossing[:, 0]], tri[crossing[:, 1]]
    shared = (a[:, :, None] == b[:, None, :]).any(axis=(1, 2))
    return vf, ee, crossing[~shared], crossing[shared]


def energy_scale(res, cfg):
    """S of the energy guard: |KE| + |U_elastic| (first step's row) + M |g| L."""
    x = res["rest_positions"]
    tri = res["triangles"]
    area = 0.5 * np.linalg.norm(np.cross(x[tri[:, 1]] - x[tri[:, 0]],
                                         x[tri[:, 2]] - x[tri[:, 0]]), axis=1)
    density = float(cfg["cloth"][0]["material"].get("density", 0.1))
    mass = density * area.sum()
    g = float(np.linalg.norm(cfg.get("gravity", [0.0, 0.0, -9.81])))
    size = float(np.linalg.norm(x.max(axis=0) - x.min(axis=0)))
    d = res["diagnostics"]
    scale = abs(d["kinetic_energy"][0]) + abs(d["elastic_energy"][0]) + mass * g * size
    return scale, mass, size


# ------------------------------------------------------------------ picture
@njit(cache=True)
def _raster(sx, sy, sz, tri, color, img, depth):
    """z-buffer: fill each screen triangle (pixel centres), its corner colours
    (T, 3, 3) interpolated (Gouraud)."""
    H, W = depth.shape
    for t in range(tri.shape[0]):
        i, j, k = tri[t, 0], tri[t, 1], tri[t, 2]
        if sz[i] <= 0.0 or sz[j] <= 0.0 or sz[k] <= 0.0:
            continue
        ax, ay, bx, by, cx, cy = sx[i], sy[i], sx[j], sy[j], sx[k], sy[k]
        det = (bx - ax) * (cy - ay) - (cx - ax) * (by - ay)
        if abs(det) < 1e-12:
            continue
        x0 = max(0, int(np.floor(min(ax, bx, cx)))); x1 = min(W - 1, int(np.ceil(max(ax, bx, cx))))
        y0 = max(0, int(np.floor(min(ay, by, cy)))); y1 = min(H - 1, int(np.ceil(max(ay, by, cy))))
        for py in range(y0, y1 + 1):
            fy = py + 0.5
            for px in range(x0, x1 + 1):
                fx = px + 0.5
                w1 = ((fx - ax) * (cy - ay) - (cx - ax) * (fy - ay)) / det
                w2 = ((bx - ax) * (fy - ay) - (fx - ax) * (by - ay)) / det
                w0 = 1.0 - w1 - w2
                if w0 < 0.0 or w1 < 0.0 or w2 < 0.0:
                    continue
                # perspective-correct depth: interpolate 1/z
                z = 1.0 / (w0 / sz[i] + w1 / sz[j] + w2 / sz[k])
                if z < depth[py, px]:
                    depth[py, px] = z
                    for ch in range(3):
                        img[py, px, ch] = (w0 * color[t, 0, ch] + w1 * color[t, 1, ch]
                                           + w2 * color[t, 2, ch])


@njit(cache=True)
def _mesh_distance(x, tris, out):
    """out[i] = min(out[i], distance of x[i] to the triangles (m, 3, 3))."""
    for i in range(x.shape[0]):
        for t in range(tris.shape[0]):
            d = point_triangle(x[i], tris[t, 0], tris[t, 1], tris[t, 2])[0]
            if d < out[i]:
                out[i] = d


def plane_of(quad):
    """(point, unit normal) of a stored plane square (4 corners)."""
    n = np.cross(quad[1] - quad[0], quad[3] - quad[0])
    return quad[0], n / np.linalg.norm(n)


def height_above_bodies(x, colliders):
    """Each vertex's distance to the nearest collider surface (last frame):
    the height of the cloth above its support, whatever the slope."""
    out = np.full(x.shape[0], np.inf)
    for body in colliders.values():
        rows = body["positions"][-1]
        if body["shape"] == "plane":
            p, n = plane_of(rows)
            out = np.minimum(out, np.abs((x - p) @ n))
        else:
            _mesh_distance(np.ascontiguousarray(x), np.ascontiguousarray(rows[body["triangles"]]), out)
    return out


def clip_to_box(polys, lo, hi):
    """Sutherland-Hodgman: each polygon (list of (3,) points) clipped to the box,
    fanned back into triangles; returns (k, 3, 3)."""
    out = []
    for poly in polys:
        pts = [np.asarray(p, float) for p in poly]
        for axis in range(3):
            for sign, bound in ((1.0, lo[axis]), (-1.0, hi[axis])):
                if not pts:
                    break
                new = []
                for a, b in zip(pts, pts[1:] + pts[:1]):
                    da, db = sign * (a[axis] - bound), sign * (b[axis] - bound)
                    if da >= 0:
                        new.append(a)
                    if (da >= 0) != (db >= 0):
                        new.append(a + (b - a) * (da / (da - db)))
                pts = new
        for k in range(1, len(pts) - 1):
            out.append([pts[0], pts[k], pts[k + 1]])
    return np.array(out).reshape(-1, 3, 3)


def subdivide(tris, max_edge):
    """Split triangles (k, 3, 3) at edge midpoints until no edge exceeds
    max_edge (a few large body faces would otherwise be shaded flat)."""
    for _ in range(12):
        e = np.linalg.norm(tris - np.roll(tris, 1, axis=1), axis=2).max(axis=1)
        big = e > max_edge
        if not big.any():
            break
        t = tris[big]
        a, b, c = t[:, 0], t[:, 1], t[:, 2]
        ab, bc, ca = (a + b) / 2, (b + c) / 2, (c + a) / 2
        new = np.concatenate([np.stack(q, axis=1) for q in
                              ((a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca))])
        tris = np.concatenate([tris[~big], new])
    return tris


def collider_triangles(colliders, lo, hi, max_edge):
    """The colliders' last-frame surfaces in the box [lo, hi]: meshes clipped
    to it, planes as a square through the box (the stored square lies under
    the cloth's start, which the cloth may have left)."""
    polys = []
    centre, half = 0.5 * (lo + hi), float(np.linalg.norm(hi - lo))
    for body in colliders.values():
        rows = body["positions"][-1]
        if body["shape"] == "plane":
            p, n = plane_of(rows)
            c = centre - ((centre - p) @ n) * n
            a = rows[1] - rows[0]
            a /= np.linalg.norm(a)
            b = np.cross(n, a)
            polys.append([c + half * (sa * a + sb * b)
                          for sa, sb in ((-1, -1), (1, -1), (1, 1), (-1, 1))])
        else:
            polys += [list(rows[t]) for t in body["triangles"]]
    tris = clip_to_box(polys, lo, hi)
    return subdivide(tris, max_edge) if len(tris) else tris


def render(cloth_x, cloth_tri, cloth_rgb, bodies, eye_dir, frame_points, size, fov=30.0):
    """RGB image (H, W, 3): cloth and bodies seen from ``eye_dir`` (unit, from
    the target to the eye), perspective, framed on ``frame_points``; z-buffered,
    Lambert plus a headlight, dark lines where the depth jumps (fold edges)."""
    H, W = size
    lo, hi = frame_points.min(axis=0), frame_points.max(axis=0)
    target = 0.5 * (lo + hi)
    radius = 0.5 * np.linalg.norm(hi - lo)
    dist = 1.2 * radius / np.tan(np.radians(fov / 2))
    eye = target + dist * eye_dir
    fwd = (target - eye) / np.linalg.norm(target - eye)
    right = np.cross(fwd, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)

    def camera(p):
        q = p - eye
        z = q @ fwd
        return (q @ right) / np.maximum(z, 1e-9), (q @ up) / np.maximum(z, 1e-9), z

    # focal length and centre that fit the framed points into 90 % of the image
    u, v, _ = camera(frame_points)
    f = 0.9 * min(W / max(np.ptp(u), 1e-12), H / max(np.ptp(v), 1e-12))
    u0, v0 = 0.5 * (u.min() + u.max()), 0.5 * (v.min() + v.max())
    light = np.array([0.3, -0.5, 0.8])
    light /= np.linalg.norm(light)

    def lambert(n):
        return 0.3 + 0.45 * np.clip(n @ light, 0, 1) + 0.3 * np.clip(n @ (-fwd), 0, 1)

    def face_normals(tris):
        n = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
        return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)

    # cloth: vertex normals (area-weighted), each corner turned to the side of
    # its face that faces the eye; corner colours = colour map x light
    cloth_tris = cloth_x[cloth_tri]
    fn = np.cross(cloth_tris[:, 1] - cloth_tris[:, 0], cloth_tris[:, 2] - cloth_tris[:, 0])
    vn = np.zeros_like(cloth_x)
    for c in range(3):
        np.add.at(vn, cloth_tri[:, c], fn)
    vn /= np.maximum(np.linalg.norm(vn, axis=1, keepdims=True), 1e-30)
    facing = np.where(fn @ (-fwd) < 0, -1.0, 1.0)
    corner_n = vn[cloth_tri] * facing[:, None, None]
    cloth_col = np.clip(cloth_rgb[cloth_tri] * lambert(corner_n)[..., None], 0, 1)
    tris, color = [cloth_tris], [cloth_col]
    if len(bodies):
        n = face_normals(bodies)
        n *= np.where(n @ (-fwd) < 0, -1.0, 1.0)[:, None]
        col = np.clip(0.88 * lambert(n), 0, 1)
        tris.append(bodies)
        color.append(np.repeat(np.repeat(col[:, None, None], 3, axis=1), 3, axis=2))
    tris, color = np.concatenate(tris), np.ascontiguousarray(np.concatenate(color))
    u, v, z = camera(tris.reshape(-1, 3))
    sx = W / 2 + f * (u - u0)
    sy = H / 2 - f * (v - v0)
    img = np.ones((H, W, 3))
    depth = np.full((H, W), np.inf)
    _raster(sx, sy, z, np.arange(tris.shape[0] * 3, dtype=np.int64).reshape(-1, 3), color, img, depth)
    finite = np.where(np.isfinite(depth), depth, 1e3 * dist)
    jump = np.zeros_like(depth)
    jump[:, 1:] = np.abs(np.diff(finite, axis=1))
    jump[1:, :] = np.maximum(jump[1:, :], np.abs(np.diff(finite, axis=0)))
    # a jump of more than ~1.5 pixel footprints at that depth: an edge in front of a farther surface
    img[jump > 1.5 * finite / f + 0.002 * dist] *= 0.3
    return img


def picture(path_png, x, tri, colliders, counts, xs, ys, where, summary):
    height = 1e3 * height_above_bodies(x, colliders)
    hmax = float(np.percentile(height, 99.5))
    norm = Normalize(0.0, hmax)
    cmap = matplotlib.colormaps["viridis"]
    rgb = cmap(norm(height))[:, :3]         # per vertex
    lo, hi = x.min(axis=0), x.max(axis=0)
    margin = 0.15 * float((hi - lo).max())
    box_lo, box_hi = lo - margin, hi + margin
    box_lo[2] = lo[2] - 0.3 * margin
    bodies = collider_triangles(colliders, box_lo, box_hi, 0.04 * float((hi - lo).max()))
    axis = main_axis(x[:, :2])
    side = np.array([-axis[1], axis[0], 0.0])
    if side @ np.array([1.0, 1.0, 0.0]) < 0:
        side = -side
    along = np.array([axis[0], axis[1], 0.0])

    def eye(elevation, turn):
        e = np.cos(np.radians(elevation)) * (np.cos(np.radians(turn)) * side
                                              + np.sin(np.radians(turn)) * along)
        return e + np.array([0.0, 0.0, np.sin(np.radians(elevation))])

    # the close-up: the cross-section of the pile through the thickest point,
    # seen from the ribbon's side nearest to it, low: the cloth within 0.2 m of
    # it along the pile's axis
    if side[:2] @ (np.asarray(where) - 0.5 * (lo[:2] + hi[:2])) < 0:
        side = -side
    near = np.abs((x[:, :2] - np.asarray(where)) @ axis) < 0.2
    fig = Figure(figsize=(16, 12))
    FigureCanvasAgg(fig)
    gs = fig.add_gridspec(2, 2, width_ratios=[1.6, 1], height_ratios=[1, 1])
    ax = fig.add_subplot(gs[0, 0])
    ax.imshow(render(x, tri, rgb, bodies, eye(32, 25), x, (620, 1000)))
    ax.set_axis_off()
    ax.set_title("the whole ribbon at the end, colliders grey")
    ax = fig.add_subplot(gs[1, :])
    ax.imshow(render(x, tri, rgb, bodies, eye(14, -20), x[near], (680, 1500)))
    ax.set_axis_off()
    ax.set_title(f"close-up: 0.4 m of the pile around its thickest point ({int(counts.max())} "
                 "layers, + on the map), from the side")
    fig.colorbar(ScalarMappable(norm=norm, cmap=cmap), ax=ax, fraction=0.02, pad=0.01,
                 label="height above the bodies (mm)")
    ax = fig.add_subplot(gs[0, 1])
    shown = np.where(counts > 0, counts, np.nan)
    m = ax.imshow(shown.T, origin="lower", extent=(xs[0], xs[-1], ys[0], ys[-1]),
                  cmap="magma_r", interpolation="nearest", vmin=0.5,
                  vmax=max(int(counts.max()), 1) + 0.5)
    ax.plot([where[0]], [where[1]], "c+", ms=16, mew=2.5)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_aspect("equal")
    ax.set_title("layers crossed by a vertical ray")
    fig.colorbar(m, ax=ax, fraction=0.046, pad=0.02, label="layers",
                 ticks=range(1, int(counts.max()) + 1))
    fig.suptitle(summary, fontsize=11)
    fig.tight_layout()
    fig.savefig(path_png, dpi=100)


# ------------------------------------------------------------------ main
def analyse(path, fold_min, ray_step):
    res = read_result(path, frames=[-1])
    cfg = yaml.safe_load(res["config"])
    piece = cfg["cloth"][0]
    nu, nv = piece["mesh"]["grid"]["resolution"]
    thickness = float(piece.get("thickness", 0.001))
    x = res["positions"][-1]
    tri = res["triangles"]
    d = res["diagnostics"]
    line = centreline(x, nu, nv)
    axis = main_axis(line[:, :2])
    p = line[:, :2] @ axis
    folds = turning_points(p, fold_min)
    counts, xs, ys, zmin, zmax = layer_map(x, tri, ray_step)
    i, j = np.unravel_index(int(np.argmax(counts)), counts.shape)
    vf, ee, crossing, neighbour_crossing = self_contacts(x, tri, thickness)
    scale, mass, size = energy_scale(res, cfg)
    E = d["total_energy"]
    rise = E - np.minimum.accumulate(E)
    k_rise = int(np.argmax(rise))
    si = d.get("self_intersections", np.array([np.nan]))
    stage = sum(np.asarray(v, dtype=float) for v in res["stage_time"].values())
    out = {
        "file": str(path),
        "status": res["attrs"].get("status"),
        "error": res["attrs"].get("error", ""),
        "time_end": float(res["time"][-1]),
        "steps": int(res["steps_written"]),
        "vertices": int(x.shape[0]),
        "thickness_m": thickness,
        "folds": len(folds),
        "fold_rows": [int(r) for r in folds],
        "fold_axis_xy": [float(a) for a in axis],
        "max_layers": int(counts[i, j]),
        "max_layers_at_xy": [float(xs[i]), float(ys[j])],
        "max_layers_z_range_m": [float(zmin[i, j]), float(zmax[i, j])],
        "area_with_2plus_layers_m2": float((counts >= 2).sum() * ray_step ** 2),
        "area_by_layers_cm2": {int(k): round(float(n * ray_step ** 2 * 1e4), 1)
                               for k, n in enumerate(np.bincount(counts.ravel())) if k and n},
        "self_contacts_vf": int(len(vf.vertex)),
        "self_contacts_ee": int(len(ee.edge_a)),
        "self_contacts_below_half_thickness": int((vf.distance < 0.5 * thickness).sum()
                                                  + (ee.distance < 0.5 * thickness).sum()),
        "self_contact_min_distance_m": float(min(vf.distance.min(initial=np.inf),
                                                 ee.distance.min(initial=np.inf))),
        "crossing_triangle_pairs_end": int(len(crossing)),
        "crossing_vertex_neighbours_end": int(len(neighbour_crossing)),
        "max_self_intersections_run": float(np.nanmax(si)) if np.isfinite(si).any() else None,
        "energy_scale_S_J": float(scale),
        "cloth_mass_kg": float(mass),
        "energy_start_J": float(E[0]),
        "energy_end_J": float(E[-1]),
        "energy_max_rise_J": float(rise[k_rise]),
        "energy_max_rise_over_S": float(rise[k_rise] / scale),
        "energy_max_rise_time_s": float(d["time"][k_rise]),
        "energy_max_excess_over_start_over_S": float((E.max() - E[0]) / scale),
        "max_strain_run": float(np.nanmax(d["max_strain"])),
        "max_strain_end": float(d["max_strain"][-1]),
        "max_penetration_run_m": float(np.nanmax(d["max_penetration"])),
        "contact_work_J": float(np.nansum(d["contact_work"])),
        "friction_work_J": float(np.nansum(d["friction_work"])),
        "failsafe_work_J": float(np.nansum(d["failsafe_work"])),
        "impulse_work_J": float(np.nansum(d.get("impulse_work", np.zeros(1)))),
        "step_time_s": float(stage.sum()),
        "solves_per_step_mean": float(np.mean(res["stage_calls"]["solve"])),
    }
    return out, (x, tri, res["colliders"], counts, xs, ys, (xs[i], ys[j]))


def report(r):
    lines = [
        f"{r['file']}: {r['status']}{' (' + r['error'] + ')' if r['error'] else ''}, "
        f"t = {r['time_end']:.2f} s, {r['steps']} steps, {r['vertices']} vertices",
        f"folds (centreline reversals along the pile's axis): {r['folds']} at rows {r['fold_rows']}",
        f"most layers on a vertical ray: {r['max_layers']} at x = {r['max_layers_at_xy'][0]:.3f}, "
        f"y = {r['max_layers_at_xy'][1]:.3f} m (z {1e3 * r['max_layers_z_range_m'][0]:.1f} to "
        f"{1e3 * r['max_layers_z_range_m'][1]:.1f} mm); 2 or more layers over "
        f"{1e4 * r['area_with_2plus_layers_m2']:.0f} cm²; area (cm²) by layer count "
        + ", ".join(f"{k}: {a:g}" for k, a in r["area_by_layers_cm2"].items()),
        f"self-contacts at the end (closer than {1e3 * r['thickness_m']:g} mm, no shared vertex): "
        f"{r['self_contacts_vf']} vertex-face, {r['self_contacts_ee']} edge-edge, "
        f"{r['self_contacts_below_half_thickness']} of them closer than half of it, the closest "
        f"{1e3 * r['self_contact_min_distance_m']:.2f} mm",
        f"crossing triangle pairs at the end: {r['crossing_triangle_pairs_end']} sharing no vertex "
        f"(as the diagnostic counts), {r['crossing_vertex_neighbours_end']} sharing one "
        f"(a triangle folded through a neighbour at a sharp crease)",
        f"largest self_intersections over the run: {r['max_self_intersections_run']}",
        f"energy: {r['energy_start_J']:.4f} J at the first step, {r['energy_end_J']:.4f} J at the end; "
        f"largest rise above the running minimum {r['energy_max_rise_J']:.4g} J = "
        f"{r['energy_max_rise_over_S']:.3g} S (t = {r['energy_max_rise_time_s']:.3f} s), "
        f"largest excess over the start {r['energy_max_excess_over_start_over_S']:.3g} S; "
        f"S = {r['energy_scale_S_J']:.4g} J",
        f"largest strain: {r['max_strain_run']:.3f} over the run, {r['max_strain_end']:.3f} at the end",
        f"works over the run: contact {r['contact_work_J']:.4g} J, friction {r['friction_work_J']:.4g} J, "
        f"fail-safe {r['failsafe_work_J']:.4g} J, impulses {r['impulse_work_J']:.4g} J; "
        f"max penetration before the fail-safe {1e3 * r['max_penetration_run_m']:.2f} mm",
        f"solves per step {r['solves_per_step_mean']:.2f}; time in the steps (rank 0 stage "
        f"times) {r['step_time_s']:.1f} s",
    ]
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("result", help="result file of a ribbon run")
    ap.add_argument("--png", help="write the close-up picture here")
    ap.add_argument("--json", help="write the figures here as JSON")
    ap.add_argument("--fold-min", type=float, default=0.02,
                    help="m: a reversal of the centreline smaller than this is not a fold")
    ap.add_argument("--ray-step", type=float, default=0.002, help="m: spacing of the vertical rays")
    args = ap.parse_args(argv)
    r, pic = analyse(args.result, args.fold_min, args.ray_step)
    print(report(r))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(r, fh, indent=1)
    if args.png:
        summary = (f"{r['folds']} folds, at most {r['max_layers']} layers, "
                   f"{r['self_contacts_vf']} + {r['self_contacts_ee']} self-contacts at the end, "
                   f"t = {r['time_end']:.2f} s")
        picture(args.png, *pic, summary)
        print(f"picture: {args.png}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
