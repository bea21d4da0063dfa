#!/usr/bin/env python3
"""Where a sewn garment came to rest: one row of figures per result file.

    .venv/bin/python scripts/garment_at_rest.py OUT.h5 [OUT2.h5 ...] [--markdown]

For each main result file ``OUT.h5`` of a garment scene (``distcloth run`` or
``distcloth drape``) and its sewing file ``OUT_sewing.h5``:

* scene, ranks, pattern vertices (the sewing file's panels), welded vertices;
* sewing: simulated time and steps at the weld (the sewing file's last
  diagnostics row) and the widest stitch then (mm);
* the end state: for a drape file the method, iterations, stops, final
  residual (unbalanced force / weight) and the last measured window motion;
  for a run file the end time and the last kinetic energy;
* at the last frame, checks independent of the simulator's contact code:
  - body: per mesh collider, the smallest signed distance of a garment
    vertex (``ClosedMesh.signed_distance`` of garment/start_check.py: sign by
    the generalized winding number, negative inside), the vertices inside,
    and those deeper than 10 % of the contact offset d (cloth thickness +
    collider thickness, from the file's config; the thinnest cloth if there
    are several);
  - crossings: intersecting garment triangle pairs (``self_intersections``:
    exact oracle, pairs sharing a vertex not tested);
  - strain: the largest principal engineering strain (principal stretch of
    the 2x2 right Cauchy-Green tensor, minus 1) of every welded triangle
    against its own flat panel's rest shape, as the weld keeps it (the
    sewing file's rest positions at the pattern triangle's corners); max and
    99th percentile.

A sewing file given alone stands for its main file; a missing main file, a
file still being written (status 'running') or an unreadable one gets one
line after the table.  Lengths in the files are metres.
"""
from __future__ import annotations

import argparse
import hashlib
import math
import os
import sys
from pathlib import Path

import h5py
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from distcloth.garment.start_check import ClosedMesh, self_intersections  # noqa: E402
from distcloth.io.h5read import read_attrs, read_result  # noqa: E402
from distcloth.sew import sewing_path  # noqa: E402

DEEP_FRACTION = 0.1         # "deep": inside by more than this fraction of d
SEWING_SUFFIX = "_sewing"


# ------------------------------------------------------------------ geometry

def principal_strain(rest: np.ndarray, current: np.ndarray) -> np.ndarray:
    """Largest principal engineering strain (m,) of triangles with rest
    corners ``rest`` (m, 3, 3; flat, anywhere in space) now at ``current``
    (m, 3, 3): the deformation gradient F (3x2) from the triangle's own 2D
    rest frame, C = F^T F, strain = sqrt(lambda_max(C)) - 1.  NaN for a
    degenerate rest triangle."""
    e1 = rest[:, 1] - rest[:, 0]
    e2 = rest[:, 2] - rest[:, 0]
    a = np.linalg.norm(e1, axis=1)                       # rest frame: e1 on the u axis
    with np.errstate(invalid="ignore", divide="ignore"):
        u = e1 / a[:, None]
        b = np.einsum("ij,ij->i", e2, u)
        c = np.linalg.norm(e2 - b[:, None] * u, axis=1)  # Dm = [[a, b], [0, c]]
        d1 = current[:, 1] - current[:, 0]
        d2 = current[:, 2] - current[:, 0]
        f0 = d1 / a[:, None]                             # F = Ds Dm^-1
        f1 = (d2 - (b / a)[:, None] * d1) / c[:, None]
        c11 = np.einsum("ij,ij->i", f0, f0)
        c22 = np.einsum("ij,ij->i", f1, f1)
        c12 = np.einsum("ij,ij->i", f0, f1)
        lam = 0.5 * (c11 + c22) + np.sqrt(0.25 * (c11 - c22) ** 2 + c12 ** 2)
        strain = np.sqrt(lam) - 1.0
    bad = ~(a > 0) | ~(c > 1e-12 * np.maximum(a, 1e-300))
    strain[bad] = np.nan
    return strain


