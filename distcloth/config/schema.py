"""Typed scene configuration: frozen dataclasses, SI units, every key described once.

Each field carries its doc line, unit, default and allowed values
(describe.py); the loader, the ``--set`` key tree, the resolved YAML and the
key reference of docs/config.md are generated from these declarations.  Rules
that tie several keys together live in rules.py.
"""
from __future__ import annotations

from dataclasses import MISSING, dataclass
from typing import Any

from ..body.clip import ROOT_MOTIONS
from .describe import GIVEN, Only, choice, section, setting
from .fabrics import FABRICS

EFFECTS = ("gravity", "membrane", "bending", "damping", "drag", "collisions", "self_collision",
           "strain_limiting", "loads")
LIMIT_METHODS = ("provot", "velocity")
VELOCITY_RULES = ("average", "directional")
COLLIDER_SHAPES = ("plane", "sphere", "capsule", "box", "mesh")
COLLIDER_METHODS = ("bvh", "image")   # mesh colliders: BVH closest points or image-space maps
IMAGE_AXES = ("x", "y", "z")
UP_AXES = ("y", "z")                   # a mesh collider file's up axis
SKINNING_METHODS = ("dqs", "lbs")      # dual-quaternion or linear blend skinning
CMU_UNIT = 0.0254 / 0.45               # m per length unit of the CMU database's BVH conversions
# the geometry keys of each collider shape (all required)
SHAPE_KEYS = {"plane": ("normal", "offset"), "sphere": ("center", "radius"),
              "capsule": ("a", "b", "radius"), "box": ("center", "half_extents"),
              "mesh": ("file",)}
# geometry keys a shape may leave out: a mesh's center places it
OPTIONAL_SHAPE_KEYS = {"mesh": ("center",)}
INTEGRATORS = ("backward_euler", "bdf2", "implicit_midpoint", "newmark",
               "symplectic_euler", "explicit_midpoint", "rk4")
GRID_PATTERNS = ("regular", "alternating")
GRID_EDGES = ("left", "right", "bottom", "top")
GRID_CORNERS = ("bottom_left", "bottom_right", "top_left", "top_right")
MATERIAL_MODELS = ("mass_spring", "fem")
MASS_LUMPINGS = ("area", "uniform")
STRAIN_MODELS = ("stvk", "corotated")
BENDING_MODELS = ("flexion", "grid_lines", "dihedral", "isometric", "dihedral_shell",
                  "isometric_shell")
MAT_TYPES = ("baij", "aij")
LINEARISATION_POINTS = ("predictor", "start")
RETRY_STOPS = ("no_gain", "converged")     # when the energy retry's Newton stops
DRAPE_METHODS = ("stop_and_go", "dynamic", "quasistatic", "newton")
CONTACT_MODELS = ("constraints", "barrier")   # body contact in an implicit step
DRAPE_STOP_ON = ("potential", "kinetic", "both")
DRAPE_CRITERIA = ("force", "motion")
MAX_NEWTON_ITERATIONS = 100
# the energy-momentum midpoint's default: measured 12 per step on average on a
# swinging FE sheet at h = 10 ms, at most 30 (docs/integrators.md)
ENERGY_MOMENTUM_NEWTON_ITERATIONS = 30

# The prefix of distcloth's PETSc options (-distcloth_ksp_rtol), written once:
# linalg/petsc.py and the command line take it from here.
OPTION_PREFIX = "distcloth_"

# PETSc options a scene gets unless it says otherwise (EG07 tutorial, Part 1
# §5.6: CG with block Jacobi over the ranks, SSOR on each block; BAIJ SOR
# allows only omega = 1, i.e. symmetric Gauss-Seidel).
DEFAULT_SOLVER: dict[str, Any] = {
    "ksp_type": "cg",
    "pc_type": "bjacobi",
    "sub_pc_type": "sor",
    "ksp_rtol": 1.0e-5,
}

# keys that apply only with one value of another key
FEM_ONLY = Only("model", "fem", "only with model: fem (mass_spring uses stretch, shear and "
                                "flexion springs)")
MESH_ONLY = Only("shape", "mesh", "only with shape: mesh")
IMAGE_ONLY = Only("method", "image", "only with method: image")
FILE_ONLY = Only("file", GIVEN, "only for file meshes")
PATTERN_ONLY = Only("pattern", GIVEN, "only for pattern meshes")
VELOCITY_ONLY = Only("method", "velocity", "only with method: velocity")
VELOCITY_GIVEN = Only("velocity", GIVEN, "only with velocity (a constant-velocity motion)")
TIMES_GIVEN = Only("times", GIVEN, "only with times (a keyframed motion)")

Vec3 = tuple[float, float, float]


class ConfigError(Exception):
    """A bad configuration value: key path, the value, and what is allowed."""

    def __init__(self, key: str, value: Any, allowed: str):
        self.key, self.value, self.allowed = key, value, allowed
        super().__init__(f"{key}: {value!r} — {allowed}")


@dataclass(frozen=True)
class GridSpec:
    """A rectangular grid of vertices in the piece's own u-v plane (local x, y),
    each quad split into two triangles."""
    size: tuple[float, float] = setting(doc="[width along u, height along v]", unit="m",
                                        above=0, what="[width, height] in m")
    resolution: tuple[int, int] = setting(doc="vertices along u and along v", at_least=2,
                                          what="[nu, nv] vertices")
    pattern: str = choice("alternating", GRID_PATTERNS, doc="how the quads are split into "
                          "triangles: all along one diagonal, or alternating")


