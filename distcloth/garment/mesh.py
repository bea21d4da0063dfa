"""Triangle meshes of a pattern's panels, with the vertices of every stitch paired.

Each panel's outline is discretised as ``discretize.py`` says (one target
edge length h; the two sides of a stitch with the same arc-length fractions),
and its interior is meshed by Gmsh (Geuzaine and Remacle 2009), its
Frontal-Delaunay algorithm first, with target size h.  The outline goes in
as one discrete curve whose nodes and segments are given; Gmsh never remeshes
a discrete curve, so the seam vertices stay where they were put and stay
paired.  That is checked after every meshing: the outline comes back bit for
bit, with no node added on it, and the triangles tile the outline polygon.

Gmsh aims at well-shaped triangles but promises no minimum angle, so every
mesh is checked: if a triangle has an angle below ``min_angle``, Gmsh's
Delaunay and MeshAdapt algorithms are tried in turn.  If none reaches the
bound, the outline is too coarse there (segments longer than the panel is
wide, in strips narrower than h): the outline segments that a bad triangle's
vertices or circumcentre encroach (Ruppert's rule, Shewchuk 2002 §3) are
split at their arc-length middle through ``Outlines.insert``, so the other
side of a stitch gets a vertex at the same fraction, and the panels concerned
are meshed again.  If no segment is encroached, ``MeshError`` names the panel
and the angle.  Triangles at a corner of the outline sharper than
``min_angle`` cannot be helped and are left.

Vertices are numbered per panel (the outline first, from edge 0's start in
loop order, then the interior) and globally by concatenating the panels in
the pattern's order.  Stitched vertices are not merged: every stitch lists
its pairs of global vertex indices, for sewing.
"""
from __future__ import annotations

import math
import signal
from dataclasses import dataclass, replace

import numpy as np

from .discretize import Outlines, side_fractions
from .pattern import Panel, Pattern, SeamSide, Stitch

MIN_ANGLE = 25.0          # degrees
MAX_SPLIT_ROUNDS = 12     # rounds of outline vertices added where the mesh needs them
# Gmsh's 2D algorithms for triangles, in the order tried (Mesh.Algorithm): Frontal-
# Delaunay gives the best angles; the others sometimes succeed where it does not (next
# to a sharp corner, narrow pieces at coarse h).  Frontal-Delaunay for quads (8) crashes
# the process on a discrete outline.  Gmsh's optimisation passes (Relocate2D,
# Laplace2D) mended none of the meshes these missed, so none is run.
ALGORITHMS = ((6, "Frontal-Delaunay"), (5, "Delaunay"), (1, "MeshAdapt"))
_GMSH_OPTIONS = (
    ("General.Terminal", 0),                # silent
    ("General.NumThreads", 1),              # MPI ranks own the cores; one thread, one result
    ("Mesh.MaxNumThreads2D", 1),
    ("Mesh.RandomSeed", 1),                 # reseeded at every meshing: the same mesh every time
    ("Mesh.MeshSizeMax", 1.0),              # coordinates are in units of h
    ("Mesh.AlgorithmSwitchOnFailure", 0),   # the next algorithm is ours to choose
    # stop meshing at an error and log it: the default (2) throws it from inside the
    # mesher's OpenMP region, which aborts the whole process (a crossing outline does)
    ("General.AbortOnError", 1),
)
_gmsh_module = None


class MeshError(RuntimeError):
    """A panel could not be meshed to the required quality."""


@dataclass(frozen=True)
class _Refine:
    """A panel not yet meshed to the angle bound: the outline points, as
    (edge, arc-length fraction), to add, and the smallest angle."""
    points: list[tuple[int, float]]
    worst: float


@dataclass(frozen=True, eq=False)
class PanelMesh:
    panel: Panel
    vertices: np.ndarray                    # (n, 2) m, the panel's frame; outline first
    triangles: np.ndarray                   # (t, 3) local indices, counter-clockwise seen
    #                                         from the panel's outside
    positions: np.ndarray                   # (n, 3) m, placed around the body
    edge_vertices: tuple[np.ndarray, ...]   # per edge: local indices from its start to its end
    edge_fractions: tuple[np.ndarray, ...]  # per edge: arc-length fractions of those vertices
    offset: int                             # global index of local vertex 0
    n_outline: int                          # vertices 0 .. n_outline - 1 are on the outline

    @property
    def global_triangles(self) -> np.ndarray:
        return self.triangles + self.offset


