"""SceneConfig -> Model: place every piece, wire its springs, lump its mass."""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from ..collision.colliders import MeshFrameError, collider_file_error, read_mesh_frames
from ..config.schema import ClothSpec, ConfigError, SceneConfig
from ..model import FLEXION, SHEAR, STRUCTURAL, Model, PieceInfo
from ..physics.bending import hinges
from ..physics.bending_shell import shell_jump_stencils, shell_stencils
from ..physics.hinge_consistency import POOR_STAR_RESIDUAL, star_residual
from . import grid as gridlib
from .meshio import MeshFormatError, read_mesh
from .grips import Loads, group_of_vertices, piece_grips, piece_loads, start_velocities
from .pins import select_one, select_pin_axes, select_pins
from .placement import place
from .weld_vertices import count_parts, weld_coincident
from .garment import (Garment, body_meshes, check_garment_start, garment_arrays,
                      pattern_piece_of)
from .skin_follow import add_skin_grips, region_candidates
from .uvs import scene_uvs
from .springs import (check_triangle_mesh, flexion_stiffness, grid_spring_constants,
                      mesh_springs, mesh_structural_stiffness, triangle_areas)

_GRID_FAMILY_KIND = {"structural_u": STRUCTURAL, "structural_v": STRUCTURAL,
                     "shear": SHEAR, "flexion_u": FLEXION, "flexion_v": FLEXION}


@dataclass
class _Piece:
    positions: np.ndarray        # (n, 3) placed rest positions
    triangles: np.ndarray        # (nt, 3) piece-local
    vertex_area: np.ndarray      # (n,) lumped area
    springs: np.ndarray          # (ns, 2) piece-local
    stiffness: np.ndarray        # (ns,)
    kind: np.ndarray             # (ns,) int8
    pinned: np.ndarray           # piece-local
    grid_resolution: tuple[int, int] | None
    slide_index: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    slide_axis: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    garment: Garment | None = None    # pattern pieces: grain, stitches, fused regions
    file_index: np.ndarray | None = None   # welded file meshes: new index of each file vertex
    notes: list[str] = field(default_factory=list)   # what loading it changed or found
    pin_sets: list = field(default_factory=list)      # each pins entry's piece-local vertices
    load_sets: list = field(default_factory=list)     # each loads entry's piece-local vertices
    flexion_lines: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), dtype=np.int64))
    flexion_hinges: np.ndarray = field(default_factory=lambda: np.zeros((0, 4), dtype=np.int64))
    twist_cells: np.ndarray = field(default_factory=lambda: np.zeros((0, 4), dtype=np.int64))