@dataclass(frozen=True)
class MeshSpec:
    """The piece's rest shape, a grid or a triangle mesh from a file, and where it
    is placed: rotated about its bounding-box centre, then moved to `center`."""
    grid: GridSpec | None = setting(None, doc="a generated grid", one_of="shape")
    file: str | None = setting(None, doc="an OBJ or PLY (ASCII or binary little-endian) "
                               "triangle mesh; a relative path is relative to the scene file",
                               read="mesh_file", one_of="shape")
    pattern: str | None = setting(None, doc="a sewing pattern: GarmentCode specification JSON "
                                  "or the compact form (docs/garments.md); its panels are "
                                  "meshed, placed by the pattern, sewn and welded; a relative "
                                  "path is relative to the scene file", read="pattern_file",
                                  one_of="shape")
    scale: float = setting(1.0, doc="scale factor of a file mesh", above=0, only=FILE_ONLY)
    weld: bool = setting(True, doc="file: weld vertices that coincide (an exporter splits "
                         "them along UV seams, and the cloth would tear there); pin indices "
                         "stay the file's", only=FILE_ONLY)
    weld_tolerance: float = setting(1.0e-6, doc="file: vertices closer than this are one "
                                    "(after scale)", unit="m", above=0, only=FILE_ONLY)
    edge_length: float = setting(0.02, doc="pattern: target edge length of the panel meshes",
                                 unit="m", above=0, only=PATTERN_ONLY)
    up_axis: str = choice("y", UP_AXES, doc="pattern: the pattern's up axis; y (GarmentCode's): "
                          "turned +90 degrees about x like a y-up mesh collider, so that the "
                          "garment fits a body read with up_axis: y", only=PATTERN_ONLY)
    translation: Vec3 = setting((0.0, 0.0, 0.0), doc="pattern: added to every vertex after "
                                "the pattern's own placement and up_axis", unit="m",
                                only=PATTERN_ONLY)
    center: Vec3 = setting((0.0, 0.0, 0.0), doc="grid and file: where the bounding-box centre "
                           "goes", unit="m")
    rotation: Vec3 = setting((0.0, 0.0, 0.0), doc="grid and file: rotation about x, then y, "
                             "then z, applied before the translation", unit="degrees")


@dataclass(frozen=True)
class VertexSelector:
    """Vertices of a piece chosen by one selector (pins and loads)."""
    edge: str | None = choice(None, GRID_EDGES, doc="grids only: a side of the grid (u min, "
                              "u max, v min, v max in its own coordinates, before rotation)",
                              one_of="selector")
    corner: str | None = choice(None, GRID_CORNERS, doc="grids only: a corner of the grid",
                                one_of="selector")
    indices: tuple[int, ...] | None = setting(None, doc="vertex indices of this piece, "
                                              "0 <= i < its vertex count", at_least=0,
                                              nonempty=True, what="vertex indices",
                                              one_of="selector")
    box_min: Vec3 | None = setting(None, key="box.min", doc="the vertices inside this box "
                                   "(world coordinates after placement): its low corner",
                                   unit="m", what="[x, y, z] in m", one_of="selector")
    box_max: Vec3 | None = setting(None, key="box.max", doc="the box's high corner, >= min "
                                   "in every component", unit="m", what="[x, y, z] in m",
                                   one_of="selector")


@dataclass(frozen=True)
class PinMotionSpec:
    """Prescribed motion of a pin group (a grip, docs/loads_and_grips.md): a
    constant velocity, or keyframed translations and rotations about a centre,
    linear in between and held after the last key.  The held vertices follow
    it exactly in every integrator; a sliding pin follows its component along
    the axis."""
    velocity: Vec3 | None = setting(None, doc="constant velocity of every vertex of the group",
                                    unit="m/s", one_of="motion")
    start: float = setting(0.0, doc="velocity: when the group starts moving", unit="s",
                           at_least=0, only=VELOCITY_GIVEN)
    stop: float | None = setting(None, doc="velocity: when it stops, > start; null: never",
                                 unit="s", above=0, only=VELOCITY_GIVEN)
    times: tuple[float, ...] | None = setting(None, doc="keyframe times, strictly increasing",
                                              unit="s", nonempty=True, at_least=0,
                                              what="increasing times in s", one_of="motion")
    translations: tuple[Vec3, ...] = setting((), doc="keyframes: displacement from the start "
                                             "position at each time (the first one zero); "
                                             "default zeros", unit="m",
                                             what="[x, y, z] vectors (one per time)",
                                             only=TIMES_GIVEN)
    rotations: tuple[Vec3, ...] = setting((), doc="keyframes: rotation about center at each "
                                          "time as a rotation vector (axis times angle; the "
                                          "first one zero), slerp in between; default zeros",
                                          unit="rad", what="[x, y, z] vectors (one per time)",
                                          only=TIMES_GIVEN)
    center: Vec3 | None = setting(None, doc="keyframes: the point the rotations turn about; "
                                  "null: the group's centroid at the start", unit="m",
                                  only=TIMES_GIVEN)


@dataclass(frozen=True)
class PinSpec(VertexSelector):
    """Vertices held in place, chosen by one selector; with `axis` they are held
    only along that direction (a sliding pin); with `motion` they move as
    prescribed (a grip)."""
    axis: Vec3 | None = setting(None, doc="with any selector: hold the vertices only along "
                                "this direction (S = I - a aᵀ), free across it", nonzero=True)
    motion: PinMotionSpec | None = setting(None, doc="prescribed motion of the group; null: "
                                           "held where it starts")


@dataclass(frozen=True)
class LoadSpec(VertexSelector):
    """An external force on selected vertices of the piece (docs/loads_and_grips.md):
    a point load split equally (or given per vertex), or a line load along
    the mesh's boundary edges whose both ends are selected, lumped to their
    ends by half of each edge's length; constant, or ramped up from zero."""
    force: Vec3 | None = setting(None, doc="point load: the total force, split equally over "
                                 "the selected vertices", unit="N", one_of="load")
    forces: tuple[Vec3, ...] | None = setting(None, doc="point loads with indices: one force "
                                              "per index, in the same order", unit="N",
                                              nonempty=True, what="[x, y, z] vectors (one "
                                              "per index)", one_of="load")
    line_force: Vec3 | None = setting(None, doc="line load per length of the selected "
                                      "boundary (a grid edge, or the boundary edges between "
                                      "selected vertices)", unit="N/m", one_of="load")
    ramp: float = setting(0.0, doc="the load grows linearly from zero to full over this "
                          "time; 0: full from the start", unit="s", at_least=0)


