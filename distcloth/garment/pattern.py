"""Sewing patterns: flat panels placed around a body, and the stitches between
their edges.

Two inputs give the same :class:`Pattern`:

* a GarmentCode specification (Korosteleva and Sorkine-Hornung 2023
  (GarmentCode); the format of Korosteleva and Lee 2021; ``*_specification.json``),
  read by :func:`read_garmentcode`;
* a compact form for hand-written patterns (a dict, or a YAML/JSON file without
  the ``pattern`` key), read by :func:`read_compact`.

:func:`load_pattern` reads either from a file.  Everything is converted to
metres.  A bad pattern raises :class:`PatternError` (a ``ValueError``) with the
key path of the offending value and a one-line message.

GarmentCode conventions, as pygarment implements them (docs/garments.md gives
the file and function for each):

* ``properties.units_in_meter``: vertices, translations and arc radii are in
  units of 1/units_in_meter m (100: centimetres).
* A panel's edges form a closed loop in list order; a counter-clockwise loop
  (y up) shows the panel's outside (right side of the fabric) towards +z of
  the panel frame: front panels are counter-clockwise, back panels clockwise.
* Curvature: ``circle`` params [radius, large_arc, right] (curves.CircularArc);
  ``quadratic`` [[u, v]] and ``cubic`` [[u1, v1], [u2, v2]] control points, or
  a bare [u, v] (the older format, a quadratic).  With
  ``curvature_coords: relative`` a control point is start + u (end - start) +
  v perp(end - start), perp(x, y) = (-y, x): u runs along the edge, v to its
  left, both in units of the edge's straight length; with ``absolute`` it is a
  point of the panel's frame.
* Placement: p3 = R (x, y, 0) + translation, R = Rz(c) Ry(b) Rx(a) for
  ``rotation`` [a, b, c] in degrees (Maya's xyz order: about x first).
* ``normalize_panel_translation: true`` moves each panel's vertex mean to its
  origin and adds the offset to translation x, y, as pygarment does on load
  (absolute control points move with the vertices).
* Read as written: the loops' own edge numbers (``normalized_edge_loops`` is
  not applied), no parameters or constraints; the older {from, to} stitch form
  is refused (docs/garments.md lists what is not supported).
* A stitch [{panel, edge}, {panel, edge}] sews the first side's start to the
  second side's end (pygarment's default "swap": the outside faces meet); a
  third element "right_wrong" sews start to start.

The compact form (all keys but ``panels`` optional)::

    units_in_meter: 1            # 100 for centimetres
    curve_coords: relative       # or absolute
    panels:
      front:
        vertices: [[x, y], ...]  # edge i runs from vertex i to vertex i+1 (last: to vertex 0)
        edges:                   # curved or labelled edges, by index
          1: {arc: {radius: 0.58, large: false, right: true}}
          3: {quad: [[0.5, -0.1]], label: waist}
          4: {cubic: [[0.2, 0.3], [0.5, 0.2]]}
        translation: [x, y, z]
        rotation: [a, b, c]      # degrees
        grain: [gx, gy]          # default [1, 0], the panel's x axis
        label: body
    seams:
      - [front:0, back:3]                  # as a GarmentCode stitch (b walked backwards)
      - [front:1-2, back:5-6]              # a side of several consecutive edges
      - [front:4, back:7, right_wrong]     # start to start
      - {sides: [front:5, back:8], right_wrong: true, label: side}
"""
from __future__ import annotations

import json
import math
import os
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import yaml

from ..rotations import rotation_matrix
from .curves import Bezier, CircularArc, Line, frozen_array


class PatternError(ValueError):
    """A bad pattern: ``path`` is the key path of the offending value (dots,
    list indices as numbers), ``message`` says what is wrong, in one line."""

    def __init__(self, path: str, message: str):
        self.path, self.message = path, message
        super().__init__(f"{path}: {message}" if path else message)


@dataclass(frozen=True, eq=False)
class Edge:
    """One edge of a panel's outline: vertex indices and the curve between them."""
    start: int
    end: int
    curve: Line | CircularArc | Bezier
    label: str | None = None

    def length(self) -> float:
        return self.curve.length()


