"""Quick-look pictures of a result file (rank 0, after the run, serial read).

``<stem>_frames.png``: the first, two intermediate and the last written frame
as Lambert-shaded surfaces in one common, equal-aspect bounding box, with the
colliders where they were at each frame, semi-transparent grey.  The box
holds the cloth and the bounded bodies, but these no further than one cloth
size from the cloth (a huge body or terrain must not shrink the cloth to a
dot); a plane is drawn as a square filling the box.
``<stem>_views.png`` (scenes with a mesh collider, a body): the last frame
from the front and from the side, orthographic, the body whole.
``<stem>_energy.png``: energies, solver iterations and the stage-time split.

Uses matplotlib's object API with the Agg canvas (no pyplot, no global
backend switch), so it is safe to call from inside any program.
"""
from __future__ import annotations

import os

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator, MultipleLocator, NullLocator
from mpl_toolkits.mplot3d.art3d import Poly3DCollection

from distcloth.io.h5read import read_attrs, read_result

# Poly3DCollection costs ~20 us per polygon to sort and draw; beyond this
# many triangles per panel the mesh is decimated for the picture.
MAX_PREVIEW_TRIANGLES = 30000
# The colliders of a panel share this many triangles (an even split); a mesh
# with more is decimated like the cloth, by vertex clustering on its first row.
MAX_COLLIDER_TRIANGLES = 10000
# A plane's square is cut into this many cells per side: the painter's sort
# orders whole triangles, and two triangles as large as the picture would
# hide the cloth's front or show its back through them.
PLANE_CELLS = 12
_CLOTH_RGB = np.array([0.30, 0.52, 0.80])
_BODY_RGB = np.array([0.60, 0.60, 0.60])
BODY_ALPHA = 0.35
_LIGHT = np.array([0.35, -0.45, 0.82]) / np.linalg.norm([0.35, -0.45, 0.82])
# The views: (title, matplotlib azimuth).  Result files are z-up and a y-up
# body mesh is turned (x, y, z) -> (x, -z, y), so its front faces -y: the
# front view looks from -y, the side view from +x.
VIEWS = (("front", -90.0), ("side", 0.0))
# A little from above: the shoulders and the garment's top edge show.
VIEW_ELEV = 8.0
# The views are of the dressed body: a body up to this many cloth sizes from
# the cloth is shown whole (a skirt's wearer from head to feet).
VIEW_REACH = 3.0
ENERGY_NAMES = ("kinetic_energy", "gravitational_energy", "elastic_energy", "total_energy")
ITERATION_NAMES = ("ksp_iterations", "newton_iterations")


def pick_frames(n_frames: int, count: int = 4) -> list[int]:
    """``count`` frame indices spread from the first to the last (fewer if not available)."""
    if n_frames <= 0:
        return []
    return sorted(set(np.round(np.linspace(0, n_frames - 1, count)).astype(int).tolist()))


def decimate(rest: np.ndarray, triangles: np.ndarray, target: int) -> tuple[np.ndarray, np.ndarray]:
    """Vertex clustering on the rest shape: (cluster of each vertex, triangles
    between clusters) with about ``target`` triangles at most.

    Clustering in the rest shape keeps one coarse mesh for all frames, and
    unlike dropping random triangles it leaves no holes.  Each coarse vertex
    is later placed at the mean of its cluster.
    """
    nt = triangles.shape[0]
    edges = rest[triangles[:, [1, 2, 0]]] - rest[triangles]
    h = np.mean(np.linalg.norm(edges, axis=2)) * np.sqrt(nt / target)
    lo = rest.min(axis=0)
    for _ in range(8):
        cells = np.floor((rest - lo) / h).astype(np.int64)
        _, cluster = np.unique(cells, axis=0, return_inverse=True)
        cluster = cluster.ravel()
        t = np.sort(cluster[triangles], axis=1)
        keep = (t[:, 0] != t[:, 1]) & (t[:, 1] != t[:, 2])
        coarse = np.unique(t[keep], axis=0)
        if coarse.shape[0] <= target:
            return cluster, coarse
        h *= 1.1 * np.sqrt(coarse.shape[0] / target)
    return cluster, coarse