@dataclass(frozen=True)
class MaterialSpec:
    """The piece's material: springs from a membrane stiffness (model: mass_spring,
    Vassilev et al. 2001 §2.2), or linear triangles in plane stress with the
    orthotropic law of the EG07 tutorial, Part 1 Eq. 22 (model: fem; moduli are
    modulus times thickness, in N/m). All pieces of a scene share one material
    law for now; their densities and bending stiffnesses may differ."""
    model: str = choice("mass_spring", MATERIAL_MODELS, doc="mass_spring: structural, shear "
                        "and flexion springs; fem: continuum membrane (EG07 tutorial, Part 1 "
                        "§3.5-3.6)")
    density: float = setting(0.1, doc="mass per area", unit="kg/m²", above=0)
    stretch: float = setting(10.0, doc="uniaxial membrane stiffness Y", unit="N/m", above=0)
    shear: float | None = setting(None, doc="in-plane shear stiffness G of the springs; null: "
                                  "stretch / 10", unit="N/m", at_least=0)
    bending: float = setting(1.0e-6, doc="bending stiffness B", unit="N·m", at_least=0)
    damping: float = setting(0.0, doc="spring damping: c = damping * k along each spring",
                             unit="s", at_least=0)
    E_weft: float | None = setting(None, doc="weft modulus; null: stretch", unit="N/m",
                                   above=0, only=FEM_ONLY)
    E_warp: float | None = setting(None, doc="warp modulus; null: E_weft", unit="N/m",
                                   above=0, only=FEM_ONLY)
    nu_weft: float | None = setting(None, doc="weft Poisson ratio; null: 0.3", at_least=0,
                                    only=FEM_ONLY)
    nu_warp: float | None = setting(None, doc="warp Poisson ratio; null: nu_weft E_warp / "
                                    "E_weft, the only value that keeps Eq. 22 symmetric; "
                                    "nu_weft nu_warp < 1", at_least=0, only=FEM_ONLY)
    G: float | None = setting(None, doc="shear modulus; null: E_weft / (2 (1 + nu_weft))",
                              unit="N/m", above=0, only=FEM_ONLY)
    strain: str = choice("stvk", STRAIN_MODELS, doc="stvk: Green strain, St. Venant-Kirchhoff; "
                         "corotated: Biot strain")
    weft: Vec3 = setting((1.0, 0.0, 0.0), doc="weft direction in the placed rest shape "
                         "(projected on each triangle)", nonzero=True)
    bending_model: str | None = choice(None, BENDING_MODELS, doc="null: flexion for mass_spring "
                                       "(its only model: line elements on grids, hinges on mesh "
                                       "files); for fem grid_lines when every piece is a grid "
                                       "(grid_lines: grids only), else dihedral; the models are "
                                       "compared under Bending models below and in "
                                       "docs/fidelity.md")
    preset: str | None = choice(None, tuple(FABRICS), doc="a named fabric "
                                "(distcloth/config/fabrics.py; values illustrative, no "
                                "measured source): implies model: fem, every key given "
                                "overrides it")
    tension_weft: tuple[tuple[float, float], ...] | None = setting(
        None, doc="strain: stvk only: weft direct stress against Green strain as [[e, S], ...], "
        "piecewise linear from [0, 0], both increasing (EG07 tutorial, Part 2 §1: measured "
        "curves, stiffening)", unit="N/m", read="curve", only=FEM_ONLY)
    tension_warp: tuple[tuple[float, float], ...] | None = setting(
        None, doc="the same for the warp direction", unit="N/m", read="curve", only=FEM_ONLY)
    shear_curve: tuple[tuple[float, float], ...] | None = setting(
        None, doc="strain: stvk only: shear stress against shear strain 2 E_uv (odd in the "
        "strain), as [[e, S], ...] like tension_weft", unit="N/m", read="curve", only=FEM_ONLY)
    compression: float = setting(
        1.0, doc="strain: stvk only: weft and warp stiffness under compression as a fraction of "
        "the stiffness at the start of the tension curve (Choi and Ko 2002: woven cloth buckles "
        "into fine wrinkles at a small fraction of its tensile load, wrinkles a coarse mesh "
        "cannot show; 1: the linear law)", above=0, at_most=1, only=FEM_ONLY)

    def orthotropic(self) -> tuple[float, float, float, float, float]:
        """(E_weft, E_warp, nu_weft, nu_warp, G) with the defaults filled in."""
        e_weft = self.stretch if self.E_weft is None else self.E_weft
        e_warp = e_weft if self.E_warp is None else self.E_warp
        nu_weft = 0.3 if self.nu_weft is None else self.nu_weft
        nu_warp = nu_weft * e_warp / e_weft if self.nu_warp is None else self.nu_warp
        g = e_weft / (2.0 * (1.0 + nu_weft)) if self.G is None else self.G
        return e_weft, e_warp, nu_weft, nu_warp, g

    @property
    def bending_kind(self) -> str:
        if self.bending_model is not None:
            return self.bending_model
        # a fem scene made only of grids gets grid_lines (config/rules.py: the
        # choice needs every piece); elsewhere dihedral, not dihedral_shell: on
        # near-equilateral meshes (the panel mesher's) the per-hinge sum is
        # within 1.5 % of the Peirce bending length, and the shell's step costs
        # 4.6-8.3x at 10k vertices and 4.5-9x at 100k, nearly all in the solve
        # (docs/fidelity.md, docs/benchmarks.md); a mesh file far from
        # equilateral, where it is 1-6 % short, is warned at load (scene/build.py)
        return "flexion" if self.model == "mass_spring" else "dihedral"

    @property
    def shear_stiffness(self) -> float:
        return self.stretch / 10.0 if self.shear is None else self.shear


@dataclass(frozen=True)
class StartNoiseSpec:
    """A seeded random displacement of the start positions along the rest
    shape's normals (the rest shape itself is unchanged): a perfectly flat,
    symmetric cloth pushed in its plane stays flat, as real cloth never does."""
    amplitude: float = setting(0.0, doc="standard deviation of each vertex's displacement "
                               "(0: none)", unit="m", at_least=0)
    seed: int = setting(0, doc="random seed: the same seed gives the same start on any "
                        "number of ranks", at_least=0)


@dataclass(frozen=True)
class FollowSkinSpec:
    """A skin-following region (EG07 tutorial, Part 2 §2.3): a tight part of
    the garment (a waistband, a cuff) moves with the body's surface at the
    offset it had when it was attached instead of being simulated.  Attached
    where the run starts (a sewn garment: at the weld); each vertex keeps its
    position in the frame of the body triangle closest to it then."""
    collider: str | None = setting(None, doc="the mesh collider it follows, by name; null: "
                                   "the scene's only mesh collider")
    edges: tuple[str, ...] = setting((), doc="pattern pieces: labels of the pattern's edges "
                                     "whose band follows (the vertices within band of them in "
                                     "the flat panel); empty: the whole piece (then "
                                     "within alone chooses)",
                                     what="edge labels of the pattern")
    band: float = setting(0.03, doc="width of the band along those edges, in the flat panel",
                          unit="m", above=0)
    within: float = setting(0.01, doc="only the vertices this close to the body's surface "
                            "when attached follow it", unit="m", above=0)


