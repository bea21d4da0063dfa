"""Error metrics of one result against a reference, in pure numpy.

A "result" is the dict of ``distcloth.io.h5read.read_result`` (only the keys
``time``, ``positions``, ``rest_positions``, ``triangles``, ``diagnostics``
are used), so a test can build an exact reference by hand.

Comparisons are made at common output times (seconds, not step counts) and
at the reference's material points: a variant on another mesh is evaluated
there by barycentric interpolation in the rest shape, which is exact for any
field affine in the rest coordinates (rigid motion, uniform stretch).
"""
from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree

# frames whose times differ by less than this (relative to the time scale) are
# the same output time; steps are rounded from every/h, so only round-off separates them
TIME_MATCH_RTOL = 1e-9


def common_times(t_a: np.ndarray, t_b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Indices (ia, ib) of the frames of a and b at the same time, in time order."""
    t_a, t_b = np.asarray(t_a, float), np.asarray(t_b, float)
    if t_a.size == 0 or t_b.size == 0:
        return np.zeros(0, int), np.zeros(0, int)
    scale = max(float(np.max(np.abs(t_a))), float(np.max(np.abs(t_b))), 1e-300)
    order = np.argsort(t_b, kind="stable")
    pos = np.clip(np.searchsorted(t_b[order], t_a), 1, t_b.size - 1) if t_b.size > 1 \
        else np.zeros(t_a.size, int)
    # nearest of the two neighbours in the sorted b times
    cand = np.stack([pos - 1, pos]) if t_b.size > 1 else np.stack([pos, pos])
    dist = np.abs(t_b[order][cand] - t_a[None])
    best = cand[np.argmin(dist, axis=0), np.arange(t_a.size)]
    ok = np.abs(t_b[order][best] - t_a) <= TIME_MATCH_RTOL * scale
    ia = np.flatnonzero(ok)
    return ia, order[best[ok]]


class RestInterpolator:
    """Locate points in the rest shape of a triangle mesh: for each query point
    the triangle containing it (its projection, for a curved rest shape) and
    its barycentric coordinates there."""

    def __init__(self, rest: np.ndarray, triangles: np.ndarray, candidates: int = 12):
        self.rest = np.asarray(rest, float)
        self.tri = np.asarray(triangles, np.int64)
        self.centroids = self.rest[self.tri].mean(axis=1)
        self.tree = cKDTree(self.centroids)
        self.k = min(candidates, len(self.tri))

    def locate(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
        """(triangle per point (m,), barycentrics (m, 3), largest distance outside
        its triangle in m: 0 when every point lies on the mesh)."""
        p = np.asarray(points, float)
        _, cand = self.tree.query(p, k=self.k)
        cand = cand.reshape(len(p), self.k)                    # (m, k)
        a, b, c = (self.rest[self.tri[cand, i]] for i in range(3))   # (m, k, 3)
        e1, e2, d = b - a, c - a, p[:, None, :] - a
        # barycentrics of the projection onto each candidate's plane (least squares)
        d11 = np.einsum("mki,mki->mk", e1, e1)
        d12 = np.einsum("mki,mki->mk", e1, e2)
        d22 = np.einsum("mki,mki->mk", e2, e2)
        r1 = np.einsum("mki,mki->mk", d, e1)
        r2 = np.einsum("mki,mki->mk", d, e2)
        det = d11 * d22 - d12 * d12
        u = (d22 * r1 - d12 * r2) / det
        v = (d11 * r2 - d12 * r1) / det
        bary = np.stack([1 - u - v, u, v], axis=-1)             # (m, k, 3)
        # clamp into the triangle (renormalised) and measure how far that moves the point
        clamped = np.clip(bary, 0.0, None)
        clamped /= clamped.sum(axis=-1, keepdims=True)
        q = (clamped[..., 0:1] * a + clamped[..., 1:2] * b + clamped[..., 2:3] * c)
        miss = np.linalg.norm(q - p[:, None, :], axis=-1)      # distance to the triangle
        best = np.argmin(miss, axis=1)
        rows = np.arange(len(p))
        inside = np.all(bary[rows, best] >= -1e-12, axis=-1)
        # inside points keep their exact barycentrics (exactness for affine fields)
        w = np.where(inside[:, None], bary[rows, best], clamped[rows, best])
        return cand[rows, best], w, float(np.max(miss[rows, best], initial=0.0))


def interpolation(rest_from, tri_from, points) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(vertex indices (m, 3), weights (m, 3), worst miss in m) mapping a field on the
    mesh (rest_from, tri_from) to ``points`` of its rest shape."""
    loc = RestInterpolator(rest_from, tri_from)
    t, w, miss = loc.locate(points)
    return np.asarray(tri_from)[t], w, miss


def apply_map(field: np.ndarray, idx: np.ndarray, w: np.ndarray) -> np.ndarray:
    """field (..., n, d) -> (..., m, d) at the located points."""
    return np.einsum("...mjd,mj->...md", field[..., idx, :], w)


def same_mesh(a: dict, b: dict) -> bool:
    return (a["rest_positions"].shape == b["rest_positions"].shape
            and np.array_equal(a["triangles"], b["triangles"])
            and np.array_equal(a["rest_positions"], b["rest_positions"]))


def lumped_weights(rest: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """A third of each adjacent triangle's rest area per vertex, summing to 1:
    the weight of a material point in centre-of-mass and RMS averages."""
    a, b, c = (rest[triangles[:, i]] for i in range(3))
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    w = np.bincount(triangles.ravel(), weights=np.repeat(area / 3, 3), minlength=len(rest))
    return w / w.sum()


def rms(dx: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Weighted RMS length of displacement errors (frames, m, 3) -> (frames,)."""
    return np.sqrt(np.einsum("fm,m->f", np.einsum("fmi,fmi->fm", dx, dx), weights))


def _diag_at(result: dict, name: str, times: np.ndarray) -> np.ndarray:
    """A per-step diagnostic at frame times (linear in time; frame 0 takes the first step's
    value, since diagnostics start after step 1)."""
    d = result["diagnostics"]
    if name not in d or len(d[name]) == 0:
        return np.full(len(times), np.nan)
    return np.interp(times, d["time"], d[name])


def energy_drift(result: dict) -> float:
    """Total energy at the end minus at the first step, J (from diagnostics/total_energy)."""
    e = result["diagnostics"].get("total_energy")
    if e is None or len(e) == 0:
        return math.nan
    return float(e[-1] - e[0])


def nanmax(result: dict, name: str) -> float:
    v = result["diagnostics"].get(name)
    if v is None or len(v) == 0 or not np.any(np.isfinite(v)):
        return math.nan
    return float(np.nanmax(v))


def time_to_divergence(times: np.ndarray, err: np.ndarray, threshold: float) -> float:
    """First common time at which the error exceeds ``threshold``; inf if never."""
    over = np.flatnonzero(np.asarray(err) > threshold)
    return float(times[over[0]]) if over.size else math.inf


def reference_drape(reference: dict, support_area: float = 0.0) -> dict:
    """The reference's drape measures at all its frames (computed once per study)."""
    return drape_measures(reference["positions"], reference["rest_positions"], reference["triangles"],
                          support_area=support_area)


def compare(result: dict, reference: dict, *, divergence_threshold: float = 0.01,
            support_area: float = 0.0, ref_drape: dict | None = None, drape: bool = True) -> dict:
    """Every metric of ``result`` against ``reference``.

    Returns scalars (``rms_mean``, ``rms_max``, ``final_error``, ``final_max_error``,
    ``com_final_error``, ``com_max_error``, ``energy_drift``, ``energy_error_max``,
    ``max_strain``, ``max_penetration``, ``time_to_divergence``, ``frames_compared``,
    ``map_miss``, the ``DRAPE_METRICS``) and series (``times``, ``rms``, ``com_error``,
    ``drape``: each of ``DRAPE_MEASURES`` over time, on the result's own mesh).
    ``ref_drape``: ``reference_drape(reference, support_area)``, to compute it once;
    ``drape=False`` skips the drape measures (the rasterised shadow is the costly part)."""
    ia, ib = common_times(result["time"], reference["time"])
    if ia.size == 0:
        raise ValueError("no common output times: choose output.every as a multiple of every step")
    times = np.asarray(reference["time"])[ib]
    x_ref = np.asarray(reference["positions"])[ib]
    x = np.asarray(result["positions"])[ia]
    # drape measures on each mesh's own triangles (a shadow needs no mapping), on the
    # reference's raster so that both outlines are counted on cells of one size
    drape_metrics = _drape_against(x, result, reference, ib, support_area, ref_drape) if drape else {}
    miss = 0.0
    if not same_mesh(result, reference):
        idx, w, miss = interpolation(result["rest_positions"], result["triangles"],
                                     reference["rest_positions"])
        x = apply_map(x, idx, w)
    weights = lumped_weights(reference["rest_positions"], reference["triangles"])
    dx = x - x_ref
    err = rms(dx, weights)
    pointwise_final = np.linalg.norm(dx[-1], axis=1)
    com_err = np.linalg.norm(np.einsum("fmi,m->fi", dx, weights), axis=1)
    e_err = np.abs(_diag_at(result, "total_energy", times) - _diag_at(reference, "total_energy", times))
    return {
        "times": times, "rms": err, "com_error": com_err,
        "frames_compared": int(ia.size), "t_final": float(times[-1]),
        "rms_mean": float(np.sqrt(np.mean(err ** 2))), "rms_max": float(np.max(err)),
        "final_error": float(err[-1]), "final_max_error": float(np.max(pointwise_final)),
        "com_final_error": float(com_err[-1]), "com_max_error": float(np.max(com_err)),
        "energy_drift": energy_drift(result),
        "energy_error_max": float(np.nanmax(e_err)) if np.any(np.isfinite(e_err)) else math.nan,
        "max_strain": nanmax(result, "max_strain"),
        "max_penetration": nanmax(result, "max_penetration"),
        "time_to_divergence": time_to_divergence(times, err, divergence_threshold),
        "map_miss": miss, **drape_metrics,
    }


def _drape_against(x, result, reference, ib, support_area, ref_drape) -> dict:
    """The result's drape measures at the common frames ``x`` (series ``drape``) and
    their differences from the reference's (frames ``ib``)."""
    ref_drape = ref_drape if ref_drape is not None else reference_drape(reference, support_area)
    cell = math.sqrt(rest_area(reference["rest_positions"], reference["triangles"])) / SHADOW_CELLS
    series = drape_measures(x, result["rest_positions"], result["triangles"],
                            support_area=support_area, cell=cell)
    return {"drape": series, **compare_drape(series, {m: v[ib] for m, v in ref_drape.items()})}




# ---------------------------------------------------------------------------
# Drape measures: what a chaotic scene (falling, folding cloth) can still be
# compared by once its positions have decorrelated.

# Rasterisation of the shadow: cells of sqrt(rest area) / SHADOW_CELLS (about
# 2 mm on a 1 m cloth).  A cell counts when its centre lies in a projected
# triangle, so the error sits on the outline only: at most perimeter * cell / 2
# (edges along the grid lines, i.e. 1/1024 of a square's area per side pair),
# and far less on slanted outlines whose half-cells cancel; a few times finer
# than any difference between variants worth reporting, and still a few
# milliseconds per frame.
SHADOW_CELLS = 512
# triangle x cell tests per batch (bounds memory at ~100 MB)
SHADOW_BATCH = 2_000_000
DRAPE_MEASURES = ("shadow_area", "drape_coefficient", "com_height", "vertical_extent")


def ground_basis(up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """(3, 3): two orthonormal directions spanning the ground plane, then ``up``."""
    n = np.asarray(up, float) / np.linalg.norm(up)
    helper = np.eye(3)[int(np.argmin(np.abs(n)))]
    e1 = np.cross(n, helper)
    e1 /= np.linalg.norm(e1)
    return np.stack([e1, np.cross(n, e1), n])


def rest_area(rest: np.ndarray, triangles: np.ndarray) -> float:
    a, b, c = (np.asarray(rest, float)[np.asarray(triangles)[:, i]] for i in range(3))
    return float(0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1).sum())


def shadow_area(x: np.ndarray, triangles: np.ndarray, cell: float, up=(0.0, 0.0, 1.0)) -> float:
    """Area (m²) of the union of the triangles projected along ``up`` onto the
    ground plane, counted on a grid of square cells of side ``cell`` anchored at
    the shadow's lower corner (cell centres at lo + (i + 1/2) cell)."""
    p = (np.asarray(x, float) @ ground_basis(up)[:2].T)              # (n, 2) ground coordinates
    if len(p) == 0:
        return 0.0
    lo = p.min(axis=0)
    shape = np.maximum(np.ceil((p.max(axis=0) - lo) / cell).astype(np.int64), 1)
    return float(shadow_cells(p, triangles, cell, lo, shape).sum()) * cell * cell


def shadow_cells(p: np.ndarray, triangles: np.ndarray, cell: float, lo, shape) -> np.ndarray:
    """Boolean grid ``shape`` of the cells (side ``cell``, centres at lo + (i + 1/2)
    cell) whose centres lie under a triangle of the ground-plane points ``p`` (n, 2);
    a fixed grid lets several parts of a mesh be rasterised apart and OR-ed."""
    tri = np.asarray(triangles, np.int64)
    covered = np.zeros(tuple(int(k) for k in shape), bool)
    if len(tri) == 0:
        return covered
    q = np.asarray(p, float)[tri]                                   # (t, 3, 2)
    e1, e2 = q[:, 1] - q[:, 0], q[:, 2] - q[:, 0]
    twice = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    q = q[np.abs(twice) > 1e-14 * cell * cell]                       # edge-on triangles cast no area
    if len(q) == 0:
        return covered
    lo = np.asarray(lo, float)
    # candidate cells per triangle: the centres inside its bounding box
    first = np.ceil((q.min(axis=1) - lo) / cell - 0.5).astype(np.int64)     # (t, 2)
    span = np.maximum(np.floor((q.max(axis=1) - lo) / cell - 0.5).astype(np.int64) - first + 1, 1)
    # triangles binned by their box's size in powers of two along each axis, so that a
    # long sliver (a hull edge of a Delaunay mesh, a cloth seen edge-on) costs its own box,
    # not every triangle's; vectorised within a bin, in batches that bound the memory
    bins = np.ceil(np.log2(span)).astype(np.int64)
    key = bins[:, 0] * 64 + bins[:, 1]
    for b in np.unique(key):
        sel = np.flatnonzero(key == b)
        kx, ky = span[sel].max(axis=0)
        off = np.stack(np.meshgrid(np.arange(kx), np.arange(ky), indexing="ij"), -1).reshape(-1, 2)
        per = max(1, SHADOW_BATCH // len(off))
        for s in range(0, len(sel), per):
            _mark_cells(covered, q[sel[s:s + per]], first[sel[s:s + per]], off, lo, cell)
    return covered


def _mark_cells(covered, q, first, off, lo, cell) -> None:
    """Set the cells whose centres lie in (or on) a projected triangle of the batch."""
    idx = first[:, None, :] + off[None]                             # (t, k², 2)
    c = lo + (idx + 0.5) * cell
    a, b, d = q[:, None, 0], q[:, None, 1], q[:, None, 2]

    def side(u, v):        # z of (v - u) x (c - u), the sign says which side of uv
        return (v[..., 0] - u[..., 0]) * (c[..., 1] - u[..., 1]) - (v[..., 1] - u[..., 1]) * (c[..., 0] - u[..., 0])
    s0, s1, s2 = side(a, b), side(b, d), side(d, a)
    tol = 1e-12 * cell * cell               # centres on a shared edge count (once: the grid is boolean)
    inside = (((s0 >= -tol) & (s1 >= -tol) & (s2 >= -tol)) | ((s0 <= tol) & (s1 <= tol) & (s2 <= tol)))
    inside &= np.all((idx >= 0) & (idx < np.array(covered.shape)), axis=-1)
    covered[idx[inside][:, 0], idx[inside][:, 1]] = True


def drape_measures(positions: np.ndarray, rest: np.ndarray, triangles: np.ndarray, *,
                   support_area: float = 0.0, up=(0.0, 0.0, 1.0), cell: float | None = None) -> dict:
    """Per frame of ``positions`` (frames, n, 3): ``shadow_area`` (m²), ``drape_coefficient``
    (Cusick's (A_shadow - A_disc) / (A_cloth - A_disc) with the support disc's area,
    or A_shadow / A_cloth without one), ``com_height`` (m, area-weighted, along ``up``)
    and ``vertical_extent`` (m, highest minus lowest vertex along ``up``)."""
    pos = np.asarray(positions, float)
    area = rest_area(rest, triangles)
    cell = cell if cell is not None else math.sqrt(area) / SHADOW_CELLS
    n = np.asarray(up, float) / np.linalg.norm(up)
    height = pos @ n                                                 # (frames, n)
    w = lumped_weights(np.asarray(rest, float), np.asarray(triangles))
    shadow = np.array([shadow_area(x, triangles, cell, up) for x in pos])
    return {"shadow_area": shadow,
            "drape_coefficient": (shadow - support_area) / (area - support_area),
            "com_height": height @ w,
            "vertical_extent": height.max(axis=1) - height.min(axis=1)}


def support_disc_area(raw: dict) -> float:
    """The area of the disc a draped cloth rests on, for Cusick's drape coefficient:
    the horizontal cross-section of the scene's one sphere collider (its shadow);
    0 when there is none or several (the coefficient is then shadow / cloth area)."""
    spheres = [c for c in (raw.get("colliders") or []) if isinstance(c, dict) and c.get("shape") == "sphere"]
    if len(spheres) != 1 or "radius" not in spheres[0]:
        return 0.0
    return math.pi * float(spheres[0]["radius"]) ** 2


def compare_drape(series: dict, ref_series: dict) -> dict:
    """``{measure}_final_diff`` and ``{measure}_max_diff``: the variant minus the
    reference at the last common time, and the largest |difference| over time."""
    out = {}
    for m in DRAPE_MEASURES:
        d = np.asarray(series[m]) - np.asarray(ref_series[m])
        out[f"{m}_final_diff"] = float(d[-1])
        out[f"{m}_max_diff"] = float(np.max(np.abs(d)))
    return out


DRAPE_METRICS = tuple(f"{m}_{k}_diff" for m in DRAPE_MEASURES for k in ("final", "max"))


SCALAR_METRICS = ("rms_mean", "rms_max", "final_error", "final_max_error", "com_final_error",
                  "com_max_error", "energy_drift", "energy_error_max", "max_strain",
                  "max_penetration", "time_to_divergence", "frames_compared", "t_final",
                  "map_miss") + DRAPE_METRICS