def _shade(tri_xyz: np.ndarray, rgb: np.ndarray = _CLOTH_RGB) -> np.ndarray:
    """RGB per triangle: ambient + two-sided Lambert term of its normal."""
    nrm = np.cross(tri_xyz[:, 1] - tri_xyz[:, 0], tri_xyz[:, 2] - tri_xyz[:, 0])
    length = np.linalg.norm(nrm, axis=1, keepdims=True)
    nrm = np.divide(nrm, length, out=np.zeros_like(nrm), where=length > 0)
    lambert = np.abs(nrm @ _LIGHT)           # cloth has two sides: light either
    return np.clip(rgb[None, :] * (0.3 + 0.8 * lambert[:, None]), 0.0, 1.0)


def _cluster_means(cluster: np.ndarray, positions: np.ndarray) -> np.ndarray:
    """Each frame's (frames, n, 3) vertices averaged over the clusters of ``decimate``."""
    counts = np.bincount(cluster).astype(float)
    coarse = np.empty((positions.shape[0], counts.size, 3))
    for f, x in enumerate(positions):
        for c in range(3):
            coarse[f, :, c] = np.bincount(cluster, weights=x[:, c]) / counts
    return coarse


def _bodies(colliders: dict, budget: int) -> tuple[list[dict], int]:
    """The colliders to draw, each decimated to its share of ``budget``
    triangles; and how many were decimated."""
    bodies, decimated = [], 0
    share = budget // max(1, len(colliders))
    for body in colliders.values():
        tri, rows = body["triangles"], body["positions"]
        if rows.shape[0] == 0:
            continue
        if body["shape"] != "plane" and tri.shape[0] > share:
            cluster, tri = decimate(rows[0], tri, share)
            rows = _cluster_means(cluster, rows)
            decimated += 1
        bodies.append({"triangles": tri, "positions": rows, "moving": body["moving"],
                       "plane": body["shape"] == "plane"})
    return bodies, decimated


def _plane_point(quad: np.ndarray, point: np.ndarray) -> np.ndarray:
    """The projection of ``point`` on the plane of a stored square (4 corners)."""
    n = np.cross(quad[1] - quad[0], quad[3] - quad[0])
    n /= np.linalg.norm(n)
    return point - ((point - quad[0]) @ n) * n