def build_model(cfg: SceneConfig) -> Model:
    """The Model of a scene: pieces concatenated in order (vertex and
    triangle indices offset), pins as sorted unique global indices.

    Lumped mass = density * vertex area (or the piece's mass split equally
    with mass_lumping: uniform).  Mesh files: a third of each
    adjacent triangle.  Grids: a quarter of each adjacent cell, uniform over
    the interior whatever the triangle pattern (a third of each triangle
    would give the alternating pattern's 8- and 4-triangle vertices 4/3 and
    2/3 of a cell, a checkerboard of masses the cloth does not have; for the
    regular pattern the two agree on interior vertices).

    Mass-spring grids with the ``bending`` effect on get flexion line
    elements (three consecutive vertices along u or v: physics/bending.py,
    ``FlexionLineTerm``); they carry no in-plane stiffness, so the structural
    springs are the same with bending on or off.  Mass-spring mesh files
    (consistently oriented) bend by dihedral angles on their hinges
    (``flexion_hinges``); garment panels keep flexion springs."""
    if not cfg.cloth:
        raise ConfigError("cloth", [], "at least one cloth piece")
    bending_active = cfg.has("bending")
    _check_one_continuum_material(cfg)
    _check_collider_files(cfg)
    garments = any(spec.mesh.pattern is not None for spec in cfg.cloth)
    bodies = (body_meshes(cfg) if garments and (cfg.garment.clearance > 0
                                                or cfg.garment.start_check) else [])
    pieces = [_build_piece(p, spec, bending_active and spec.material.model == "mass_spring", cfg,
                           bodies, grid_lines=bending_active
                           and spec.material.bending_kind == "grid_lines")
              for p, spec in enumerate(cfg.cloth)]

    if bending_active:
        for p, (spec, piece) in enumerate(zip(cfg.cloth, pieces)):
            piece.notes.extend(_per_hinge_mesh_notes(spec, piece, f"cloth.{p}"))

    infos, vertex_start, triangle_start = [], 0, 0
    for spec, piece in zip(cfg.cloth, pieces):
        vertex_stop = vertex_start + piece.positions.shape[0]
        triangle_stop = triangle_start + piece.triangles.shape[0]
        infos.append(PieceInfo(spec.name, vertex_start, vertex_stop, triangle_start,
                               triangle_stop, piece.grid_resolution))
        vertex_start, triangle_start = vertex_stop, triangle_stop
    offsets = [info.vertex_start for info in infos]

    positions = np.concatenate([piece.positions for piece in pieces])
    triangles = np.concatenate([piece.triangles + o for piece, o in zip(pieces, offsets)])
    springs = np.concatenate([piece.springs + o for piece, o in zip(pieces, offsets)])
    stiffness = np.concatenate([piece.stiffness for piece in pieces])
    kind = np.concatenate([piece.kind for piece in pieces])
    pinned = np.unique(np.concatenate([piece.pinned + o for piece, o in zip(pieces, offsets)]))
    flexion_lines = np.concatenate([piece.flexion_lines + o for piece, o in zip(pieces, offsets)])
    flexion_hinges = np.concatenate([piece.flexion_hinges + o for piece, o in zip(pieces, offsets)])
    twist_cells = np.concatenate([piece.twist_cells + o for piece, o in zip(pieces, offsets)])
    slide_index = np.concatenate([piece.slide_index + o for piece, o in zip(pieces, offsets)])
    slide_axis = np.concatenate([piece.slide_axis for piece in pieces])
    # a fully pinned vertex stays fully pinned; a vertex sliding along two axes is pinned
    keep = ~np.isin(slide_index, pinned)
    slide_index, slide_axis = slide_index[keep], slide_axis[keep]
    uniq, counts = np.unique(slide_index, return_counts=True)
    twice = uniq[counts > 1]
    pinned = np.union1d(pinned, twice)
    keep = ~np.isin(slide_index, twice)
    slide_index, slide_axis = slide_index[keep], slide_axis[keep]
    # c = damping * k along each spring (docs/config.md)
    damping = np.concatenate([np.full(piece.springs.shape[0], spec.material.damping)
                              for spec, piece in zip(cfg.cloth, pieces)]) * stiffness
    vertex_area = np.concatenate([piece.vertex_area for piece in pieces])
    vertex_mass = np.concatenate([_lumped_mass(spec, piece)
                                  for spec, piece in zip(cfg.cloth, pieces)])
    rest_length = np.linalg.norm(positions[springs[:, 1]] - positions[springs[:, 0]], axis=1)
    if any(piece.garment is not None for piece in pieces):
        vertex_mass = vertex_mass + np.concatenate(
            [piece.garment.added_mass if piece.garment is not None
             else np.zeros(piece.positions.shape[0]) for piece in pieces])

    hinge_vertices = shell_stencil = shell_present = shell_jump = None
    kinds = {spec.material.bending_kind for spec in cfg.cloth}
    try:
        if kinds & {"dihedral", "isometric"}:
            hinge_vertices = hinges(triangles)
        if kinds & {"dihedral_shell", "isometric_shell"}:
            shell_stencil, shell_present = shell_stencils(triangles)
            shell_jump = shell_jump_stencils(shell_stencil, shell_present)
    except ValueError as exc:
        raise ConfigError("cloth", "mesh", "hinge bending needs consistently oriented "
                          f"triangles: {exc}") from None
    model = Model(rest_positions=positions, triangles=triangles.astype(np.int64),
                 hinge_vertices=hinge_vertices, shell_stencil=shell_stencil,
                 shell_present=shell_present, shell_jump_stencil=shell_jump,
                 flexion_lines=flexion_lines.astype(np.int64) if flexion_lines.shape[0] else None,
                 flexion_hinges=(flexion_hinges.astype(np.int64) if flexion_hinges.shape[0]
                                 else None),
                 twist_cells=twist_cells.astype(np.int64) if twist_cells.shape[0] else None,
                 vertex_mass=vertex_mass, vertex_area=vertex_area,
                 spring_vertices=springs.astype(np.int64), spring_rest_length=rest_length,
                 spring_stiffness=stiffness, spring_damping=damping,
                 spring_kind=kind.astype(np.int8), pinned=pinned.astype(np.int64),
                 slide_vertices=slide_index.astype(np.int64), slide_axes=slide_axis,
                 pieces=infos, initial_positions=_start_noise(cfg, infos, positions, triangles))
    model.load_notes = [note for piece in pieces for note in piece.notes]
    model.grips = [g for p, (spec, piece, o) in enumerate(zip(cfg.cloth, pieces, offsets))
                   for g in piece_grips(spec, piece.pin_sets, piece.positions, o, f"cloth.{p}")]
    model.pin_group = group_of_vertices(model.grips, model.num_vertices)
    loads = [piece_loads(spec, piece.load_sets, piece.positions, piece.triangles, o,
                         f"cloth.{p}")
             for p, (spec, piece, o) in enumerate(zip(cfg.cloth, pieces, offsets))]
    model.loads = Loads(*(np.concatenate([getattr(x, name) for x in loads])
                          for name in ("vertices", "forces", "ramps")))
    model.initial_velocities = start_velocities(cfg, model)
    uvs = scene_uvs(cfg, infos)
    if uvs is not None:
        model.uv, model.uv_index = uvs
    if any(piece.garment is not None for piece in pieces):
        garment_arrays(model, cfg, [piece.garment for piece in pieces], offsets)
        if cfg.garment.start_check:
            check_garment_start(cfg, model, bodies)
    if any(spec.follow_skin is not None for spec in cfg.cloth):
        model.follow_regions = region_candidates(cfg, model, [piece.garment for piece in pieces])
        if model.stitch_pairs is None:      # a sewn garment is attached at its weld (sew.py)
            add_skin_grips(cfg, model, 0.0)
    return model