@dataclass(frozen=True, eq=False)
class SeamMesh:
    """The vertices of one stitch: ``pairs[k]`` = (global index on side a,
    global index on side b), in the order the sides are walked;
    ``fractions[k]`` their arc-length fractions along their sides."""
    stitch: Stitch
    pairs: np.ndarray                       # (k, 2) int
    fractions: np.ndarray                   # (k, 2)


@dataclass(frozen=True, eq=False)
class GarmentMesh:
    pattern: Pattern
    target_edge: float
    min_angle: float
    panels: tuple[PanelMesh, ...]
    seams: tuple[SeamMesh, ...]

    @property
    def positions(self) -> np.ndarray:
        """(N, 3) placed positions of all panels' vertices, global numbering."""
        return np.concatenate([p.positions for p in self.panels])

    @property
    def triangles(self) -> np.ndarray:
        return np.concatenate([p.global_triangles for p in self.panels])

    def panel(self, name: str) -> PanelMesh:
        return self.panels[self.pattern.panel_index(name)]


def triangle_angles(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """(t, 3) interior angles in degrees, at each triangle's corners in order."""
    p = points[triangles]
    u = np.roll(p, -1, axis=1) - p          # to the next corner
    w = np.roll(p, 1, axis=1) - p           # to the previous corner
    cross = u[..., 0] * w[..., 1] - u[..., 1] * w[..., 0]
    return np.degrees(np.arctan2(np.abs(cross), np.einsum("tkd,tkd->tk", u, w)))


def outline_angles(outline: np.ndarray, orientation: int) -> np.ndarray:
    """Interior angle (degrees, up to 360) of a closed polygon at each vertex;
    ``orientation`` +1 for a counter-clockwise loop, -1 for a clockwise one."""
    u = np.roll(outline, 1, axis=0) - outline       # to the previous vertex
    w = np.roll(outline, -1, axis=0) - outline      # to the next vertex
    cross = w[:, 0] * u[:, 1] - w[:, 1] * u[:, 0]
    dot = np.einsum("nd,nd->n", u, w)
    return np.degrees(np.arctan2(orientation * cross, dot)) % 360.0


def _cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """z component of the cross product of rows of 2D vectors."""
    return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]


def _gmsh():
    """The gmsh module, initialised once per process.  Debian's gmsh 4.8 resets
    SIGINT to the default action when imported (later versions have
    ``initialize(interruptible=False)`` instead): the handler is put back, so
    Ctrl-C still raises KeyboardInterrupt.  Configuration files are not read,
    so every machine and rank meshes with the same options."""
    global _gmsh_module
    if _gmsh_module is None:
        handler = signal.getsignal(signal.SIGINT)
        import gmsh  # here, not at the top: importing it resets SIGINT (above)
        if handler is not None:
            signal.signal(signal.SIGINT, handler)
        gmsh.initialize(readConfigFiles=False)
        for option, value in _GMSH_OPTIONS:
            gmsh.option.setNumber(option, value)
        _gmsh_module = gmsh
    return _gmsh_module