@dataclass(frozen=True)
class ClothSpec:
    """One piece of cloth."""
    name: str = setting(doc="unique among the pieces", auto="piece{index}")
    mesh: MeshSpec = setting(doc="rest shape and placement", what="a mapping with grid: or file:")
    pins: tuple[PinSpec, ...] = setting((), doc="held vertices (a single mapping is a "
                                        "one-element list)", what="pins")
    loads: tuple[LoadSpec, ...] = setting((), doc="point and line loads (the loads effect; a "
                                          "single mapping is a one-element list)",
                                          what="loads")
    initial_velocity: Vec3 = setting((0.0, 0.0, 0.0), doc="velocity of every vertex at the "
                                     "start (pinned directions excepted)", unit="m/s")
    initial_angular_velocity: Vec3 = setting((0.0, 0.0, 0.0), doc="angular velocity about the "
                                             "piece's centroid at the start, added to "
                                             "initial_velocity", unit="rad/s")
    material: MaterialSpec = section(MaterialSpec, doc="the material")
    thickness: float = setting(0.001, doc="contact offset of the cloth against colliders and "
                               "itself", unit="m", at_least=0)
    mass_lumping: str = choice("area", MASS_LUMPINGS, doc="area: each vertex carries density "
                               "times its lumped area; uniform: density times the piece's area, "
                               "split equally over its vertices (what Blender and Newton do, "
                               "for comparisons with them)")
    start_noise: StartNoiseSpec = section(StartNoiseSpec, doc="out-of-plane noise of the start "
                                          "positions")
    follow_skin: FollowSkinSpec | None = setting(None, doc="a region that moves with the body's "
                                                  "surface instead of being simulated; null: "
                                                  "none")
    layer: int = setting(0, doc="pieces worn together: 0 innermost; a piece of layer k "
                         "starts k * garment.layer_gap further out, is sewn after the layers "
                         "under it (from k * garment.sewing.duration on) and, with "
                         "self_collision, meets them in the solve as a body", at_least=0)


@dataclass(frozen=True)
class MotionSpec:
    """Rigid keyframes of a collider: y = R(t) x + p(t) on the shape's
    coordinates; the pose is held before the first time and after the last."""
    times: tuple[float, ...] = setting(doc="keyframe times, strictly increasing", unit="s",
                                       nonempty=True, what="increasing times in s")
    translations: tuple[Vec3, ...] = setting((), doc="p at each time, linear in between; "
                                             "default zeros", unit="m",
                                             what="[x, y, z] vectors (one per time)")
    rotations: tuple[Vec3, ...] = setting((), doc="R at each time as a rotation vector (axis "
                                          "times angle), slerp along the shortest arc in "
                                          "between; default zeros", unit="rad",
                                          what="[x, y, z] vectors (one per time)")


@dataclass(frozen=True)
class AnimationSpec:
    """A body mesh that moves by motion capture (docs/bodies.md): a skeleton
    fitted to the mesh, bone-heat skinning weights, the clip's joint
    rotations retargeted to that skeleton, the mesh skinned at every step
    (one vertex array, the BVH refit).  Scene time: the body holds its rest
    pose for settle seconds, blends into the clip's first pose over
    blend_in, plays the clip (its speed eased in over ease_in), then holds
    the last pose or blends back to rest over blend_out."""
    motion: str = setting(doc="a BVH motion capture file (any joint hierarchy and channel "
                          "order; its joints are mapped to the body's by the CMU database's "
                          "names), relative to the scene file", read="motion_file")
    joints: tuple[tuple[str, str], ...] = setting((), doc="body joint -> the motion file's joint "
                                                 "driving it, for files not named like the CMU "
                                                 "database's (docs/bodies.md lists the body's "
                                                 "joints and the CMU names); given joints "
                                                 "replace the CMU names", read="joint_map")
    units: float = setting(CMU_UNIT, doc="metres per length unit of the file (the CMU "
                           "database's BVH conversions: 0.0254/0.45); the clip's travel is then "
                           "scaled to the body by the ratio of hip heights", unit="m", above=0)
    skinning: str = choice("dqs", SKINNING_METHODS, doc="dqs: dual-quaternion skinning (Kavan "
                           "et al. 2008; keeps a twisted limb's volume); lbs: linear blend "
                           "skinning (a twisted wrist collapses: the candy wrapper)")
    root_motion: str = choice("keep", ROOT_MOTIONS, doc="keep: the body travels as captured; "
                              "remove: it walks in place (the root's horizontal travel taken out)")
    speed: float = setting(1.0, doc="playback speed (1: as captured)", above=0, at_most=10)
    clip_start: float = setting(0.0, doc="clip time played first (a CMU file's frame 0 is a "
                                "reference pose, not part of the motion: 0.0084 skips it)",
                                unit="s", at_least=0)
    clip_end: float | None = setting(None, doc="clip time played last; null: the clip's end",
                                     unit="s", above=0)
    settle: float = setting(0.0, doc="time the body holds its rest pose first (a garment is "
                            "sewn and settles meanwhile)", unit="s", at_least=0)
    blend_in: float = setting(0.5, doc="time over which the pose goes from rest to the clip's "
                              "first played pose", unit="s", at_least=0)
    ease_in: float = setting(0.3, doc="time over which the playback speed rises from 0 (the "
                             "body's velocity stays continuous where the clip starts)", unit="s",
                             at_least=0)
    blend_out: float = setting(0.0, doc="time over which the pose returns to rest after the clip; "
                               "0: the last pose is held", unit="s", at_least=0)
    reach: float | None = setting(None, doc="bvh method: the body parts (bones) whose skin is "
                                  "within this distance of the cloth where it starts are the only "
                                  "ones in its contact (EG07 tutorial Part 2 §2.3; a skirt never "
                                  "tests the arms); null: the whole body", unit="m", above=0)
    arm_clearance: float | None = setting(None, doc="where the capture brings an upper arm "
                                          "closer than this to the chest, the whole arm is "
                                          "turned out about the shoulder (the least angle, "
                                          "smooth in time) until it is this far: room for the "
                                          "sleeves and bodice that would otherwise be pinched "
                                          "between arm and chest (docs/bodies.md); null: the "
                                          "arms as captured", unit="m", above=0)
    leg_clearance: float | None = setting(None, doc="where the capture brings the lower legs "
                                          "(shins and feet) closer than this to each other, "
                                          "both legs are turned apart about the hips (the least "
                                          "angle, smooth in time) until they are this far: "
                                          "room for trouser legs that would otherwise be "
                                          "pinched between the ankles (docs/bodies.md); null: "
                                          "the legs as captured", unit="m", above=0)