@dataclass(frozen=True, eq=False)
class Panel:
    """A flat piece of fabric: its outline in its own 2D frame (metres) and its
    placement in 3D.  ``orientation`` is +1 if the edge loop runs counter-
    clockwise (outside face towards the frame's +z), -1 if clockwise."""
    name: str
    vertices: np.ndarray                      # (n, 2) m
    edges: tuple[Edge, ...]
    rotation: np.ndarray                      # (3, 3)
    translation: np.ndarray                   # (3,) m
    grain: np.ndarray = None                  # (2,) unit vector; default the x axis
    label: str | None = None
    rotation_degrees: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self):
        object.__setattr__(self, "vertices", frozen_array(self.vertices, (2,)))
        object.__setattr__(self, "rotation", frozen_array(self.rotation, (3,)))
        object.__setattr__(self, "translation", frozen_array(self.translation, (3,)))
        g = np.array([1.0, 0.0] if self.grain is None else self.grain, dtype=np.float64)
        object.__setattr__(self, "grain", frozen_array(g / np.hypot(*g)))

    def place(self, points: np.ndarray) -> np.ndarray:
        """3D positions (m) of points (n, 2) of the panel's frame."""
        points = np.asarray(points, dtype=np.float64)
        return points @ self.rotation[:, :2].T + self.translation

    def outline(self, per_edge: int = 32) -> np.ndarray:
        """The closed outline sampled with ``per_edge`` points per edge (each
        edge's start included, its end not): (len(edges) * per_edge, 2)."""
        s = np.arange(per_edge) / per_edge
        return np.concatenate([e.curve.point(s) for e in self.edges])

    @cached_property        # the outline is fixed, and sampling Béziers is not free
    def orientation(self) -> int:
        return 1 if signed_area(self.outline()) > 0.0 else -1

    @property
    def normal(self) -> np.ndarray:
        """Unit normal of the outside face in 3D."""
        return self.rotation[:, 2] * self.orientation

    def edge_lengths(self) -> np.ndarray:
        return np.array([e.length() for e in self.edges])


@dataclass(frozen=True)
class SeamSide:
    """One side of a stitch: consecutive edges of a panel (in the panel's loop
    order), walked backwards (from the last edge's end to the first edge's
    start) if ``reverse``."""
    panel: str
    edges: tuple[int, ...]
    reverse: bool = False


@dataclass(frozen=True)
class Stitch:
    """Two seam sides sewn together: the point at arc-length fraction u along
    side ``a`` (walked as it says) meets the point at fraction u along ``b``."""
    a: SeamSide
    b: SeamSide
    label: str | None = None


@dataclass(frozen=True, eq=False)
class Pattern:
    panels: tuple[Panel, ...]
    stitches: tuple[Stitch, ...]
    name: str | None = None

    def panel(self, name: str) -> Panel:
        for p in self.panels:
            if p.name == name:
                return p
        raise KeyError(name)

    @property
    def panel_names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.panels)

    def panel_index(self, name: str) -> int:
        return self.panel_names.index(name)