def _triangulate(outline: np.ndarray, h: float, algorithm: int, name: str,
                 holes: tuple[np.ndarray, ...] = ()):
    """Gmsh's ``algorithm`` on the closed outline (n, 2) less the closed
    ``holes`` inside it, in units of h so the target size is 1; returns
    vertices (the outline's, then each hole's, bit for bit, then the
    interior's) and triangles, or raises MeshError if the algorithm fails
    or changes a boundary."""
    gmsh = _gmsh()
    curves = [np.asarray(outline, dtype=np.float64)] + [np.asarray(c, dtype=np.float64)
                                                         for c in holes]
    n = sum(c.shape[0] for c in curves)
    gmsh.clear()
    gmsh.option.setNumber("Mesh.Algorithm", algorithm)
    # each boundary as a discrete curve, already meshed: its nodes and segments are final
    first, loops, tag_lists = 1, [], []
    for k, curve in enumerate(curves, start=1):
        tags = np.arange(first, first + curve.shape[0])
        first += curve.shape[0]
        gmsh.model.addDiscreteEntity(1, k)
        gmsh.model.mesh.addNodes(1, k, tags,
                                 np.column_stack([curve / h, np.zeros(len(curve))]).ravel())
        gmsh.model.mesh.addElementsByType(k, 1, [],
                                          np.column_stack([tags, np.roll(tags, -1)]).ravel())
        loops.append(gmsh.model.geo.addCurveLoop([k], k))
        tag_lists.append(tags)
    gmsh.model.geo.addPlaneSurface(loops, 1)
    gmsh.model.geo.synchronize()
    label = dict(ALGORITHMS).get(algorithm, algorithm)
    gmsh.logger.start()
    try:
        gmsh.model.mesh.generate(2)
        errors = [m for m in gmsh.logger.get() if m.startswith("Error")]
    except Exception as err:        # the binding raises a bare Exception
        errors = [str(err)]
    finally:
        gmsh.logger.stop()
    if errors:
        raise MeshError(f"panel {name!r}: Gmsh's {label} failed ({'; '.join(errors)}); does "
                        "the outline touch itself?")
    for k, (curve, tags) in enumerate(zip(curves, tag_lists), start=1):
        on_curve, xyz, _ = gmsh.model.mesh.getNodes(1, k)
        if not (np.array_equal(on_curve, tags)
                and np.array_equal(xyz.reshape(-1, 3)[:, :2], curve / h)):
            raise MeshError(f"panel {name!r}: Gmsh's {label} changed the outline")
    inner, xyz, _ = gmsh.model.mesh.getNodes(2, 1)
    _, nodes = gmsh.model.mesh.getElementsByType(2)
    index = np.full(max(n, int(inner.max(initial=0))) + 1, -1, dtype=np.int64)
    index[1:n + 1] = np.arange(n)
    index[inner.astype(np.int64)] = n + np.arange(inner.size)
    tris = index[nodes.astype(np.int64).reshape(-1, 3)]
    verts = np.concatenate(curves + [xyz.reshape(-1, 3)[:, :2] * h])
    # a disc with m holes: 2V - n - 2 + 2m triangles (Euler), every vertex
    # used, the triangles' areas adding up to the region's (no overlap, no gap)
    a, b, c = (verts[tris[:, k]] for k in range(3))
    area = np.abs(_cross(b - a, c - a)).sum() / 2.0
    region = sum((1 if k == 0 else -1) * abs(_polygon_area(curve)) for k, curve in enumerate(curves))
    if (tris.shape[0] != 2 * verts.shape[0] - n - 2 + 2 * len(holes) or np.any(tris < 0)
            or np.any(np.bincount(tris.ravel(), minlength=verts.shape[0]) == 0)
            or abs(area - region) > 1e-9 * region):
        raise MeshError(f"panel {name!r}: Gmsh's {label} did not tile the outline")
    return verts, tris


def triangulate(outline: np.ndarray, h: float, holes: tuple[np.ndarray, ...] = (),
                name: str = "region"):
    """A region meshed as a panel is, for specimens and test shapes: the
    closed ``outline`` (n, 2) less ``holes``, every boundary vertex kept and
    first in the result (outline, then holes), interior at target edge h,
    Gmsh's algorithms tried in the panel mesher's order until one reaches
    ``MIN_ANGLE`` (else the last one's mesh); returns (vertices (V, 2),
    triangles (T, 3), counter-clockwise)."""
    best = None
    for algorithm, _ in ALGORITHMS:
        try:
            verts, tris = _triangulate(outline, h, algorithm, name, holes)
        except MeshError:
            continue
        a, b, c = (verts[tris[:, k]] for k in range(3))
        flip = _cross(b - a, c - a) < 0
        tris[flip] = tris[flip][:, [0, 2, 1]]
        best = (verts, tris)
        if triangle_angles(verts, tris).min() >= MIN_ANGLE:
            break
    if best is None:
        raise MeshError(f"{name!r}: no Gmsh algorithm meshed it")
    return best