@dataclass(frozen=True)
class ColliderGeometry:
    """The geometry keys of the shapes, written in the collider's own mapping;
    each shape takes exactly its own (SHAPE_KEYS, and a mesh its optional center)."""
    normal: Vec3 | None = setting(None, doc="plane: normal (normalised on use); normal · y < "
                                  "offset is inside", nonzero=True, what="[x, y, z], non-zero")
    offset: float | None = setting(None, doc="plane: normal · y = offset on the plane",
                                   unit="m", what="a number in m (normal . y = offset)")
    center: Vec3 | None = setting(None, doc="sphere, box: centre; mesh (optional): where the "
                                  "bounding-box centre of the placed mesh (its first frame) "
                                  "goes, as for cloth pieces", unit="m", what="[x, y, z] in m")
    radius: float | None = setting(None, doc="sphere, capsule: radius", unit="m", above=0,
                                   what="a number > 0 in m")
    a: Vec3 | None = setting(None, doc="capsule: one end of the segment", unit="m",
                             what="[x, y, z] in m")
    b: Vec3 | None = setting(None, doc="capsule: the other end", unit="m", what="[x, y, z] in m")
    half_extents: Vec3 | None = setting(None, doc="box: half sizes along x, y, z (axis-aligned "
                                        "in the body frame)", unit="m", above=0,
                                        what="[x, y, z], each > 0, in m")


@dataclass(frozen=True)
class ColliderSpec:
    """A rigid or deforming body the cloth collides with (collisions effect):
    checked even without the effect, used only with it. Contact when the
    distance phi < d = the cloth's thickness + the collider's. A mesh is placed
    like a cloth piece, one transform for every frame, in this order: turned
    z-up (up_axis), scaled, rotated about its bounding-box centre (of its first
    frame), then moved by center or translation; motion moves the placed mesh."""
    name: str = setting(doc="unique among the colliders", auto="collider{index}")
    shape: str = choice(MISSING, COLLIDER_SHAPES, doc="the body: each shape takes the geometry "
                        "keys that name it below (all required but a mesh's center) and no "
                        "others; mesh also takes the keys marked 'only with shape: mesh'")
    geometry: tuple[tuple[str, Any], ...] = setting(doc="the shape's keys and values",
                                                    inline=ColliderGeometry)
    friction: float = setting(0.0, doc="Coulomb coefficient mu (0: frictionless)", at_least=0)
    thickness: float = setting(0.0, doc="added to the cloth's thickness for the contact "
                               "distance d", unit="m", at_least=0)
    files: tuple[str, ...] = setting((), key="file", doc="mesh: an OBJ or PLY triangle mesh "
                                     "(relative to the scene file), or a list of them: a "
                                     "deforming sequence with the same triangles, one file per "
                                     "frame; a closed mesh has an inside, an open one is "
                                     "two-sided", read="mesh_files", only=MESH_ONLY,
                                     what="an OBJ or PLY file, or a list of them (one per "
                                     "frame)")
    frame_rate: float | None = setting(None, doc="mesh: frames per second of a sequence "
                                       "(needed with a list of files, refused with one)", unit="1/s", above=0,
                                       only=MESH_ONLY)
    scale: float = setting(1.0, doc="mesh: scale factor", above=0, only=MESH_ONLY)
    up_axis: str = choice("z", UP_AXES, doc="mesh: the file's up axis; y (a y-up file, e.g. a "
                          "scanned body): first turned +90 degrees about x, (x, y, z) -> (x, -z, "
                          "y), so that its +y becomes +z", only=MESH_ONLY)
    rotation: Vec3 = setting((0.0, 0.0, 0.0), doc="mesh: rotation about x, then y, then z, "
                             "about the bounding-box centre, after up_axis and scale",
                             unit="degrees", only=MESH_ONLY)
    translation: Vec3 | None = setting(None, doc="mesh: added to every vertex after scale and "
                                       "rotation; exclusive with center; null: none", unit="m",
                                       what="[x, y, z] in m", only=MESH_ONLY)
    method: str = choice("bvh", COLLIDER_METHODS, doc="mesh: bvh (BVH closest points for "
                         "contact constraints, vertex-face and edge-edge CCD impulses) or image "
                         "(depth, normal and velocity maps, Vassilev et al. 2001 §4, Eq. 15 "
                         "response)", only=MESH_ONLY)
    resolution: tuple[int, int] = setting((256, 256), doc="image-space map size", unit="pixels",
                                          at_least=8, at_most=8192, only=IMAGE_ONLY)
    axis: str = choice("z", IMAGE_AXES, doc="image-space projection axis", only=IMAGE_ONLY)
    motion: MotionSpec | None = setting(None, doc="rigid keyframes; null: at rest")
    animation: AnimationSpec | None = setting(None, doc="mesh: skinned by motion capture (one "
                                              "file, not a sequence); null: not animated",
                                              only=MESH_ONLY)


@dataclass(frozen=True)
class SewingSpec:
    """The sewing phase of pattern pieces (docs/garments.md): a spring joins
    every stitched pair of vertices, its rest length going from the pair's start
    gap to zero over the duration; when every pair is within the tolerance the
    stitches are welded and the run goes on with one connected garment."""
    duration: float = setting(0.5, doc="time over which the stitch springs' rest lengths go "
                              "to zero (layer k's from k times this on)", unit="s", above=0)
    stiffness: float = setting(2000.0, doc="stiffness of each stitch spring (a closed seam's gap is its load over this)", unit="N/m", above=0)
    tolerance: float = setting(1.0e-3, doc="weld when every stitched pair is this close",
                               unit="m", above=0)
    gravity: float = setting(0.0, doc="fraction of gravity acting while the garment is sewn "
                             "(an open garment would fall off the body before its seams close; "
                             "its weight comes on at the weld)", at_least=0, at_most=1)
    friction: float = setting(0.0, doc="fraction of the colliders' friction while the garment is "
                              "sewn (panels slide around the body into place instead of being "
                              "held where they first touch it; full friction from the weld)",
                              at_least=0, at_most=1)
    max_duration: float = setting(3.0, doc="the run stops with an error naming the widest "
                                  "stitch if the seams have not closed by then; >= duration",
                                  unit="s", above=0)


@dataclass(frozen=True)
class SeamSpec:
    """What a sewn seam adds to the fabric along it (EG07 tutorial, Part 2 §1:
    seams are stiffer than the fabric, and a seam sewn shorter than the fabric
    it joins puckers it)."""
    stretch: float = setting(1.0, doc="seam strip modulus as a multiple of the fabric's "
                             "(springs along the welded seam edges; 0: none)", at_least=0)
    width: float = setting(0.01, doc="width of the seam strip (seam allowance)", unit="m",
                           above=0)
    bending: float = setting(2.0, doc="bending stiffness of the hinges across a seam as a "
                             "multiple of the fabric's", above=0)
    shrinkage: float = setting(0.0, doc="the seam line's rest length shortened by this "
                               "fraction (the tutorial's pucker: up to 0.05)", at_least=0,
                               at_most=0.2)


