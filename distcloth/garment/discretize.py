"""Where the mesh vertices go on a pattern's panel outlines.

Every edge gets arc-length fractions s in [0, 1] (0 and 1 included) at which
its vertices lie.  An unsewn edge of length L starts with ceil(L / h) equal
segments for the target edge length h.  The two sides of a stitch share one
list of fractions u along the side, each side walked as the stitch says, so
vertex k of one side is sewn to vertex k of the other and both sit at the
same fraction of their side's arc length even when the two sides differ in
length (the longer side sets the count, as pygarment's boxmeshgen.py
BoxMesh.read_stitches does: "Assign n of longer edge").

A side of several edges has corners inside it; each corner must be a vertex
of its own side, and a vertex of the other side is put at the same fraction.
Corners of the two sides closer than a quarter of h (along the longer side)
are taken as one (their fractions then differ by less than that), so that
nearly matching corners do not leave a sliver segment.

The mesher may ask for a vertex to be added on an outline (where Ruppert's
segment splitting would put one); on a sewn edge it goes into the stitch's
shared list, so the other side gets a vertex at the same fraction and the
pairing stays one to one.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .pattern import Pattern, SeamSide, Stitch

# corners of the two sides of a stitch closer than this fraction of h are merged
MERGE_FRACTION = 0.25


def uniform_fractions(length: float, h: float) -> np.ndarray:
    """Fractions of ceil(length / h) equal segments (at least one)."""
    n = max(1, math.ceil(length / h))
    return np.linspace(0.0, 1.0, n + 1)


def _knots(lengths: np.ndarray, reverse: bool) -> np.ndarray:
    """Fractions of a side's corners in the order the side is walked."""
    c = np.concatenate([[0.0], np.cumsum(lengths)]) / lengths.sum()
    c[-1] = 1.0
    return 1.0 - c[::-1] if reverse else c


def _merged_knots(ka: np.ndarray, kb: np.ndarray, tol: float):
    """One sorted list of corner fractions for both sides, and each side's own
    corners mapped onto it (a merged pair takes the mean of the two); two
    corners of the same side are never merged."""
    order = sorted([(u, 0, i) for i, u in enumerate(ka)] + [(u, 1, i) for i, u in enumerate(kb)])
    clusters: list[list[tuple[float, int, int]]] = []
    for item in order:
        last = clusters[-1] if clusters else None
        if last and item[0] - last[0][0] <= tol and all(s != item[1] for _, s, _ in last):
            last.append(item)
        else:
            clusters.append([item])
    reps = np.array([np.mean([u for u, _, _ in c]) for c in clusters])
    reps[0], reps[-1] = 0.0, 1.0          # both sides start at 0 and end at 1
    own = (np.empty(len(ka)), np.empty(len(kb)))
    for r, c in zip(reps, clusters):
        for _, s, i in c:
            own[s][i] = r
    return reps, own


@dataclass
class _Seam:
    stitch: Stitch
    u: np.ndarray                         # shared fractions along both sides, sorted
    knots: tuple[np.ndarray, np.ndarray]  # each side's corners on the u scale, walk order

    def walked(self, k: int) -> tuple[int, ...]:
        side = (self.stitch.a, self.stitch.b)[k]
        return side.edges[::-1] if side.reverse else side.edges


def _new_seam(pattern: Pattern, stitch: Stitch, h: float) -> _Seam:
    sides = (stitch.a, stitch.b)
    lengths = [np.array([pattern.panel(s.panel).edges[e].length() for e in s.edges])
               for s in sides]
    longest = max(float(L.sum()) for L in lengths)
    reps, own = _merged_knots(*(_knots(L, s.reverse) for L, s in zip(lengths, sides)),
                              MERGE_FRACTION * h / longest)
    pieces = [np.linspace(a, b, max(1, math.ceil((b - a) * longest / h)) + 1)[:-1]
              for a, b in zip(reps[:-1], reps[1:])]
    return _Seam(stitch, np.concatenate(pieces + [[1.0]]), own)


class Outlines:
    """The fractions of every edge of a pattern, refined on request."""

    def __init__(self, pattern: Pattern, h: float):
        self.pattern = pattern
        self.seams = [_new_seam(pattern, st, h) for st in pattern.stitches]
        # (panel, edge) -> (seam index, side 0/1, position of the edge in the side's walk)
        self.sewn = {}
        for i, seam in enumerate(self.seams):
            for k, side in enumerate((seam.stitch.a, seam.stitch.b)):
                for j, e in enumerate(seam.walked(k)):
                    self.sewn[(side.panel, e)] = (i, k, j)
        self.free = {(p.name, i): uniform_fractions(e.length(), h)
                     for p in pattern.panels for i, e in enumerate(p.edges)
                     if (p.name, i) not in self.sewn}

    def edge(self, panel: str, edge: int) -> np.ndarray:
        """Fractions along ``edge`` of ``panel`` (its own direction), 0 and 1 included."""
        if (panel, edge) in self.free:
            return self.free[(panel, edge)]
        i, k, j = self.sewn[(panel, edge)]
        seam = self.seams[i]
        lo, hi = seam.knots[k][j], seam.knots[k][j + 1]
        u = seam.u[np.searchsorted(seam.u, lo):np.searchsorted(seam.u, hi) + 1]
        s = (u - lo) / (hi - lo)
        s[0], s[-1] = 0.0, 1.0
        reverse = (seam.stitch.a, seam.stitch.b)[k].reverse
        return 1.0 - s[::-1] if reverse else s

    def panel(self, name: str) -> list[np.ndarray]:
        return [self.edge(name, i) for i in range(len(self.pattern.panel(name).edges))]

    def insert(self, panel: str, edge: int, s: float) -> set[str]:
        """Add a vertex at fraction ``s`` of ``edge`` of ``panel`` (and at the
        same fraction of the other side if the edge is sewn); returns the
        panels whose outline changed."""
        if (panel, edge) in self.free:
            f = self.free[(panel, edge)]
            if np.any(f == s):
                return set()
            self.free[(panel, edge)] = np.insert(f, np.searchsorted(f, s), s)
            return {panel}
        i, k, j = self.sewn[(panel, edge)]
        seam = self.seams[i]
        side = (seam.stitch.a, seam.stitch.b)[k]
        walk = 1.0 - s if side.reverse else s
        lo, hi = seam.knots[k][j], seam.knots[k][j + 1]
        u = lo + walk * (hi - lo)
        if np.any(seam.u == u):
            return set()
        seam.u = np.insert(seam.u, np.searchsorted(seam.u, u), u)
        return {seam.stitch.a.panel, seam.stitch.b.panel}


def side_fractions(pattern: Pattern, side: SeamSide, fractions: list[np.ndarray]
                   ) -> np.ndarray:
    """Arc-length fractions along a seam side of its vertices, in walk order,
    given its panel's per-edge fractions."""
    panel = pattern.panel(side.panel)
    lengths = np.array([panel.edges[e].length() for e in side.edges])
    before = np.concatenate([[0.0], np.cumsum(lengths)[:-1]])
    frac = np.concatenate([before[k] + fractions[e][(k > 0):] * lengths[k]
                           for k, e in enumerate(side.edges)]) / lengths.sum()
    return 1.0 - frac[::-1] if side.reverse else frac