def _start_noise(cfg: SceneConfig, infos, positions, triangles):
    """Start positions moved along the rest normals by each piece's seeded noise
    (``start_noise``), or None when no piece asks for it.  Drawn from the
    global model, so every rank and any rank count get the same start."""
    if not any(spec.start_noise.amplitude > 0 for spec in cfg.cloth):
        return None
    normals = np.zeros_like(positions)
    corner = positions[triangles]
    area_normal = np.cross(corner[:, 1] - corner[:, 0], corner[:, 2] - corner[:, 0])
    for k in range(3):
        np.add.at(normals, triangles[:, k], area_normal)
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-300)
    start = positions.copy()
    for spec, info in zip(cfg.cloth, infos):
        noise = spec.start_noise
        if noise.amplitude > 0:
            rows = slice(info.vertex_start, info.vertex_stop)
            draw = np.random.default_rng(noise.seed).standard_normal(info.vertex_stop
                                                                      - info.vertex_start)
            start[rows] += noise.amplitude * draw[:, None] * normals[rows]
    return start


def _check_one_continuum_material(cfg: SceneConfig) -> None:
    """All pieces share the material model, strain and bending model, and fem
    pieces one orthotropic law (one force term per effect; per-piece laws later)."""
    first = cfg.cloth[0].material if cfg.cloth else None
    for p, spec in enumerate(cfg.cloth[1:], start=1):
        m = spec.material
        same = (m.model == first.model and m.bending_kind == first.bending_kind
                and (m.model != "fem" or (m.orthotropic() == first.orthotropic()
                                          and m.strain == first.strain)))
        if not same:
            raise ConfigError(f"cloth.{p}.material", m.model,
                              "the same model, strain, bending model and (fem) moduli as "
                              "cloth.0.material: per-piece continuum laws are not supported yet")