@dataclass(frozen=True)
class FusedSpec:
    """An interlining fused to a panel (or a box of it): the region's triangles
    and vertices take the combined material, the fabric's plus the
    interlining's (layers glued together act in parallel)."""
    piece: str = setting(doc="the cloth piece (its name) whose pattern has the panel")
    panel: str = setting(doc="the panel's name in the pattern")
    box_min: tuple[float, float] | None = setting(None, key="box.min", doc="the region's low "
                                                  "corner in the panel's 2D frame; null: the "
                                                  "whole panel", unit="m",
                                                  what="[x, y] in m")
    box_max: tuple[float, float] | None = setting(None, key="box.max", doc="the region's high "
                                                  "corner", unit="m", what="[x, y] in m")
    stretch: float = setting(0.0, doc="the interlining's membrane modulus, added along the weft; the "
                             "region's whole law is scaled by 1 + stretch / E_weft, so an "
                             "orthotropic fabric keeps its ratios", unit="N/m",
                             at_least=0)
    bending: float = setting(0.0, doc="the interlining's bending stiffness, added (a factor on the "
                             "fabric's: the fabric needs bending > 0)", unit="N·m",
                             at_least=0)
    density: float = setting(0.0, doc="the interlining's areal density, added", unit="kg/m²",
                             at_least=0)


@dataclass(frozen=True)
class GarmentSpec:
    """Pattern pieces: sewing, seams, fused interlinings and layers
    (docs/garments.md)."""
    sewing: SewingSpec = section(SewingSpec, doc="the sewing phase")
    seams: SeamSpec = section(SeamSpec, doc="the seams of the welded garment")
    fused: tuple[FusedSpec, ...] = setting((), doc="interlinings fused to panels",
                                           what="fused regions")
    clearance: float = setting(0.01, doc="pre-positioning: a panel that starts inside a body "
                               "mesh collider or closer to it than this is moved out along its "
                               "outside normal until it is this far (0: the pattern's placement "
                               "as it is)", unit="m", at_least=0)
    layer_gap: float = setting(0.01, doc="a piece of layer k starts k times this further out, "
                               "each panel moved along its outside normal", unit="m",
                               at_least=0)
    start_check: bool = setting(True, doc="refuse to start when a garment intersects a body "
                                "mesh collider or itself (the offending elements are named)")


@dataclass(frozen=True)
class TimeSpec:
    """Time stepping: span, integrator, Newton iterations and step health (a
    rejected step is retried at h/2 with adaptive, else the run stops)."""
    end: float = setting(1.0, doc="simulated time", unit="s", above=0)
    step: float = setting(0.01, doc="time step h, <= end", unit="s", above=0)
    integrator: str = choice("backward_euler", INTEGRATORS, doc="implicit: backward_euler, bdf2, "
                             "implicit_midpoint, newmark; explicit: symplectic_euler, "
                             "explicit_midpoint, rk4")
    newton_iterations: int | None = setting(None, doc="Newton iterations per step at most; 1 is "
                                            "one linear solve, linearised at the scheme's "
                                            "predictor; null: "
                                            "1, but 30 for implicit_midpoint and newmark with "
                                            "energy_momentum (their energy is conserved by the "
                                            "converged step)", at_least=1,
                                            at_most=MAX_NEWTON_ITERATIONS)
    newton_tolerance: float = setting(1.0e-8, doc="relative residual force norm that stops "
                                      "Newton early", above=0)
    newmark_beta: float = setting(0.25, doc="Newmark's beta (1/4: average acceleration)",
                                  at_least=0, at_most=0.5)
    newmark_gamma: float = setting(0.5, doc="Newmark's gamma (1/2: second order, no numerical "
                                   "damping)", above=0, at_most=1)
    energy_momentum: bool = setting(True, doc="implicit_midpoint, and newmark with beta 1/4 and "
                                    "gamma 1/2: the Newton residual takes the conservative forces "
                                    "as discrete gradients between the step's end positions "
                                    "(Simo and Tarnow 1992, Gonzalez 1996), so a converged step "
                                    "keeps the energy of membrane, springs, gravity and isometric "
                                    "bending; false: forces at the midpoint (Newmark: the "
                                    "trapezoidal average), which gains energy on stiff nonlinear "
                                    "membranes. Needs Newton iterated (newton_iterations null or "
                                    ">= 2; docs/integrators.md)")
    adaptive: bool | None = setting(None, doc="retry a rejected step (failed solve, NaN, "
                                    "blow-up, strain bound, energy gain, unconverged Newton "
                                    "where convergence is required) as two steps of h/2; null: "
                                    "true for the energy-momentum schemes (their energy is "
                                    "only conserved by a converged step, and Newton converges "
                                    "on shorter steps), false otherwise")
    max_halvings: int = setting(6, doc="how many times adaptive may halve a step", at_least=1,
                                at_most=30)
    max_strain: float | None = setting(None, doc="reject a step whose largest membrane strain "
                                       "(stretch - 1 of a structural spring, principal stretch "
                                       "- 1 of an FE triangle) exceeds this; null: no bound",
                                       above=0)
    energy_guard: bool = setting(True, doc="reject a step that leaves a passive scene with "
                                 "more than E_ref + max_energy_gain * S of energy (Step health); "
                                 "false: such a step is accepted and the run ends "
                                 "completed_with_warnings")
    max_energy_gain: float = setting(0.1, doc="the guard's margin, a fraction of S = KE + "
                                     "|U_elastic| + M |g| L at the reference", above=0)
    energy_retry_newton: int = setting(10, doc="a step the energy guard rejects, or a "
                                       "backward Euler step (BDF-2's first) of a passive scene "
                                       "that ends above its start's energy, is solved again "
                                       "with at most this many Newton iterations, each "
                                       "backtracking on the residual, before it is "
                                       "halved or the run stops (a linearised large step on a "
                                       "stiff membrane can gain energy; docs/integrators.md); "
                                       "1: no retry", at_least=1,
                                       at_most=MAX_NEWTON_ITERATIONS)
    energy_retry_until: str = choice("no_gain", RETRY_STOPS, doc="when the energy retry's "
                                     "Newton stops before energy_retry_newton iterations: "
                                     "no_gain, once an iterate passes the energy guard and ends "
                                     "no higher than the last step's energy (a step still "
                                     "rejected is solved again to the limit); converged, only "
                                     "at newton_tolerance")
    require_newton_convergence: bool | None = setting(None, doc="true: a step whose Newton "
                                                      "loop ends above newton_tolerance is "
                                                      "rejected; false: accepted, counted in "
                                                      "newton_unconverged; null: true for the "
                                                      "energy-momentum schemes, false otherwise")
    linearise_at: str | None = choice(None, LINEARISATION_POINTS, doc="where a step's first "
                                      "Newton iteration is linearised: predictor (x0 + h v0 "
                                      "for backward Euler; keeps BDF-2 second order on a stiff "
                                      "membrane) or start (x0, Baraff and Witkin 1998: robust "
                                      "where contacts stop the cloth, whose predictor lies "
                                      "inside the body and its folds); null: start with the "
                                      "collisions or self_collision effect, else predictor "
                                      "(docs/integrators.md). Newmark other than the "
                                      "energy-momentum one always starts at x0")

    @property
    def energy_momentum_scheme(self) -> bool:
        """implicit_midpoint, or newmark with beta 1/4 and gamma 1/2, with
        energy_momentum: the schemes whose converged step conserves energy."""
        if not self.energy_momentum:
            return False
        return self.integrator == "implicit_midpoint" or (
            self.integrator == "newmark" and self.newmark_beta == 0.25 and self.newmark_gamma == 0.5)