def welded_rest_triangles(sew_triangles, sew_rest, pattern_vertex, triangles):
    """Rest corners (nt, 3, 3) of every welded triangle (rows of ``triangles``,
    corners in its order) from its pattern triangle, and a note on how they
    were matched.  weld_model maps the pattern triangles through the vertex
    map, drops those that collapse and keeps the order; if the rows do not
    agree they are matched by vertex set (rest corners permuted to the welded
    triangle's corner order; unmatched rows get NaN)."""
    mapped = pattern_vertex[sew_triangles]
    keep = ((mapped[:, 0] != mapped[:, 1]) & (mapped[:, 1] != mapped[:, 2])
            & (mapped[:, 2] != mapped[:, 0]))
    mapped = mapped[keep]
    rest = sew_rest[sew_triangles[keep]]
    dropped = int((~keep).sum())
    if mapped.shape == triangles.shape and np.array_equal(mapped, triangles):
        return rest, f"rows equal ({dropped} collapsed)" if dropped else "rows equal"
    n = int(max(mapped.max(initial=0), triangles.max(initial=0))) + 1

    def key(t):
        s = np.sort(t, axis=1).astype(np.int64)
        return (s[:, 0] * n + s[:, 1]) * n + s[:, 2]

    kp, kw = key(mapped), key(triangles)
    order = np.argsort(kp, kind="stable")
    at = np.minimum(np.searchsorted(kp[order], kw), max(kp.size - 1, 0))
    found = kp[order[at]] == kw if kp.size else np.zeros(kw.size, bool)
    src = order[at]
    # corner k of the welded triangle is corner perm[k] of the pattern one
    perm = np.argmax(mapped[src][:, None, :] == triangles[:, :, None], axis=2)
    out = np.take_along_axis(rest[src], perm[:, :, None], axis=1)
    out[~found] = np.nan
    return out, (f"matched {int(found.sum())}/{triangles.shape[0]} by vertex set "
                 f"({dropped} collapsed)")


# ------------------------------------------------------------------ files

def main_and_sewing(path: str) -> tuple[str, str]:
    stem, ext = os.path.splitext(path)
    if stem.endswith(SEWING_SUFFIX):
        return stem[: -len(SEWING_SUFFIX)] + ext, path
    return path, sewing_path(path)


def _config(text: str) -> dict:
    import yaml
    try:
        cfg = yaml.safe_load(text)
    except yaml.YAMLError:
        return {}
    return cfg if isinstance(cfg, dict) else {}


def _contact_offsets(cfg: dict) -> dict:
    """Collider name -> d = (thinnest) cloth thickness + collider thickness."""
    cloth = [float(c.get("thickness", 0.001)) for c in cfg.get("cloth") or []
             if isinstance(c, dict)]
    t = min(cloth) if cloth else 0.001
    return {str(c.get("name")): t + float(c.get("thickness", 0.0) or 0.0)
            for c in cfg.get("colliders") or [] if isinstance(c, dict)} | {None: t}


def _last(diag: dict, name: str):
    v = diag.get(name)
    return float(v[-1]) if v is not None and v.size else math.nan


def _last_finite(diag: dict, name: str):
    v = diag.get(name)
    if v is None:
        return math.nan
    v = v[np.isfinite(v)]
    return float(v[-1]) if v.size else math.nan


_BODIES: dict = {}


def _closed_mesh(vertices, triangles) -> ClosedMesh:
    """The body's prepared queries, kept across files (the same body)."""
    h = hashlib.sha1(np.ascontiguousarray(vertices).tobytes())
    h.update(np.ascontiguousarray(triangles).tobytes())
    key = h.hexdigest()
    if key not in _BODIES:
        _BODIES[key] = ClosedMesh(vertices, triangles)
    return _BODIES[key]