def _build_piece(p: int, spec: ClothSpec, bending_active: bool, cfg: SceneConfig,
                 bodies=(), grid_lines: bool = False) -> _Piece:
    """``bending_active``: mass-spring bending (line elements on a grid,
    hinges on a file); ``grid_lines``: the continuum's line and twist
    elements on a grid."""
    key = f"cloth.{p}"
    mesh = spec.mesh
    if mesh.grid is not None:
        piece = _grid_piece(spec, bending_active or grid_lines, key)
        if grid_lines:
            piece.twist_cells = gridlib.grid_twist_cells(piece.grid_resolution)
    elif mesh.file is not None:
        piece = _file_piece(spec, key)
        if bending_active:
            try:     # mass-spring bending by dihedral angles on the file's hinges
                piece.flexion_hinges = hinges(piece.triangles)
            except ValueError:
                pass     # not consistently oriented: its flexion springs bend it
    elif mesh.pattern is not None:
        garment = pattern_piece_of(spec, p, cfg, bodies)
        piece = _triangle_piece(spec, garment.positions, garment.triangles)
        piece.garment = garment
    else:
        raise ConfigError(f"{key}.mesh", None, "exactly one of grid, file")
    pins = spec.pins
    if piece.file_index is not None:     # pin indices are the file's, before the weld
        pins = tuple(_welded_pin(pin, piece.file_index, f"{key}.pins.{i}")
                     for i, pin in enumerate(pins))
    piece.pinned = select_pins(pins, piece.positions, piece.grid_resolution, f"{key}.pins")
    piece.pin_sets = [select_one(pin, piece.positions, piece.grid_resolution, f"{key}.pins.{i}")
                      for i, pin in enumerate(pins)]
    loads = spec.loads
    if piece.file_index is not None:
        loads = tuple(_welded_pin(load, piece.file_index, f"{key}.loads.{i}")
                      for i, load in enumerate(loads))
    piece.load_sets = [select_one(load, piece.positions, piece.grid_resolution,
                                  f"{key}.loads.{i}") for i, load in enumerate(loads)]
    piece.slide_index, piece.slide_axis = select_pin_axes(pins, piece.positions,
                                                          piece.grid_resolution, f"{key}.pins")
    return piece


# the least every rank holds per vertex of the whole model (positions, masses,
# springs, the pattern and the matrix rows of its own share come on top)
MODEL_BYTES_PER_VERTEX = 400


def _check_fits_in_memory(n_vertices: int, key: str, value) -> None:
    """Refuse a mesh whose model alone cannot fit in this machine's available
    memory, before anything is allocated (every rank holds the whole model)."""
    available = available_memory()
    need = n_vertices * MODEL_BYTES_PER_VERTEX
    if available is not None and need > available:
        raise ConfigError(key, value, f"a mesh that fits in memory: {n_vertices} vertices need "
                          f"at least {need / 2**30:.3g} GiB, {available / 2**30:.3g} GiB available")


def available_memory() -> int | None:
    """MemAvailable of /proc/meminfo in bytes (None where there is none)."""
    try:
        with open("/proc/meminfo", encoding="ascii") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def _check_collider_files(cfg: SceneConfig) -> None:
    """Every mesh collider's files read and agree frame by frame, whether or not
    the collisions effect is on, so that `check` finds a bad one before any work."""
    for i, spec in enumerate(cfg.colliders):
        if spec.shape == "mesh":
            try:
                read_mesh_frames(spec.files)
            except MeshFrameError as exc:
                raise collider_file_error(spec, f"colliders.{i}", exc) from None