@dataclass(frozen=True)
class LinearSystemSpec:
    """distcloth's own settings of the implicit solve (the PETSc options are under
    solver:). On the command line: -distcloth_<key> <value>, e.g.
    -distcloth_mat_type aij."""
    mat_type: str | None = choice(None, MAT_TYPES, doc="PETSc matrix type, block size 3 either "
                                  "way (PETSc's GAMG needs aij); null: the size preset's without "
                                  "a solver: section, else baij")
    warm_start: bool | None = setting(None, doc="start each solve from the previous step's "
                                      "solution (a Newton correction from zero); null: on without "
                                      "a solver: section, off with one")
    pc_rebuild_every: int = setting(1, doc="rebuild the preconditioner every k-th solve, reuse "
                                    "it in between", at_least=1)
    step_error_fraction: float | None = setting(
        None, doc="one-solve steps of backward Euler and BDF-2: the solve stops where the "
        "error it can leave in the positions is at most this fraction of the last step's "
        "estimated local error (on the unpreconditioned residual, between 1e-6 and 1e-2 of "
        "|b|; the first step and a step after a change of size use ksp_rtol); null: every "
        "solve at ksp_rtol (docs/integrators.md, \"A solve as accurate as the step\")", above=0)


@dataclass(frozen=True)
class DrapeSpec:
    """`distcloth drape`: relaxation to the rest state (Volino and
    Magnenat-Thalmann 2007; docs/drape.md)."""
    method: str = choice("stop_and_go", DRAPE_METHODS, doc="stop_and_go: dynamics with every "
                         "velocity zeroed at an energy extremum; dynamic, quasistatic, newton: "
                         "see docs/drape.md")
    stop_on: str = choice("potential", DRAPE_STOP_ON, doc="stop_and_go: zero the velocities at "
                          "a potential-energy minimum, at a kinetic-energy maximum, or (both) "
                          "where the potential rises while the kinetic energy falls (contact "
                          "that pushes cloth out of a body raises the potential mid-swing)")
    tolerance: float = setting(1.0e-3, doc="done when every vertex's unbalanced force (what no "
                               "pin holds, no body supports and static friction does not "
                               "carry) is at most this times its weight", above=0)
    criterion: str = choice("force", DRAPE_CRITERIA, doc="force: done when the residual is "
                            "below tolerance; motion: done when no vertex moved more than "
                            "motion_tolerance over the last window iterations (Volino and "
                            "Magnenat-Thalmann 2007 §3: a garment's 'visible stability'; a "
                            "coarse garment in contact keeps forces its contacts hold)")
    motion_tolerance: float = setting(5.0e-4, doc="criterion motion: the largest displacement "
                                      "of any vertex over a window", unit="m", above=0)
    window: int = setting(20, doc="criterion motion: iterations over which the displacement is "
                          "measured; any criterion: iterations an unpinned cloth that has "
                          "touched a collider may touch none before the drape stops with no "
                          "rest state (docs/drape.md)", at_least=1)
    max_iterations: int = setting(2000, doc="iterations before giving up", at_least=1)
    frame_every: int = setting(10, doc="iterations between frames", at_least=1)


@dataclass(frozen=True)
class ContactSpec:
    """How body contact enters an implicit step (collisions effect;
    docs/collisions.md, "Contact as a barrier")."""
    model: str = choice("constraints", CONTACT_MODELS, doc="constraints: vertices predicted to "
                        "reach a body become Baraff-Witkin constraints, revised over up to four "
                        "solves, with a position fail-safe after the step; barrier: a barrier "
                        "energy of the gap to each body and a lagged friction dissipation in a "
                        "Newton solve with a line search that never lets a vertex reach its "
                        "contact distance (incremental potential contact, Li et al. 2020); "
                        "needs backward_euler or bdf2 and colliders that are not image maps")
    barrier_width: float | None = setting(None, doc="barrier: the gap above the contact "
                                          "distance d over which the barrier acts; null: half "
                                          "the largest d", unit="m", above=0)
    barrier_stiffness: float = setting(10.0, doc="barrier: the force it exerts at half its "
                                       "width, in weights of the vertex", above=0)
    static_speed: float = setting(1.0e-3, doc="barrier: the slip speed below which friction "
                                  "holds a vertex as stuck (IPC's smoothing eps_v)", unit="m/s",
                                  above=0)
    newton_iterations: int = setting(50, doc="barrier: Newton iterations per step at most",
                                     at_least=1, at_most=MAX_NEWTON_ITERATIONS)
    velocity_tolerance: float = setting(0.1, doc="barrier: Newton stops when its update "
                                        "changes no velocity by more than this (0.1: on the "
                                        "tablecloth landing on a sphere at 20 ms, 4 times "
                                        "faster than 0.01 for 6 % more error; 0.3 gave 70 % "
                                        "more; docs/collisions.md)", unit="m/s", above=0)