def garment_at_rest(main: str, sewing: str | None = None) -> dict:
    """The figures of one result file (and its sewing file, if any)."""
    if sewing is None:
        sewing = main_and_sewing(main)[1]
    r = read_result(main, frames=slice(-1, None))
    attrs, diag = r["attrs"], r["diagnostics"]
    cfg = _config(r["config"] or "")
    row = {"file": os.path.basename(main), "scene": attrs.get("scene", cfg.get("scene", "?")),
           "ranks": attrs.get("ranks"), "status": attrs.get("status", "?"),
           "welded": int(r["rest_positions"].shape[0]), "triangles": int(r["triangles"].shape[0])}

    # sewing phase
    sew = None
    if os.path.exists(sewing):
        sew = read_result(sewing, positions=False)
        sd = sew["diagnostics"]
        row.update(pattern=int(sew["rest_positions"].shape[0]), sew_time=_last(sd, "time"),
                   sew_steps=int(sd["step"][-1]) if sd["step"].size else None,
                   stitch_gap=_last(sd, "stitch_gap"))

    # end state
    method = attrs.get("drape_method")
    row["drape"] = method
    if method:
        row.update(iterations=int(_last(diag, "time")) if diag["time"].size else 0,
                   stops=_last(diag, "stops"), residual=_last(diag, "residual"),
                   motion=_last_finite(diag, "window_motion"))
    else:
        row.update(end_time=_last(diag, "time"), kinetic=_last(diag, "kinetic_energy"))
    if r["positions"] is None or r["positions"].shape[0] == 0:
        row["note"] = "no frame written"
        return row
    x = r["positions"][-1]
    tri = r["triangles"]
    row["frame_time"] = float(r["time"][-1])

    # body: signed distance to every mesh collider at that frame
    offsets = _contact_offsets(cfg)
    bodies = []
    for name, c in r["colliders"].items():
        if c["shape"] != "mesh":
            continue
        d = offsets.get(name, offsets[None])
        sd = _closed_mesh(c["positions"][-1], c["triangles"]).signed_distance(x)
        bodies.append({"name": name, "d": d, "min": float(sd.min()),
                       "inside": int((sd < 0).sum()),
                       "deep": int((sd < -DEEP_FRACTION * d).sum())})
    row["bodies"] = bodies

    # crossings of the welded garment (no `same`: welded seams share vertices)
    row["crossings"] = int(self_intersections(x, tri).shape[0])

    # strain against each triangle's own flat panel
    pv = None
    with h5py.File(main, "r") as f:
        if "garment/pattern_vertex" in f:
            pv = f["garment/pattern_vertex"][...].astype(np.int64)
    if sew is None and pv is not None:
        row["pattern"] = int(pv.shape[0])
    if sew is not None and pv is not None and pv.shape[0] == sew["rest_positions"].shape[0]:
        rest, how = welded_rest_triangles(sew["triangles"].astype(np.int64),
                                          sew["rest_positions"], pv, tri.astype(np.int64))
    elif pv is None:
        # not a sewn garment: the file's own rest shape
        rest, how = r["rest_positions"][tri], "own rest shape"
    else:
        rest, how = None, ("no sewing file" if sew is None else
                           f"pattern_vertex has {pv.shape[0]} rows, sewing mesh "
                           f"{sew['rest_positions'].shape[0]}")
    row["strain_match"] = how
    if rest is not None:
        s = principal_strain(rest, x[tri])
        s = s[np.isfinite(s)]
        if s.size:
            row.update(strain_max=float(s.max()), strain_p99=float(np.percentile(s, 99)))
    return row


# ------------------------------------------------------------------ table

COLUMNS = ["file", "scene", "ranks", "status", "pattern v", "welded v", "sew t (s)",
           "sew steps", "gap (mm)", "end state", "frame", "d (mm)", "body min sd (mm)",
           "inside", f"deep >{DEEP_FRACTION:g}d", "crossings", "strain max (%)",
           "strain p99 (%)"]


def _f(v, fmt: str) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "-"
    return format(v, fmt)