def _welded_pin(pin, file_index: np.ndarray, key: str):
    """``pin`` (or a load) with its file vertex indices moved to the welded mesh's."""
    if pin.indices is None:
        return pin
    indices = np.asarray(pin.indices, dtype=np.int64)
    if ((indices < 0) | (indices >= file_index.shape[0])).any():
        raise ConfigError(f"{key}.indices", list(pin.indices),
                          f"vertex indices of the file, 0 <= i < {file_index.shape[0]}")
    return dataclasses.replace(pin, indices=tuple(int(i) for i in file_index[indices]))


def _grid_piece(spec: ClothSpec, bending_active: bool, key: str) -> _Piece:
    grid = spec.mesh.grid
    if grid.pattern not in gridlib.GRID_PATTERNS:
        raise ConfigError(f"{key}.mesh.grid.pattern", grid.pattern,
                          "one of " + " | ".join(gridlib.GRID_PATTERNS))
    resolution = (int(grid.resolution[0]), int(grid.resolution[1]))
    _check_fits_in_memory(resolution[0] * resolution[1], f"{key}.mesh.grid.resolution",
                          list(resolution))
    dx, dy = gridlib.grid_spacing(grid.size, resolution)
    positions = place(gridlib.grid_vertices(grid.size, resolution),
                      spec.mesh.rotation, spec.mesh.center)
    families = gridlib.grid_springs(resolution)
    material = spec.material
    if material.model != "mass_spring":
        # springs are unused by the continuum terms: derive harmless constants
        # (no shear) rather than refuse fem on long cells
        material = dataclasses.replace(material, shear=0.0, bending=0.0)
    constants = grid_spring_constants(material, dx, dy, key=f"{key}.material")
    names = gridlib.GRID_SPRING_FAMILIES
    counts = [families[name].shape[0] for name in names]
    return _Piece(
        positions=positions,
        triangles=gridlib.grid_triangles(resolution, grid.pattern),
        vertex_area=gridlib.grid_vertex_area(grid.size, resolution),
        springs=np.concatenate([families[name] for name in names]),
        stiffness=np.repeat([constants[name] for name in names], counts),
        kind=np.repeat([_GRID_FAMILY_KIND[name] for name in names], counts).astype(np.int8),
        pinned=np.zeros(0, dtype=np.int64), grid_resolution=resolution,
        flexion_lines=(gridlib.grid_flexion_lines(resolution) if bending_active
                       else np.zeros((0, 3), dtype=np.int64)))


def _lumped_mass(spec, piece) -> np.ndarray:
    """The piece's vertex masses: density times each vertex's lumped area, or
    (mass_lumping: uniform) the piece's whole mass split equally over its
    vertices; the total is density times the piece's area either way."""
    area = piece.vertex_area
    if spec.mass_lumping == "uniform":
        return np.full(area.shape[0], spec.material.density * area.sum() / area.shape[0])
    return spec.material.density * area