def _view(cloth: np.ndarray, bodies: list[dict],
          reach: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """[low, high] of the picture: the cloth's box joined with the bounded
    bodies' boxes and the planes' points under its centre, these cut to
    ``reach`` cloth sizes around the cloth (and left out if wholly beyond)."""
    lo, hi = cloth.reshape(-1, 3).min(axis=0), cloth.reshape(-1, 3).max(axis=0)
    reach *= float((hi - lo).max())
    near_lo, near_hi = lo - reach, hi + reach
    for body in sorted(bodies, key=lambda b: b["plane"]):     # planes last: under the box
        if body["plane"]:
            x = np.array([_plane_point(q, 0.5 * (lo + hi)) for q in body["positions"]])
        else:
            x = body["positions"].reshape(-1, 3)
        b_lo, b_hi = x.min(axis=0), x.max(axis=0)
        if np.any(b_lo > near_hi) or np.any(b_hi < near_lo):
            continue                                  # out of reach: not in the picture
        lo = np.minimum(lo, np.maximum(b_lo, near_lo))
        hi = np.maximum(hi, np.minimum(b_hi, near_hi))
    span = np.maximum(hi - lo, 1e-3 * max(float((hi - lo).max()), 1e-9))
    mid = 0.5 * (lo + hi)
    return mid - 0.5 * span, mid + 0.5 * span


def _plane_cells(quad: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Triangles (2 PLANE_CELLS², 3, 3) of a plane's square (its 4 stored
    corners, collision/surfaces.py) moved under the view's centre and sized
    to the view's largest side."""
    a, b = quad[1] - quad[0], quad[3] - quad[0]
    a, b = a / np.linalg.norm(a), b / np.linalg.norm(b)
    centre = _plane_point(quad, 0.5 * (lo + hi))
    half = 0.5 * float((hi - lo).max())
    s = np.linspace(-half, half, PLANE_CELLS + 1)
    u, v = np.meshgrid(s, s, indexing="ij")
    grid = centre + u[..., None] * a + v[..., None] * b            # (cells + 1, cells + 1, 3)
    p00, p10, p11, p01 = grid[:-1, :-1], grid[1:, :-1], grid[1:, 1:], grid[:-1, 1:]
    return np.concatenate([np.stack([p00, p10, p11], axis=2).reshape(-1, 3, 3),
                           np.stack([p00, p11, p01], axis=2).reshape(-1, 3, 3)])


def _body_triangles(body: dict, frame: int, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """A body's triangles (m, 3, 3) at a picked frame, those whose centre is
    outside the view left out."""
    x = body["positions"][frame if body["moving"] else 0]
    xyz = _plane_cells(x, lo, hi) if body["plane"] else x[body["triangles"]]
    centre = xyz.mean(axis=1)
    slack = 1e-6 * float((hi - lo).max())
    inside = np.all((centre >= lo - slack) & (centre <= hi + slack), axis=1)
    return xyz[inside]


def _prepare(res: dict, max_triangles: int,
             max_collider_triangles: int) -> tuple[np.ndarray, np.ndarray, list[dict], str]:
    """The cloth's triangles and frames and the bodies to draw, decimated to
    the budgets, and a note for the title saying what was decimated."""
    positions, tri = res["positions"], res["triangles"]
    nt = tri.shape[0]
    note = ""
    if nt > max_triangles:
        cluster, tri = decimate(res["rest_positions"], tri, max_triangles)
        positions = _cluster_means(cluster, positions)
        note = f"\n(decimated: {tri.shape[0]} of {nt} triangles)"
    bodies, decimated = _bodies(res.get("colliders", {}), max_collider_triangles)
    if decimated:
        note += f"\n({decimated} collider mesh{'es' if decimated > 1 else ''} decimated)"
    return tri, positions, bodies, note


def _draw(ax, cloth_xyz: np.ndarray, bodies: list[dict], frame: int,
          lo: np.ndarray, hi: np.ndarray, zoom: float = 1.0) -> None:
    """Cloth triangles (opaque) and the bodies at ``frame`` (translucent) in
    the box [lo, hi], at equal aspect."""
    xyz = cloth_xyz
    rgba = np.concatenate([_shade(xyz), np.ones((xyz.shape[0], 1))], axis=1)
    for body in bodies:
        body_xyz = _body_triangles(body, frame, lo, hi)
        body_rgba = np.concatenate([_shade(body_xyz, _BODY_RGB),
                                    np.full((body_xyz.shape[0], 1), BODY_ALPHA)], axis=1)
        xyz = np.concatenate([xyz, body_xyz])
        rgba = np.concatenate([rgba, body_rgba])
    # one collection: the painter's sort then orders cloth and bodies
    # triangle by triangle (between collections it orders whole collections)
    ax.add_collection3d(Poly3DCollection(xyz, facecolors=rgba, edgecolors="none",
                                         linewidths=0))
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_zlim(lo[2], hi[2])
    ax.set_box_aspect(hi - lo, zoom=zoom)   # equal aspect: one metre is one metre on every axis
    ax.tick_params(labelsize=6)


def _when(attrs: dict, t: float) -> str:
    """A frame's label: a drape numbers its frames by iteration, a run by time."""
    return f"iteration {t:.0f}" if "drape_method" in attrs else f"t = {t:.4g} s"


def _frames_png(res: dict, idx: list[int], out: str, max_triangles: int,
                max_collider_triangles: int = MAX_COLLIDER_TRIANGLES) -> None:
    tri, positions, bodies, note = _prepare(res, max_triangles, max_collider_triangles)
    lo, hi = _view(positions, bodies)
    fig = Figure(figsize=(4.2 * len(idx), 4.6), dpi=100)
    FigureCanvasAgg(fig)
    status = res["attrs"].get("status", "?")
    fig.suptitle(f"{res['attrs'].get('scene', os.path.basename(out))}: {res['frames_written']} "
                 f"frames written, status {status}{note}", fontsize=10)
    for p, (x, t) in enumerate(zip(positions, res["time"])):
        ax = fig.add_subplot(1, len(idx), p + 1, projection="3d")
        _draw(ax, x[tri], bodies, p, lo, hi)
        ax.view_init(elev=25, azim=-60)
        ax.set_title(f"frame {idx[p]}, {_when(res['attrs'], t)}", fontsize=9)
    fig.tight_layout()
    fig.savefig(out)


def _has_body(colliders: dict) -> bool:
    """Whether a result file's colliders (``read_result``) hold a mesh: a body to dress."""
    return any(body["shape"] == "mesh" for body in colliders.values())


def _one_frame(res: dict, frame: int) -> dict:
    """``res`` cut to one of its read frames, the moving colliders' rows too."""
    k = range(len(res["time"]))[frame]            # a negative index counts from the end
    colliders = {name: {**body, "positions": body["positions"][k:k + 1]} if body["moving"]
                 else body for name, body in res.get("colliders", {}).items()}
    return {**res, "positions": res["positions"][k:k + 1], "time": res["time"][k:k + 1],
            "colliders": colliders}


def _clean_axes(ax, depth: str, step: float) -> None:
    """No panes, no grid, ticks one ``step`` apart on every axis (equal
    spacing reads as the equal aspect it is) but none on the ``depth`` axis,
    which points at the viewer and would crowd its ticks into a few pixels."""
    for name in "xyz":
        axis = getattr(ax, f"{name}axis")
        axis.set_pane_color((1.0, 1.0, 1.0, 0.0))
        axis.set_major_locator(NullLocator() if name == depth else MultipleLocator(step))
    ax.grid(False)


def _view_zoom(span: np.ndarray) -> float:
    """mplot3d's zoom that fills the panels with the box: it leaves room for
    the box's diagonal, but seen nearly along an axis the box is smaller.
    One zoom for all views keeps them at one scale."""
    extent = []
    for _, azim in VIEWS:
        el, az = np.deg2rad(VIEW_ELEV), np.deg2rad(azim)
        right = np.array([-np.sin(az), np.cos(az), 0.0])
        up = np.array([-np.sin(el) * np.cos(az), -np.sin(el) * np.sin(az), np.cos(el)])
        extent += [np.abs(span) @ np.abs(right), np.abs(span) @ np.abs(up)]
    return 0.95 * float(np.linalg.norm(span)) / max(extent)


def views_png(res: dict, out: str, frame: int = -1, max_triangles: int = MAX_PREVIEW_TRIANGLES,
              max_collider_triangles: int = MAX_COLLIDER_TRIANGLES) -> None:
    """One read frame of ``res`` (default the last) from the front and from
    the side (``VIEWS``), orthographic, with the colliders, written to ``out``."""
    res = _one_frame(res, frame)
    tri, positions, bodies, note = _prepare(res, max_triangles, max_collider_triangles)
    lo, hi = _view(positions, bodies, VIEW_REACH)
    step = float(np.diff(MaxNLocator(10).tick_values(0.0, float((hi - lo).max())))[0])
    zoom = _view_zoom(hi - lo)
    fig = Figure(figsize=(10.0, 6.4), dpi=100)
    FigureCanvasAgg(fig)
    fig.suptitle(f"{res['attrs'].get('scene', os.path.basename(out))}: "
                 f"{_when(res['attrs'], res['time'][0])}, "
                 f"status {res['attrs'].get('status', '?')}{note}", fontsize=10)
    for p, (name, azim) in enumerate(VIEWS):
        ax = fig.add_subplot(1, 2, p + 1, projection="3d")
        _draw(ax, positions[0][tri], bodies, 0, lo, hi, zoom=zoom)
        ax.set_proj_type("ortho")
        ax.view_init(elev=VIEW_ELEV, azim=azim)
        _clean_axes(ax, "y" if name == "front" else "x", step)
        ax.set_title(name, fontsize=9)
    fig.tight_layout()
    fig.savefig(out)


def _finite(a) -> bool:
    return a is not None and np.isfinite(a).any()


def _energy_png(res: dict, out: str) -> None:
    d = res["diagnostics"]
    t = d.get("time", np.zeros(0))
    fig = Figure(figsize=(16, 4.6), dpi=100)
    FigureCanvasAgg(fig)
    ax_e, ax_i, ax_s = (fig.add_subplot(1, 3, k) for k in (1, 2, 3))
    fig.suptitle(f"{res['attrs'].get('scene', '')}: {res['steps_written']} steps, "
                 f"status {res['attrs'].get('status', '?')}", fontsize=10)

    # Energies: gravitational relative to its start, and total shifted by the
    # same amount, so the curves add up on one axis.
    g0 = 0.0
    grav = d.get("gravitational_energy")
    if _finite(grav):
        g0 = float(grav[np.isfinite(grav)][0])
    others = sorted(k for k in d if k.endswith("_energy") and k not in ENERGY_NAMES)
    plotted = 0
    for name in ENERGY_NAMES + tuple(others):
        y = d.get(name)
        if not _finite(y):
            continue
        label = name.replace("_", " ")
        if name in ("gravitational_energy", "total_energy") and g0:
            y = y - g0
            label += " - start gravitational"
        ax_e.plot(t, y, lw=2.0 if name == "total_energy" else 1.2,
                  color="k" if name == "total_energy" else None, label=label)
        plotted += 1
    ax_e.set_xlabel("time [s]")
    ax_e.set_ylabel("energy [J]")
    ax_e.set_title("energy", fontsize=10)
    if plotted:
        ax_e.legend(fontsize=7)
    else:
        ax_e.text(0.5, 0.5, "no energy diagnostics", ha="center", transform=ax_e.transAxes)

    plotted = 0
    for name in ITERATION_NAMES:
        if _finite(d.get(name)):
            ax_i.plot(t, d[name], lw=1.0, label=name.replace("_", " "))
            plotted += 1
    ax_i.set_xlabel("time [s]")
    ax_i.set_ylabel("iterations per step")
    ax_i.set_title("solver", fontsize=10)
    res_y = d.get("ksp_residual")
    if _finite(res_y) and np.nanmax(res_y) > 0:
        ax_r = ax_i.twinx()
        ax_r.semilogy(t, np.where(res_y > 0, res_y, np.nan), color="0.5", lw=0.8, ls=":",
                      label="ksp residual")
        ax_r.set_ylabel("KSP residual", fontsize=8)
        ax_r.legend(fontsize=7, loc="upper right")
        plotted += 1
    if plotted:
        ax_i.legend(fontsize=7, loc="upper left")
    else:
        ax_i.text(0.5, 0.5, "no solver diagnostics", ha="center", transform=ax_i.transAxes)

    # Stage time: stacked bars over up to 20 time bins show how the split
    # changes along the run; the legend gives each stage's total.
    st = {k: np.nan_to_num(v) for k, v in res["stage_time"].items()}
    total = {k: float(v.sum()) for k, v in st.items()}
    grand = sum(total.values())
    if st and grand > 0 and t.size:
        nb = min(20, t.size)
        edges = np.linspace(0, t.size, nb + 1).astype(int)
        centers = np.array([t[a:b].mean() for a, b in zip(edges[:-1], edges[1:])])
        width = (t[-1] - t[0]) / nb if t.size > 1 and t[-1] > t[0] else 1.0
        bottom = np.zeros(nb)
        for name in sorted(st, key=total.get, reverse=True):
            per_bin = np.add.reduceat(st[name], edges[:-1])
            ax_s.bar(centers, per_bin, width=0.9 * width, bottom=bottom,
                     label=f"{name}: {total[name]:.3g} s ({100 * total[name] / grand:.0f}%)")
            bottom += per_bin
        ax_s.set_xlabel("time [s]")
        ax_s.set_ylabel("wall time per bin [s]")
        ax_s.legend(fontsize=7)
    else:
        ax_s.text(0.5, 0.5, "no stage timings", ha="center", transform=ax_s.transAxes)
    ax_s.set_title("stage time", fontsize=10)
    fig.tight_layout()
    fig.savefig(out)


def _reactions_png(res: dict, out: str) -> None:
    """Each pin group's reaction (diagnostics reaction_<k>_x/y/z, the groups
    named by the attribute grips) against time: a grip pulled at a constant
    velocity draws its load-elongation curve."""
    d = res["diagnostics"]
    t = d.get("time", np.zeros(0))
    names = list(res["attrs"].get("grips", []))
    fig = Figure(figsize=(8, 4.6), dpi=100)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    curves = {(k, c): d.get(f"reaction_{k}_{c}") for k in range(len(names)) for c in "xyz"}
    largest = max((float(np.nanmax(np.abs(y))) for y in curves.values() if _finite(y)),
                  default=0.0)
    for k, name in enumerate(names):
        for c, style in zip("xyz", ("-", "--", ":")):
            y = curves[k, c]
            # components at round-off of the largest are left out
            if _finite(y) and np.nanmax(np.abs(y)) > 1e-9 * largest:
                ax.plot(t, y, style, color=f"C{k % 10}", lw=1.2, label=f"{name} {c}")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("reaction [N]")
    ax.set_title(f"{res['attrs'].get('scene', '')}: reaction force of each pin group",
                 fontsize=10)
    if ax.lines:
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out)


def write_previews(h5_path: str | os.PathLike, out_dir: str | os.PathLike | None = None,
                   max_triangles: int = MAX_PREVIEW_TRIANGLES) -> list[str]:
    """Write ``<stem>_frames.png`` (if any frame was written), ``<stem>_views.png``
    (if also a mesh collider is in the file), ``<stem>_energy.png`` and
    ``<stem>_reactions.png`` (if the run recorded pin-group reactions) next to
    the file (or in ``out_dir``); return their paths.

    Serial: call on one rank only (rank 0), after the writer is closed.
    """
    h5_path = os.fspath(h5_path)
    stem = os.path.splitext(os.path.basename(h5_path))[0]
    folder = os.fspath(out_dir) if out_dir is not None else os.path.dirname(os.path.abspath(h5_path))
    os.makedirs(folder, exist_ok=True)
    idx = pick_frames(int(read_attrs(h5_path).get("frames_written", 0)))
    res = read_result(h5_path, frames=idx)     # only the frames shown are read
    written = []
    if idx:
        path = os.path.join(folder, f"{stem}_frames.png")
        _frames_png(res, idx, path, max_triangles)
        written.append(path)
    if idx and _has_body(res["colliders"]):
        path = os.path.join(folder, f"{stem}_views.png")
        views_png(res, path, frame=-1, max_triangles=max_triangles)   # the last frame, read above
        written.append(path)
    path = os.path.join(folder, f"{stem}_energy.png")
    _energy_png(res, path)
    written.append(path)
    if "reaction_0_x" in res["diagnostics"]:
        path = os.path.join(folder, f"{stem}_reactions.png")
        _reactions_png(res, path)
        written.append(path)
    return written