def signed_area(polygon: np.ndarray) -> float:
    x, y = polygon[:, 0], polygon[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


# --- reading: small checked accessors --------------------------------------------

def _join(path: str, key) -> str:
    return f"{path}.{key}" if path else str(key)


def _mapping(value, path: str, what: str = "a mapping") -> Mapping:
    if not isinstance(value, Mapping):
        raise PatternError(path, f"expected {what}, got {_show(value)}")
    return value


def _sequence(value, path: str, what: str = "a list") -> Sequence:
    if isinstance(value, (str, bytes)) or not isinstance(value, Sequence):
        raise PatternError(path, f"expected {what}, got {_show(value)}")
    return value


def _show(value) -> str:
    text = json.dumps(value) if isinstance(value, (list, dict, str, int, float, bool)) \
        or value is None else repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _number(value, path: str, *, positive: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise PatternError(path, f"expected a finite number, got {_show(value)}")
    if positive and not value > 0:
        raise PatternError(path, f"expected a number > 0, got {_show(value)}")
    return float(value)


def _vector(value, n: int, path: str) -> np.ndarray:
    seq = _sequence(value, path, f"a list of {n} numbers")
    if len(seq) != n:
        raise PatternError(path, f"expected a list of {n} numbers, got {_show(value)}")
    return np.array([_number(v, _join(path, i)) for i, v in enumerate(seq)])


def _points(value, path: str, count=None, what="points") -> np.ndarray:
    seq = _sequence(value, path, f"a list of {what} [x, y]")
    if count is not None and len(seq) not in count:
        raise PatternError(path, f"expected {' or '.join(map(str, count))} {what} [x, y], "
                                 f"got {len(seq)}")
    return np.array([_vector(p, 2, _join(path, i)) for i, p in enumerate(seq)]).reshape(-1, 2)


def _index(value, n: int, path: str, what: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise PatternError(path, f"expected {what} index (an integer), got {_show(value)}")
    if not 0 <= value < n:
        raise PatternError(path, f"{what} {value} does not exist (0 to {n - 1})")
    return value


def _flag(value, path: str) -> bool:
    if isinstance(value, bool) or value in (0, 1):
        return bool(value)
    raise PatternError(path, f"expected 0 or 1 (or true/false), got {_show(value)}")


def _keys(spec: Mapping, path: str, allowed=(), required=()):
    """Refuse keys outside ``allowed`` (if given) and missing ``required`` ones."""
    if allowed:
        for key in spec:
            if key not in allowed:
                raise PatternError(_join(path, key), f"unknown key (allowed: "
                                                     f"{', '.join(sorted(allowed))})")
    for key in required:
        if key not in spec:
            raise PatternError(_join(path, key), "missing")


def _label(value, path: str) -> str | None:
    if value is None:
        return None
    if not isinstance(value, str):
        raise PatternError(path, f"expected a string label, got {_show(value)}")
    return value


# --- geometry checks shared by both readers ------------------------------------

def _curve(kind: str, params, a: np.ndarray, b: np.ndarray, relative: bool, scale: float,
           path: str, shift: np.ndarray | None = None):
    """The curve of an edge from a to b (metres) given its curvature description.
    ``shift`` (metres) is subtracted from absolute control points: the offset by
    which the panel's vertices were moved (normalize_panel_translation), since
    pygarment converts them to relative coordinates before that move."""
    def control(points):
        if relative:      # along the edge and to its left, in units of its straight length
            d = b - a
            perp = np.array([-d[1], d[0]])
            return a + points[:, :1] * d + points[:, 1:] * perp
        return points * scale - (0.0 if shift is None else shift)

    if kind == "circle":
        seq = _sequence(params, path, "[radius, large_arc, right]")
        if len(seq) != 3:
            raise PatternError(path, f"expected [radius, large_arc, right], got {_show(params)}")
        radius = _number(seq[0], _join(path, 0), positive=True) * scale
        return CircularArc(a, b, radius, _flag(seq[1], _join(path, 1)),
                           _flag(seq[2], _join(path, 2)))
    if kind in ("quadratic", "cubic"):
        count = 1 if kind == "quadratic" else 2
        pts = _points(params, path, (count,), "control points" if count > 1 else "control point")
        return Bezier(np.vstack([a, control(pts), b]))
    raise PatternError(path, f"unknown curvature type {_show(kind)} "
                             "(circle, quadratic or cubic)")


def _check_loop(name: str, edges: list[tuple[int, int]], path: str):
    for i, (s, e) in enumerate(edges):
        if s == e:
            raise PatternError(_join(path, f"{i}.endpoints"), f"panel {name!r}: edge {i} "
                               f"starts and ends at vertex {s}")
        nxt = edges[(i + 1) % len(edges)]
        if e != nxt[0]:
            raise PatternError(_join(path, f"{(i + 1) % len(edges)}.endpoints"),
                               f"panel {name!r}: the edges do not form a closed loop: edge {i} "
                               f"ends at vertex {e}, edge {(i + 1) % len(edges)} starts at "
                               f"vertex {nxt[0]}")
    starts = [s for s, _ in edges]
    if len(set(starts)) != len(starts):
        raise PatternError(path, f"panel {name!r}: the edge loop passes a vertex twice")


def _segments_cross(p: np.ndarray, q: np.ndarray) -> tuple[int, int, str] | None:
    """First pair (i, j) of the closed chain's segments p[i]-q[i], p[j]-q[j]
    (neighbours excluded) that cross, touch (an end on the other segment) or
    overlap (collinear), with which of the three; None if no two meet."""
    n = p.shape[0]
    d = q - p

    def orient(a, b, c):                    # (b - a) x (c - a), broadcast
        return (b[..., 0] - a[..., 0]) * (c[..., 1] - a[..., 1]) - \
               (b[..., 1] - a[..., 1]) * (c[..., 0] - a[..., 0])

    pi, qi = p[:, None, :], q[:, None, :]
    pj, qj = p[None, :, :], q[None, :, :]
    # an orientation is a length squared: zero below 1e-9 of the longest segment's square
    tol = 1e-9 * float(np.max(np.einsum("nd,nd->n", d, d)))
    s1, s2 = (np.sign(o) * (np.abs(o) > tol) for o in (orient(pi, qi, pj), orient(pi, qi, qj)))
    s3, s4 = (np.sign(o) * (np.abs(o) > tol) for o in (orient(pj, qj, pi), orient(pj, qj, qi)))
    cross = (s1 * s2 < 0) & (s3 * s4 < 0)
    collinear = (s1 == 0) & (s2 == 0) & (s3 == 0) & (s4 == 0)
    touch = (s1 * s2 <= 0) & (s3 * s4 <= 0) & ~cross & ~collinear
    # collinear: do the projections on segment i overlap?
    dd = np.einsum("nd,nd->n", d, d)[:, None]
    t0 = np.einsum("ijd,id->ij", pj - pi, d) / dd
    t1 = np.einsum("ijd,id->ij", qj - pi, d) / dd
    overlap = collinear & (np.maximum(t0, t1) > 1e-9) & (np.minimum(t0, t1) < 1.0 - 1e-9)
    idx = np.arange(n)
    apart = np.abs(idx[:, None] - idx[None, :])
    apart = (apart > 1) & (apart < n - 1) & (idx[:, None] < idx[None, :])
    for hits, what in ((cross & apart, "cross"), (touch & apart, "touch"),
                       (overlap & apart, "overlap")):
        found = np.argwhere(hits)
        if found.size:
            return int(found[0, 0]), int(found[0, 1]), what
    return None


def _check_outline(panel: Panel, path: str, per_edge: int = 24):
    pts = panel.outline(per_edge)
    if abs(signed_area(pts)) <= 1e-12:
        raise PatternError(path, f"panel {panel.name!r}: the outline encloses no area")
    hit = _segments_cross(pts, np.roll(pts, -1, axis=0))
    if hit is not None:
        e1, e2, what = hit[0] // per_edge, hit[1] // per_edge, hit[2]
        which = f"edges {e1} and {e2} {what}" if e1 != e2 else f"edge {e1} meets itself"
        raise PatternError(path, f"panel {panel.name!r}: the outline intersects itself ({which})")


def _check_stitches(pattern_panels: dict, stitches: list[Stitch], path: str):
    used: dict[tuple[str, int], int] = {}
    for k, st in enumerate(stitches):
        for side in (st.a, st.b):
            for e in side.edges:
                key = (side.panel, e)
                if key in used:
                    other = used[key]
                    where = "twice in this stitch" if other == k else f"also in stitch {other}"
                    raise PatternError(_join(path, k), f"edge {e} of panel {side.panel!r} is "
                                       f"sewn {where}")
                used[key] = k


def _label_of(pattern_panels: dict, side: SeamSide) -> str | None:
    panel = pattern_panels[side.panel]
    for e in side.edges:
        if panel.edges[e].label:
            return panel.edges[e].label
    return None


# --- GarmentCode specification ---------------------------------------------------

def read_garmentcode(spec: Mapping, name: str | None = None) -> Pattern:
    """A GarmentCode specification (the parsed JSON) as a :class:`Pattern`."""
    spec = _mapping(spec, "", "a GarmentCode specification (a mapping with 'pattern')")
    if "pattern" not in spec:
        raise PatternError("pattern", "missing: a GarmentCode specification has a 'pattern' "
                                      "section with 'panels' and 'stitches'")
    props = _mapping(spec.get("properties", {}), "properties")
    units = _number(props.get("units_in_meter", 100), "properties.units_in_meter",
                    positive=True)
    scale = 1.0 / units
    coords = props.get("curvature_coords", "relative")
    if coords not in ("relative", "absolute"):
        raise PatternError("properties.curvature_coords", f"expected 'relative' or 'absolute', "
                                                          f"got {_show(coords)}")
    recenter = _flag(props.get("normalize_panel_translation", False),
                     "properties.normalize_panel_translation")
    pat = _mapping(spec["pattern"], "pattern")
    panels_spec = _mapping(pat.get("panels"), "pattern.panels", "a mapping of panels by name")
    if not panels_spec:
        raise PatternError("pattern.panels", "no panels")
    order = list(panels_spec)
    if "panel_order" in pat:
        listed = _sequence(pat["panel_order"], "pattern.panel_order", "a list of panel names")
        if sorted(map(str, listed)) != sorted(order):
            raise PatternError("pattern.panel_order", "does not list exactly the panels of "
                                                      "pattern.panels")
        order = list(listed)
    panels = {}
    for pname in order:
        panels[pname] = _garmentcode_panel(str(pname), panels_spec[pname],
                                           f"pattern.panels.{pname}", scale,
                                           coords == "relative", recenter)
    stitches = _garmentcode_stitches(pat.get("stitches", []), panels, "pattern.stitches")
    return Pattern(tuple(panels.values()), tuple(stitches), name)


def _garmentcode_panel(name: str, spec, path: str, scale: float, relative: bool,
                       recenter: bool) -> Panel:
    spec = _mapping(spec, path)
    for key in ("vertices", "edges"):
        if key not in spec:
            raise PatternError(_join(path, key), f"missing: panel {name!r} needs {key}")
    verts = _points(spec["vertices"], _join(path, "vertices"), what="vertices") * scale
    if len(verts) < 2:
        raise PatternError(_join(path, "vertices"), f"panel {name!r} has {len(verts)} vertices")
    translation = _vector(spec.get("translation", [0, 0, 0]), 3, _join(path, "translation"))
    translation = translation * scale
    degrees = _vector(spec.get("rotation", [0, 0, 0]), 3, _join(path, "rotation"))
    offset = np.zeros(2)
    if recenter:        # pygarment adds the 2D offset to translation unrotated, as here
        offset = verts.mean(axis=0)
        verts = verts - offset
        translation = translation + np.array([offset[0], offset[1], 0.0])
    epath = _join(path, "edges")
    edge_specs = _sequence(spec["edges"], epath, "a list of edges")
    if len(edge_specs) < 2:
        raise PatternError(epath, f"panel {name!r} has {len(edge_specs)} edges: an outline "
                                  "needs at least 2")
    ends = []
    for i, e in enumerate(edge_specs):
        e = _mapping(e, _join(epath, i))
        _keys(e, _join(epath, i), required=("endpoints",))
        pair = _sequence(e["endpoints"], _join(epath, f"{i}.endpoints"), "[start, end]")
        if len(pair) != 2:
            raise PatternError(_join(epath, f"{i}.endpoints"), f"expected [start, end], "
                                                               f"got {_show(pair)}")
        ends.append(tuple(_index(v, len(verts), _join(epath, f"{i}.endpoints.{k}"), "vertex")
                          for k, v in enumerate(pair)))
    _check_loop(name, ends, epath)
    edges = []
    for i, (e, (s, t)) in enumerate(zip(edge_specs, ends)):
        a, b = verts[s], verts[t]
        ep = _join(epath, i)
        if not np.hypot(*(b - a)) > 1e-9 * max(1.0, float(np.abs(verts).max())):
            raise PatternError(_join(ep, "endpoints"), f"panel {name!r}: edge {i} has zero "
                               f"length (vertices {s} and {t} coincide)")
        curvature = e.get("curvature")
        cpath = _join(ep, "curvature")
        try:
            if curvature is None:
                curve = Line(a, b)
            elif isinstance(curvature, Mapping):
                if "type" not in curvature or "params" not in curvature:
                    raise PatternError(cpath, f"expected {{type, params}}, got "
                                              f"{_show(dict(curvature))}")
                curve = _curve(curvature["type"], curvature["params"], a, b, relative, scale,
                               _join(cpath, "params") if curvature["type"] in
                               ("circle", "quadratic", "cubic") else _join(cpath, "type"),
                               offset)
            else:       # the older format: a bare control point of a quadratic Bézier
                point = _vector(curvature, 2, cpath)
                curve = _curve("quadratic", [point.tolist()], a, b, relative, scale, cpath,
                               offset)
        except ValueError as err:
            if isinstance(err, PatternError):
                raise
            raise PatternError(cpath, f"panel {name!r} edge {i}: {err}") from None
        edges.append(Edge(s, t, curve, _label(e.get("label"), _join(ep, "label"))))
    panel = Panel(name, verts, tuple(edges), rotation_matrix(degrees), translation,
                  label=_label(spec.get("label"), _join(path, "label")),
                  rotation_degrees=tuple(float(v) for v in degrees))
    _check_outline(panel, path)
    return panel


def _garmentcode_stitches(spec, panels: dict, path: str) -> list[Stitch]:
    seq = _sequence(spec, path, "a list of stitches")
    out = []
    for k, st in enumerate(seq):
        spath = _join(path, k)
        if isinstance(st, Mapping) and ("from" in st or "to" in st):
            raise PatternError(spath, "the older {from, to} stitch form is not supported: "
                                      "write [{panel, edge}, {panel, edge}]")
        st = _sequence(st, spath, "[{panel, edge}, {panel, edge}]")
        same = False
        if len(st) == 3:
            if st[2] != "right_wrong":
                raise PatternError(_join(spath, 2), f"expected \"right_wrong\" or nothing, got "
                                                    f"{_show(st[2])}")
            same = True
        elif len(st) != 2:
            raise PatternError(spath, f"a stitch joins two edges: got {len(st)} entries")
        sides = []
        for j in range(2):
            side = _mapping(st[j], _join(spath, j), "{panel, edge}")
            _keys(side, _join(spath, j), required=("panel", "edge"))
            pname = side["panel"]
            if pname not in panels:
                raise PatternError(_join(spath, f"{j}.panel"), f"no panel named {_show(pname)}")
            e = _index(side["edge"], len(panels[pname].edges), _join(spath, f"{j}.edge"),
                       f"edge of panel {pname!r}:")
            sides.append((pname, e))
        a = SeamSide(sides[0][0], (sides[0][1],), False)
        b = SeamSide(sides[1][0], (sides[1][1],), not same)
        out.append(Stitch(a, b, _label_of(panels, a) or _label_of(panels, b)))
    _check_stitches(panels, out, path)
    return out


# --- compact form -------------------------------------------------------------------

_REF = re.compile(r"^\s*(?P<panel>.+?)\s*:\s*(?P<first>\d+)\s*(?:-\s*(?P<last>\d+))?\s*$")
_CURVE_KEYS = ("arc", "quad", "cubic")


def read_compact(spec: Mapping, name: str | None = None) -> Pattern:
    """A pattern in the compact form (module docstring) as a :class:`Pattern`."""
    spec = _mapping(spec, "", "a pattern (a mapping with 'panels')")
    _keys(spec, "", allowed=("name", "units_in_meter", "curve_coords", "panels", "seams"))
    units = _number(spec.get("units_in_meter", 1), "units_in_meter", positive=True)
    scale = 1.0 / units
    coords = spec.get("curve_coords", "relative")
    if coords not in ("relative", "absolute"):
        raise PatternError("curve_coords", f"expected 'relative' or 'absolute', got "
                                           f"{_show(coords)}")
    panels_spec = _mapping(spec.get("panels"), "panels", "a mapping of panels by name")
    if not panels_spec:
        raise PatternError("panels", "no panels")
    panels = {str(n): _compact_panel(str(n), p, f"panels.{n}", scale, coords == "relative")
              for n, p in panels_spec.items()}
    seams = _compact_seams(spec.get("seams", []) or [], panels, "seams")
    return Pattern(tuple(panels.values()), tuple(seams), spec.get("name", name))


def _compact_panel(name: str, spec, path: str, scale: float, relative: bool) -> Panel:
    spec = _mapping(spec, path)
    _keys(spec, path, allowed=("vertices", "edges", "translation", "rotation", "grain", "label"))
    if "vertices" not in spec:
        raise PatternError(_join(path, "vertices"), f"missing: panel {name!r} needs its outline")
    verts = _points(spec["vertices"], _join(path, "vertices"), what="vertices") * scale
    n = len(verts)
    if n < 3:
        raise PatternError(_join(path, "vertices"), f"panel {name!r}: an outline needs at least "
                                                    f"3 vertices, got {n}")
    epath = _join(path, "edges")
    extra = _mapping(spec.get("edges", {}) or {}, epath, "a mapping of edge index to "
                                                         "{arc|quad|cubic, label}")
    by_index = {}
    for key, value in extra.items():
        kpath = _join(epath, key)
        try:
            i = int(key)
        except (TypeError, ValueError):
            raise PatternError(kpath, "edge keys are edge indices") from None
        by_index[_index(i, n, kpath, f"edge of panel {name!r}:")] = (_mapping(value, kpath), kpath)
    edges = []
    for i in range(n):
        a, b = verts[i], verts[(i + 1) % n]
        if not np.hypot(*(b - a)) > 1e-9 * max(1.0, float(np.abs(verts).max())):
            raise PatternError(_join(path, "vertices"), f"panel {name!r}: edge {i} has zero "
                               f"length (vertices {i} and {(i + 1) % n} coincide)")
        desc, kpath = by_index.get(i, ({}, _join(epath, i)))
        _keys(desc, kpath, allowed=_CURVE_KEYS + ("label",))
        kinds = [k for k in _CURVE_KEYS if k in desc]
        if len(kinds) > 1:
            raise PatternError(kpath, f"panel {name!r} edge {i}: one of arc, quad, cubic, "
                                      f"not {' and '.join(kinds)}")
        try:
            if not kinds:
                curve = Line(a, b)
            elif kinds[0] == "arc":
                apath = _join(kpath, "arc")
                arc = _mapping(desc["arc"], apath, "{radius, large, right}")
                _keys(arc, apath, allowed=("radius", "large", "right"), required=("radius",))
                curve = CircularArc(
                    a, b, _number(arc["radius"], _join(apath, "radius"), positive=True) * scale,
                    _flag(arc.get("large", False), _join(apath, "large")),
                    _flag(arc.get("right", False), _join(apath, "right")))
            else:
                kind = "quadratic" if kinds[0] == "quad" else "cubic"
                curve = _curve(kind, desc[kinds[0]], a, b, relative, scale,
                               _join(kpath, kinds[0]))
        except ValueError as err:
            if isinstance(err, PatternError):
                raise
            raise PatternError(kpath, f"panel {name!r} edge {i}: {err}") from None
        edges.append(Edge(i, (i + 1) % n, curve, _label(desc.get("label"),
                                                         _join(kpath, "label"))))
    translation = _vector(spec.get("translation", [0, 0, 0]), 3,
                          _join(path, "translation")) * scale
    degrees = _vector(spec.get("rotation", [0, 0, 0]), 3, _join(path, "rotation"))
    grain = None
    if "grain" in spec:
        grain = _vector(spec["grain"], 2, _join(path, "grain"))
        if not np.hypot(*grain) > 0:
            raise PatternError(_join(path, "grain"), "the grain direction must not be [0, 0]")
    panel = Panel(name, verts, tuple(edges), rotation_matrix(degrees), translation, grain,
                  _label(spec.get("label"), _join(path, "label")),
                  tuple(float(v) for v in degrees))
    _check_outline(panel, path)
    return panel


def _side(ref, panels: dict, path: str, reverse: bool) -> SeamSide:
    if isinstance(ref, Mapping):
        _keys(ref, path, required=("panel", "edges"))
        pname = ref["panel"]
        raw = ref["edges"]
        edge_list = [raw] if isinstance(raw, int) and not isinstance(raw, bool) else \
            list(_sequence(raw, _join(path, "edges"), "an edge index or a list of them"))
    elif isinstance(ref, str):
        m = _REF.match(ref)
        if not m:
            raise PatternError(path, f"expected 'panel:edge' or 'panel:first-last', got "
                                     f"{_show(ref)}")
        pname = m["panel"]
        first = int(m["first"])
        last = int(m["last"]) if m["last"] is not None else first
        if pname in panels:
            n = len(panels[pname].edges)
            _index(first, n, path, f"edge of panel {pname!r}:")
            _index(last, n, path, f"edge of panel {pname!r}:")
            edge_list = [(first + k) % n for k in range((last - first) % n + 1)]
        else:
            edge_list = []
    else:
        raise PatternError(path, f"expected 'panel:edge' or {{panel, edges}}, got {_show(ref)}")
    if pname not in panels:
        raise PatternError(path, f"no panel named {_show(pname)}")
    n = len(panels[pname].edges)
    edges = tuple(_index(e, n, path, f"edge of panel {pname!r}:") for e in edge_list)
    if not edges:
        raise PatternError(path, "a seam side needs at least one edge")
    for e0, e1 in zip(edges, edges[1:]):
        if e1 != (e0 + 1) % n:
            raise PatternError(path, f"edges {list(edges)} of panel {pname!r} are not "
                                     "consecutive in the panel's loop order")
    return SeamSide(pname, edges, reverse)


def _compact_seams(spec, panels: dict, path: str) -> list[Stitch]:
    seq = _sequence(spec, path, "a list of seams")
    out = []
    for k, seam in enumerate(seq):
        spath = _join(path, k)
        label = None
        if isinstance(seam, Mapping):
            _keys(seam, spath, allowed=("sides", "right_wrong", "label"), required=("sides",))
            sides = _sequence(seam["sides"], _join(spath, "sides"), "two seam sides")
            same = _flag(seam.get("right_wrong", False), _join(spath, "right_wrong"))
            label = _label(seam.get("label"), _join(spath, "label"))
            side_path = _join(spath, "sides")
        else:
            sides = list(_sequence(seam, spath, "[side, side] or {sides, right_wrong, label}"))
            same = False
            if len(sides) == 3:
                if sides[2] != "right_wrong":
                    raise PatternError(_join(spath, 2), f"expected right_wrong or nothing, got "
                                                        f"{_show(sides[2])}")
                same, sides = True, sides[:2]
            side_path = spath
        if len(sides) != 2:
            raise PatternError(side_path, f"a seam joins two sides: got {len(sides)}")
        a = _side(sides[0], panels, _join(side_path, 0), False)
        b = _side(sides[1], panels, _join(side_path, 1), not same)
        out.append(Stitch(a, b, label or _label_of(panels, a) or _label_of(panels, b)))
    _check_stitches(panels, out, path)
    return out


def to_compact(pattern: Pattern) -> dict:
    """The compact form of ``pattern`` (metres, absolute control points): reading
    it back gives the same geometry, edge numbering and stitches."""
    panels = {}
    for p in pattern.panels:
        verts = [p.vertices[e.start].tolist() for e in p.edges]
        edges = {}
        for i, e in enumerate(p.edges):
            desc = {}
            c = e.curve
            if isinstance(c, CircularArc):
                desc["arc"] = {"radius": c.radius, "large": c.large, "right": c.right}
            elif isinstance(c, Bezier):
                desc["quad" if c.kind == "quadratic" else "cubic"] = c.control[1:-1].tolist()
            if e.label:
                desc["label"] = e.label
            if desc:
                edges[i] = desc
        entry = {"vertices": verts, "translation": p.translation.tolist(),
                 "rotation": list(p.rotation_degrees), "grain": p.grain.tolist()}
        if edges:
            entry["edges"] = edges
        if p.label:
            entry["label"] = p.label
        panels[p.name] = entry
    seams = []
    for st in pattern.stitches:
        a, b = st.a, st.b
        if a.reverse and not b.reverse:      # the compact form walks its first side forwards
            a, b = b, a
        seam = {"sides": [{"panel": a.panel, "edges": list(a.edges)},
                          {"panel": b.panel, "edges": list(b.edges)}],
                "right_wrong": a.reverse == b.reverse}
        if st.label:
            seam["label"] = st.label
        seams.append(seam)
    out = {"units_in_meter": 1, "curve_coords": "absolute", "panels": panels, "seams": seams}
    if pattern.name:
        out["name"] = pattern.name
    return out


# --- files ------------------------------------------------------------------------

def load_pattern(path: str) -> Pattern:
    """Read a GarmentCode specification (JSON with a ``pattern`` section) or a
    compact pattern (YAML or JSON) from ``path``."""
    try:
        with open(path, encoding="utf-8") as stream:
            text = stream.read()
    except OSError as err:
        raise PatternError("", f"{path}: {err.strerror}") from None
    try:
        data = json.loads(text) if path.lower().endswith(".json") else yaml.safe_load(text)
    except (ValueError, yaml.YAMLError) as err:
        first = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
        raise PatternError("", f"{path}: not valid {'JSON' if path.lower().endswith('.json') else 'YAML'}: {first}") from None
    name = os.path.splitext(os.path.basename(path))[0]
    if name.endswith("_specification"):
        name = name[: -len("_specification")]
    if isinstance(data, Mapping) and "pattern" in data:
        return read_garmentcode(data, name)
    return read_compact(data, name)