@dataclass(frozen=True)
class StrainLimitSpec:
    """The strain_limiting effect (docs/strain_limiting.md): after each step
    every structural and shear spring is brought back within its bound, the
    largest engineering strain l / l0 - 1 it may have; pinned and contact
    vertices never move."""
    method: str = choice("provot", LIMIT_METHODS, doc="provot: position correction of "
                         "over-stretched springs (Provot 1995); velocity: the velocity "
                         "directional modification of Vassilev et al. 2001 §3")
    rule: str = choice("average", VELOCITY_RULES, doc="velocity: average (Eq. 5 for every "
                       "spring, the paper's rule for static bodies) or directional (Eq. 5 only "
                       "for springs across the directional vector g dt + v_object, the rear end "
                       "catching up with the front otherwise, the paper's rule for moving "
                       "bodies; it cannot hold cloth hanging from pins: docs/strain_limiting.md)",
                       only=VELOCITY_ONLY)
    weft: float = setting(0.1, doc="bound of the springs along the weft (within 22.5 degrees "
                          "of the piece's material.weft)", above=0)
    warp: float = setting(0.1, doc="bound of the springs across it", above=0)
    shear: float = setting(0.1, doc="bound of the shear (diagonal) springs", above=0)
    passes: int = setting(200, doc="most Jacobi passes per step (each one neighbour exchange "
                          "and one global reduction)", at_least=1)
    tolerance: float = setting(1.0e-3, doc="strain above the bound at which the passes stop "
                               "(a warning when the last pass leaves more)", above=0)
    over_relaxation: float = setting(
        1.8, doc="factor on each pass's averaged correction (1: plain Jacobi); when the "
        "over-relaxed passes do not reach the bound the step's limiting starts again "
        "without it (docs/strain_limiting.md); the directional rule always takes 1",
        at_least=1, at_most=1.95)


@dataclass(frozen=True)
class StealSpec:
    """Load balance of the collision BVH traversal (EG07 tutorial, Part 1
    §5.8.2; distcloth/parallel/steal.py), used only when a mesh collider (bvh)
    or self_collision builds one; docs/benchmarks.md: what works here."""
    enabled: bool = setting(True, doc="false: the static assignment of the top-level tasks")
    a: float = setting(2.0, doc="a new task when the stack holds more than tau = a * pool "
                       "size + b tests", at_least=0)
    b: float = setting(8.0, doc="the constant of tau", at_least=1)
    chunk: int = setting(256, doc="traversal tests between two polls for steal requests",
                         at_least=1)


@dataclass(frozen=True)
class CheckpointSpec:
    """When a run writes its checkpoint (`<output stem>.checkpoint.h5`, read by
    `distcloth run --resume`); a run also writes one when it ends or is
    interrupted (SIGTERM, SIGINT)."""
    every_steps: int | None = setting(None, doc="write one every this many steps; null: not "
                                      "by steps", at_least=1)
    every_seconds: float | None = setting(600.0, doc="write one when this much wall time has "
                                          "passed since the last; null: not by time", unit="s",
                                          above=0)


@dataclass(frozen=True)
class OutputSpec:
    """The result file and its frames."""
    file: str = setting("out/result.h5", doc="HDF5 result, relative to the current directory; "
                        "its directory is created", read="output_file")
    every: float = setting(0.1, doc="time between frames, >= time.step (rounded to a whole "
                           "number of steps)", unit="s", above=0)
    preview: bool = setting(True, doc="PNG pictures and plots beside the HDF5 file")
    reactions: bool | None = setting(None, doc="record each pin group's reaction force every "
                                     "step (one more force evaluation per step); null: when "
                                     "a pin moves or a load acts")
    checkpoint: CheckpointSpec = section(CheckpointSpec, doc="checkpoints for restarting "
                                         "an interrupted run")


@dataclass(frozen=True)
class SceneConfig:
    """A scene: cloth pieces, the effects acting on them, time stepping, the
    linear solve, output and colliders."""
    scene: str = setting(doc="free-text name", auto="{stem}")
    cloth: tuple[ClothSpec, ...] = setting(doc="the pieces (a single mapping is a one-piece "
                                           "list)", nonempty=True, what="cloth pieces")
    effects: tuple[str, ...] = choice(("gravity", "membrane", "bending"), EFFECTS,
                                      doc="the forces and stages: collisions needs at least "
                                      "one collider; self_collision uses each piece's "
                                      "thickness; loads needs at least one cloth.<i>.loads "
                                      "entry", what="effect names")
    gravity: Vec3 = setting((0.0, 0.0, -9.81), doc="gravitational acceleration (z is up)",
                            unit="m/s²")
    drag: float = setting(0.0, doc="air drag: f = -drag * area * v per vertex", unit="N·s/m³",
                          at_least=0)
    time: TimeSpec = section(TimeSpec, doc="time stepping")
    solver: tuple[tuple[str, Any], ...] = setting(
        (), doc="PETSc options without the leading '-' and without "
        f"the prefix {OPTION_PREFIX}, which distcloth adds (ksp_rtol: 1e-8 is "
        f"-{OPTION_PREFIX}ksp_rtol 1e-8); they replace or extend the defaults "
        f"{dict(DEFAULT_SOLVER)}; no solver: section: CG with a preconditioner chosen by "
        "problem size, ksp_rtol 1e-3 (1e-5 with collisions) of the unpreconditioned "
        "residual (CG's preconditioned one with collisions) and warm start "
        "(distcloth/linalg/presets.py)",
        read="petsc_options")
    linear_system: LinearSystemSpec = section(LinearSystemSpec, doc="distcloth's own settings "
                                              "of the linear solve")
    output: OutputSpec = section(OutputSpec, doc="the result file")
    drape: DrapeSpec = section(DrapeSpec, doc="relaxation by distcloth drape")
    contact: ContactSpec = section(ContactSpec, doc="how body contact enters an implicit "
                                   "step")
    colliders: tuple[ColliderSpec, ...] = setting((), doc="bodies the cloth collides with",
                                                  what="colliders, each a mapping with name "
                                                  "and shape")
    work_stealing: StealSpec = section(StealSpec, doc="load balance of the collision traversal")
    strain_limiting: StrainLimitSpec = section(StrainLimitSpec, doc="the strain_limiting "
                                               "effect's bounds and method")
    garment: GarmentSpec = section(GarmentSpec, doc="sewing, seams, fused regions and layers "
                                   "of pattern pieces")
    source_text: str = setting("", doc="the resolved configuration as YAML, for the output "
                               "file", internal=True)

    def has(self, effect: str) -> bool:
        return effect in self.effects

    @property
    def solver_options(self) -> dict[str, Any]:
        return dict(self.solver)