def _triangle_lumped_area(positions: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Each triangle gives a third of its area to each of its corners."""
    corner_share = np.repeat(triangle_areas(positions, triangles) / 3.0, 3)
    return np.bincount(triangles.ravel(), weights=corner_share, minlength=positions.shape[0])


def _file_piece(spec: ClothSpec, key: str) -> _Piece:
    """A triangle mesh from an OBJ / PLY file: unused vertices, degenerate,
    repeated or non-manifold triangles are refused, not repaired, so that
    vertex indices in pins mean what they mean in the file."""
    mesh = spec.mesh
    file_index, notes = None, []
    try:
        vertices, triangles = read_mesh(mesh.file)
        vertices = vertices * mesh.scale
        if mesh.weld:
            n_file = vertices.shape[0]
            vertices, triangles, file_index, merged = weld_coincident(vertices, triangles,
                                                                      mesh.weld_tolerance)
            if merged:
                notes.append(f"{key}: welded {merged} of {n_file} vertices that coincide "
                             f"(within mesh.weld_tolerance {mesh.weld_tolerance:g} m)")
        check_triangle_mesh(vertices, triangles)
        topology = mesh_springs(vertices, triangles)     # refuses what springs cannot carry
    except OSError as exc:
        raise ConfigError(f"{key}.mesh.file", mesh.file,
                          f"a readable OBJ or PLY file ({exc.strerror or exc})") from None
    except MeshFormatError as exc:
        raise ConfigError(f"{key}.mesh.file", mesh.file,
                          f"an OBJ or PLY triangle mesh cloth can use: {exc}") from None
    parts = count_parts(vertices.shape[0], triangles)
    if parts > 1:
        notes.append(f"warning: {key} is {parts} separate parts (no shared vertices between "
                     "them): they move apart" + ("; mesh.weld is off" if not mesh.weld else ""))
    piece = _triangle_piece(spec, place(vertices, mesh.rotation, mesh.center), triangles,
                            vertices, topology)
    piece.file_index, piece.notes = file_index, notes
    return piece


def _per_hinge_mesh_notes(spec: ClothSpec, piece: _Piece, key: str) -> list[str]:
    """A warning when a mesh file bends per hinge on a mesh where that is
    measurably short.  Per-hinge sums are the plate only where each vertex
    star meets five conditions (physics/hinge_consistency.py): the panel
    mesher's near-equilateral meshes nearly do, jittered or right-angled
    meshes do not.  Grids bend by grid lines and garments are meshed by
    distcloth, so only mesh files are checked."""
    per_hinge = (spec.material.model == "mass_spring"
                 or spec.material.bending_kind in ("dihedral", "isometric"))
    if spec.mesh.file is None or not per_hinge:
        return []
    residual = star_residual(piece.positions, piece.triangles)
    if not residual > POOR_STAR_RESIDUAL:          # nan: no interior vertex
        return []
    remedy = ("bending_model: dihedral_shell is within 2 % on any mesh, at 5-8x the step cost"
              if spec.material.model == "fem" else "a near-equilateral mesh is within 1.5 %")
    return [f"warning: {key}.mesh.file: its triangles are far from equilateral for per-hinge "
            f"bending (hinge-star residual {residual:.2f}, above {POOR_STAR_RESIDUAL:g}; "
            "Frontal-Delaunay meshes 0.13-0.24): on such meshes the Peirce bending length "
            f"came out 1-4 % short, the rigidity 4-12 % low; {remedy} (docs/fidelity.md)"]


def _triangle_piece(spec: ClothSpec, positions, triangles, vertices=None,
                    topology=None) -> _Piece:
    """Springs and lumped areas of a placed triangle mesh (``vertices``: its
    unplaced rest shape, the same up to a rigid motion and scale)."""
    vertices = positions if vertices is None else vertices
    topology = mesh_springs(vertices, triangles) if topology is None else topology
    material = spec.material
    edge_length = np.linalg.norm(vertices[topology.edges[:, 1]] - vertices[topology.edges[:, 0]],
                                 axis=1)
    flexion_length = np.linalg.norm(vertices[topology.flexion[:, 1]]
                                    - vertices[topology.flexion[:, 0]], axis=1)
    return _Piece(
        positions=positions, triangles=triangles,
        vertex_area=_triangle_lumped_area(vertices, triangles),
        springs=np.concatenate([topology.edges, topology.flexion]),
        stiffness=np.concatenate([
            mesh_structural_stiffness(material.stretch, topology.edge_area, edge_length),
            flexion_stiffness(material.bending, flexion_length)]),
        kind=np.concatenate([np.full(topology.edges.shape[0], STRUCTURAL, dtype=np.int8),
                             np.full(topology.flexion.shape[0], FLEXION, dtype=np.int8)]),
        pinned=np.zeros(0, dtype=np.int64), grid_resolution=None)