def _polygon_area(curve: np.ndarray) -> float:
    x, y = curve[:, 0], curve[:, 1]
    return float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y)) / 2.0


def _encroached(outline: np.ndarray, verts: np.ndarray, bad: np.ndarray) -> np.ndarray:
    """Outline segments (index of their first vertex) whose diametral disc
    holds a vertex or the circumcentre of a bad triangle (``bad``, (k, 3)):
    Ruppert's rule for the segments to split before such a triangle can be
    mended."""
    a, b, c = (verts[bad[:, k]] for k in range(3))
    ab, ac = b - a, c - a
    d = 2.0 * _cross(ab, ac)
    ab2, ac2 = np.einsum("kd,kd->k", ab, ab), np.einsum("kd,kd->k", ac, ac)
    with np.errstate(divide="ignore", invalid="ignore"):    # a flat triangle: no centre
        centre = a + np.stack([ac[:, 1] * ab2 - ab[:, 1] * ac2,
                               ab[:, 0] * ac2 - ac[:, 0] * ab2], axis=1) / d[:, None]
    p = np.concatenate([verts[np.unique(bad)], centre])
    s, e = outline, np.roll(outline, -1, axis=0)
    # inside the disc on [s, e] as diameter: the segment is seen at more than 90 degrees
    dot = np.einsum("pnd,pnd->pn", s[None] - p[:, None], e[None] - p[:, None])
    scale = np.einsum("nd,nd->n", e - s, e - s)
    return np.flatnonzero(np.any(dot < -1e-12 * scale[None], axis=0))


def _in_sharp_corners(outline: np.ndarray, starts: np.ndarray, orientation: int,
                      min_angle: float, tris: np.ndarray, n_vertices: int) -> np.ndarray:
    """Triangles inside an outline corner sharper than ``min_angle``: those
    with a vertex on each of the corner's two arms (the apex counts as both),
    which no refinement can bring to the bound (the wedge is too narrow)."""
    n = outline.shape[0]
    out = np.zeros(tris.shape[0], dtype=bool)
    for v in np.flatnonzero(outline_angles(outline, orientation) < min_angle):
        e = int(np.searchsorted(starts, v, side="right")) - 1
        # at a corner the first arm is the previous edge (starts ends with n, not an edge)
        before = starts[(e - 1) % (starts.size - 1)] if v == starts[e] else starts[e]
        after = starts[e + 1] % n
        arms = []
        for a, b in ((before, v), (v, after)):
            arm = np.zeros(n_vertices, dtype=bool)
            arm[np.arange(a, b + (n if b < a else 0) + 1) % n] = True
            arms.append(arm[tris].any(axis=1))
        out |= arms[0] & arms[1]
    return out


def _mesh_panel(panel: Panel, fractions: list[np.ndarray], h: float, min_angle: float
                ) -> PanelMesh | _Refine:
    """The panel's mesh (offset 0), or what to add to its outline first."""
    counts = np.array([len(s) - 1 for s in fractions])
    starts = np.concatenate([[0], np.cumsum(counts)])
    n = int(starts[-1])
    outline = np.concatenate([e.curve.point(s[:-1]) for e, s in zip(panel.edges, fractions)])
    first, best, failure = None, None, None
    for algorithm, label in ALGORITHMS:
        try:
            verts, tris = _triangulate(outline, h, algorithm, panel.name)
        except MeshError as err:
            failure = err
            continue
        # counter-clockwise seen from the outside: the edge loop's own turning sense
        a, b, c = (verts[tris[:, k]] for k in range(3))
        flip = _cross(b - a, c - a) * panel.orientation < 0.0
        tris[flip] = tris[flip][:, ::-1]

        worst = triangle_angles(verts, tris).min(axis=1)
        bad = (worst < min_angle - 1e-9) & ~_in_sharp_corners(
            outline, starts, panel.orientation, min_angle, tris, verts.shape[0])
        if not np.any(bad):
            edge_vertices = tuple(np.append(starts[i] + np.arange(counts[i]), starts[i + 1] % n)
                                  for i in range(len(panel.edges)))
            return PanelMesh(panel, verts, tris, panel.place(verts), edge_vertices,
                             tuple(fractions), 0, n)
        if first is None:
            first = (verts, tris[bad])
        if best is None or worst[bad].min() > best[0]:
            best = (float(worst[bad].min()), label)
    if first is None:
        raise failure
    segments = _encroached(outline, *first)
    if segments.size == 0:      # splitting the outline cannot help
        raise MeshError(f"panel {panel.name!r}: no Gmsh algorithm reached {min_angle:g} "
                        f"degrees (best: {best[1]}, an angle of {best[0]:.1f} degrees) and no "
                        "outline segment is encroached")
    edges = np.searchsorted(starts, segments, side="right") - 1
    lo = np.concatenate([f[:-1] for f in fractions])[segments]
    hi = np.concatenate([f[1:] for f in fractions])[segments]
    return _Refine(list(zip(edges.tolist(), ((lo + hi) / 2.0).tolist())), best[0])