def cells(row: dict) -> list[str]:
    if row.get("drape"):
        end = (f"{row['drape']}: {row['iterations']} it, {_f(row['stops'], '.0f')} stops, "
               f"res {_f(row['residual'], '.3g')}, motion "
               + (f"{_f(1e3 * row['motion'], '.3g')} mm" if math.isfinite(row['motion'])
                  else "-"))
        frame = f"it {_f(row.get('frame_time'), '.0f')}"
    else:
        end = f"run: t {_f(row['end_time'], '.3f')} s, KE {_f(row['kinetic'], '.3g')} J"
        frame = f"t {_f(row.get('frame_time'), '.3f')} s"
    bodies = row.get("bodies") or []
    multi = len(bodies) > 1

    def per_body(fn):
        if not bodies:
            return "-"
        return " / ".join((f"{b['name']} " if multi else "") + fn(b) for b in bodies)

    strain_max = row.get("strain_max")
    max_cell = _f(None if strain_max is None else 100 * strain_max, ".1f")
    if row.get("strain_match", "").startswith(("matched", "no ", "pattern", "own")):
        max_cell += f" ({row['strain_match']})"
    p99 = row.get("strain_p99")
    return [row["file"], str(row["scene"]), _f(row.get("ranks"), "d"), str(row["status"]),
            _f(row.get("pattern"), "d"), _f(row.get("welded"), "d"),
            _f(row.get("sew_time"), ".3f"), _f(row.get("sew_steps"), "d"),
            _f(None if row.get("stitch_gap") is None else 1e3 * row["stitch_gap"], ".2f"),
            end, frame if "frame_time" in row else row.get("note", "-"),
            per_body(lambda b: _f(1e3 * b["d"], ".1f")),
            per_body(lambda b: _f(1e3 * b["min"], ".2f")),
            per_body(lambda b: str(b["inside"])), per_body(lambda b: str(b["deep"])),
            _f(row.get("crossings"), "d"), max_cell,
            _f(None if p99 is None else 100 * p99, ".1f")]


def print_table(rows: list[list[str]], markdown: bool, out=sys.stdout) -> None:
    if markdown:
        print("| " + " | ".join(COLUMNS) + " |", file=out)
        print("|" + "|".join("---" for _ in COLUMNS) + "|", file=out)
        for r in rows:
            print("| " + " | ".join(c.replace("|", "\\|") for c in r) + " |", file=out)
        return
    width = [max(len(h), *(len(r[k]) for r in rows)) for k, h in enumerate(COLUMNS)]
    print("  ".join(h.ljust(w) for h, w in zip(COLUMNS, width)).rstrip(), file=out)
    for r in rows:
        print("  ".join(c.ljust(w) for c, w in zip(r, width)).rstrip(), file=out)


def _one_line(exc: Exception) -> str:
    text = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {text[0] if text else ''}"


def skip_reason(main: str, sewing: str, given: str) -> str | None:
    """One line for a file that gives no row, else None."""
    if os.path.isdir(given):
        return f"{given}: a directory, not a result file"
    if not os.path.exists(main):
        if given == sewing and os.path.exists(sewing):
            try:
                a = read_attrs(sewing)
            except OSError as exc:
                return f"{given}: a sewing file, unreadable ({_one_line(exc)}); no main file {main}"
            err = a.get("error") or ""
            return (f"{given}: a sewing file only (status {a.get('status', '?')}"
                    f"{', ' + err if err else ''}); no main file {os.path.basename(main)}")
        return f"{given}: no such file"
    try:
        a = read_attrs(main)
    except OSError as exc:
        return f"{main}: unreadable ({_one_line(exc)})"
    if a.get("status") == "running":
        return (f"{main}: still running ({a.get('frames_written', '?')} frames so far); "
                f"skipped")
    if a.get("phase") == "sewing":
        return f"{main}: a sewing-phase file, not a main result file"
    return None


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("files", nargs="+", metavar="OUT.h5")
    ap.add_argument("--markdown", action="store_true", help="a Markdown table")
    args = ap.parse_args(argv)
    rows, notes, seen = [], [], set()
    for given in args.files:
        main_path, sewing = main_and_sewing(given)
        if os.path.abspath(main_path) in seen:
            continue
        seen.add(os.path.abspath(main_path))
        reason = skip_reason(main_path, sewing, given)
        if reason:
            notes.append(reason)
            continue
        print(f"checking {main_path} ...", file=sys.stderr, flush=True)
        try:
            rows.append(cells(garment_at_rest(main_path, sewing)))
        except (OSError, KeyError, ValueError, IndexError) as exc:
            notes.append(f"{main_path}: failed to read ({_one_line(exc)})")
    if rows:
        print_table(rows, args.markdown)
    if notes:
        if rows:
            print()
        for n in notes:
            print(n)
    return 0 if rows or not notes else 1


if __name__ == "__main__":
    sys.exit(main())