def _seam(pattern: Pattern, stitch: Stitch, meshes: dict) -> SeamMesh:
    def side(s: SeamSide):
        m = meshes[s.panel]
        idx = np.concatenate([m.edge_vertices[e][(k > 0):] for k, e in enumerate(s.edges)])
        return (idx[::-1] if s.reverse else idx) + m.offset, \
            side_fractions(pattern, s, list(m.edge_fractions))

    (ia, fa), (ib, fb) = side(stitch.a), side(stitch.b)
    if ia.size != ib.size:      # discretize.Outlines gives both sides one list
        raise MeshError(f"stitch {stitch}: {ia.size} and {ib.size} vertices on its sides")
    return SeamMesh(stitch, np.stack([ia, ib], axis=1), np.stack([fa, fb], axis=1))


def mesh_pattern(pattern: Pattern, target_edge: float, min_angle: float = MIN_ANGLE
                 ) -> GarmentMesh:
    """Mesh every panel of ``pattern`` with target edge length ``target_edge`` (m)."""
    h = float(target_edge)
    if not (math.isfinite(h) and h > 0.0):
        raise ValueError(f"target edge length must be a finite number > 0, got {target_edge!r}")
    # a check, not a target: Gmsh's worst panels on the shared patterns are at 35 to 38
    # degrees, and splitting the outline does not mend the interior
    if not 0.0 < min_angle <= 33.0:
        raise ValueError(f"min_angle must be in (0, 33] degrees, got {min_angle!r}")
    outlines = Outlines(pattern, h)
    meshes: dict[str, PanelMesh] = {}
    todo = set(pattern.panel_names)
    for _ in range(MAX_SPLIT_ROUNDS):
        changed = set()
        for name in sorted(todo):       # sorted: the same splits in the same order everywhere
            result = _mesh_panel(pattern.panel(name), outlines.panel(name), h, min_angle)
            if isinstance(result, PanelMesh):
                meshes[name] = result
                continue
            added = set()
            for edge, s in result.points:
                added |= outlines.insert(name, edge, s)
            if not added:       # nothing new to split: refining cannot help
                raise MeshError(f"panel {name!r}: a triangle with an angle of "
                                f"{result.worst:.1f} degrees next to the outline, below "
                                f"{min_angle:g}")
            changed |= added
        if not changed:
            break
        todo = changed
    else:
        raise MeshError(f"panels {sorted(todo)}: still triangles with an angle below "
                        f"{min_angle:g} degrees after {MAX_SPLIT_ROUNDS} rounds of outline "
                        "splitting")
    placed, offset = [], 0
    for panel in pattern.panels:
        placed.append(replace(meshes[panel.name], offset=offset))
        offset += placed[-1].vertices.shape[0]
    by_name = {m.panel.name: m for m in placed}
    seams = tuple(_seam(pattern, st, by_name) for st in pattern.stitches)
    return GarmentMesh(pattern, h, float(min_angle), tuple(placed), seams)
