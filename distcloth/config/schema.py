"""Typed scene configuration: frozen dataclasses with defaults, SI units.

The YAML layout and every allowed value are documented in docs/config.md;
:mod:`distcloth.config.load` turns YAML (plus ``--set`` overrides) into these
objects and refuses anything else with a :class:`ConfigError`.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

EFFECTS = ("gravity", "membrane", "bending", "damping", "drag", "collisions", "self_collision")
COLLIDER_SHAPES = ("plane", "sphere", "capsule", "box", "mesh")
COLLIDER_METHODS = ("bvh", "image")   # mesh colliders: BVH closest points or image-space maps
IMAGE_AXES = ("x", "y", "z")
# the geometry keys of each collider shape (all required)
SHAPE_KEYS = {"plane": ("normal", "offset"), "sphere": ("center", "radius"),
              "capsule": ("a", "b", "radius"), "box": ("center", "half_extents"),
              "mesh": ("file",)}
INTEGRATORS = ("backward_euler", "bdf2", "implicit_midpoint", "newmark",
               "symplectic_euler", "explicit_midpoint", "rk4")
GRID_PATTERNS = ("regular", "alternating")
GRID_EDGES = ("left", "right", "bottom", "top")
GRID_CORNERS = ("bottom_left", "bottom_right", "top_left", "top_right")
MATERIAL_MODELS = ("mass_spring", "fem")
STRAIN_MODELS = ("stvk", "corotated")
BENDING_MODELS = ("flexion", "dihedral", "isometric", "dihedral_shell", "isometric_shell")
MAT_TYPES = ("baij", "aij")
DRAPE_METHODS = ("stop_and_go", "dynamic", "quasistatic", "newton")
DRAPE_STOP_ON = ("potential", "kinetic")

# PETSc options a scene gets unless it says otherwise (seed 000 §5.6: CG with
# block Jacobi over the ranks, SSOR on each block; BAIJ SOR allows only
# omega = 1, i.e. symmetric Gauss-Seidel).
DEFAULT_SOLVER: dict[str, Any] = {
    "ksp_type": "cg",
    "pc_type": "bjacobi",
    "sub_pc_type": "sor",
    "ksp_rtol": 1.0e-5,
}


class ConfigError(Exception):
    """A bad configuration value: key path, the value, and what is allowed."""

    def __init__(self, key: str, value: Any, allowed: str):
        self.key, self.value, self.allowed = key, value, allowed
        super().__init__(f"{key}: {value!r} — {allowed}")


@dataclass(frozen=True)
class GridSpec:
    size: tuple[float, float]
    resolution: tuple[int, int]
    pattern: str = "alternating"


@dataclass(frozen=True)
class MeshSpec:
    grid: GridSpec | None = None
    file: str | None = None           # absolute path after loading (relative: to the scene file)
    scale: float = 1.0
    center: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rotation: tuple[float, float, float] = (0.0, 0.0, 0.0)   # degrees about x, y, z


@dataclass(frozen=True)
class PinSpec:
    edge: str | None = None
    corner: str | None = None
    indices: tuple[int, ...] | None = None
    box_min: tuple[float, float, float] | None = None
    box_max: tuple[float, float, float] | None = None
    axis: tuple[float, float, float] | None = None   # hold only along this direction (sliding pin)


@dataclass(frozen=True)
class MaterialSpec:
    model: str = "mass_spring"
    density: float = 0.1          # kg/m^2
    stretch: float = 10.0         # N/m
    shear: float | None = None    # N/m, None: stretch / 10
    bending: float = 1.0e-6       # N*m
    damping: float = 0.0          # s
    # model: fem (seed 000 §3.5-3.6): orthotropic plane stress, moduli times thickness in N/m;
    # None: E_weft = stretch, E_warp = E_weft, nu_weft = 0.3, nu_warp = nu_weft E_warp / E_weft,
    # G = E_weft / (2 (1 + nu_weft))
    E_weft: float | None = None
    E_warp: float | None = None
    nu_weft: float | None = None
    nu_warp: float | None = None
    G: float | None = None
    strain: str = "stvk"
    weft: tuple[float, float, float] = (1.0, 0.0, 0.0)   # weft direction in the placed rest shape
    bending_model: str | None = None   # None: flexion for mass_spring, dihedral for fem
    preset: str | None = None     # a named fabric (config/fabrics.py) the other values override
    # fem + stvk: weft / warp direct stress (N/m) against Green strain, as [[e, S], ...]
    # from [0, 0], e increasing (seed 000 Part 2 §1.3: measured curves, stiffening)
    tension_weft: tuple[tuple[float, float], ...] | None = None
    tension_warp: tuple[tuple[float, float], ...] | None = None
    shear_curve: tuple[tuple[float, float], ...] | None = None   # shear stress vs shear strain 2E_uv

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
        # dihedral, not dihedral_shell: the shell model is the accurate one (within
        # 1 % of the elastica on every mesh family, per-hinge sums +6..17 %) but a
        # step costs 8x at 100k vertices (docs/benchmarks.md); the user chooses
        return "flexion" if self.model == "mass_spring" else "dihedral"

    @property
    def shear_stiffness(self) -> float:
        return self.stretch / 10.0 if self.shear is None else self.shear


@dataclass(frozen=True)
class ClothSpec:
    name: str
    mesh: MeshSpec
    pins: tuple[PinSpec, ...] = ()
    material: MaterialSpec = field(default_factory=MaterialSpec)
    thickness: float = 0.001      # m: contact offset of the cloth against colliders


@dataclass(frozen=True)
class MotionSpec:
    """Rigid keyframes of a collider (colliders.RigidMotion): times in s,
    translations in m, rotations as rotation vectors in rad."""
    times: tuple[float, ...] = ()
    translations: tuple[tuple[float, float, float], ...] = ()
    rotations: tuple[tuple[float, float, float], ...] = ()


@dataclass(frozen=True)
class ColliderSpec:
    name: str
    shape: str
    geometry: tuple[tuple[str, Any], ...]    # the shape's keys (SHAPE_KEYS) and values
    friction: float = 0.0
    thickness: float = 0.0
    motion: MotionSpec | None = None
    # mesh colliders only: a deforming sequence is one file per frame at frame_rate
    files: tuple[str, ...] = ()
    frame_rate: float | None = None
    scale: float = 1.0
    method: str = "bvh"
    resolution: tuple[int, int] = (256, 256)   # image-space map size (pixels)
    axis: str = "z"                            # image-space projection axis


@dataclass(frozen=True)
class TimeSpec:
    end: float = 1.0
    step: float = 0.01
    integrator: str = "backward_euler"
    newton_iterations: int = 1
    newton_tolerance: float = 1.0e-8
    newmark_beta: float = 0.25    # Newmark's beta and gamma (average acceleration by default)
    newmark_gamma: float = 0.5
    adaptive: bool = False        # halve h and retry a rejected step
    max_halvings: int = 6
    max_strain: float | None = None   # reject a step whose largest membrane strain (stretch - 1) exceeds it
    energy_guard: bool = True         # reject a step that gains energy in a passive scene (energy_guard.py)
    max_energy_gain: float = 0.1      # ... beyond E_ref + this * S
    require_newton_convergence: bool = False   # reject a step whose Newton loop ran out of iterations


@dataclass(frozen=True)
class DrapeSpec:
    """``distcloth drape`` (seed 004): relaxation to the rest state."""
    method: str = "stop_and_go"
    stop_on: str = "potential"    # zero all velocities at a potential-energy minimum, or a kinetic maximum
    tolerance: float = 1.0e-3     # stop when every free vertex's force <= tolerance * its weight
    max_iterations: int = 2000
    frame_every: int = 10         # iterations between frames


@dataclass(frozen=True)
class StealSpec:
    """Load balancing of the collision traversal (seed 000 Part 1 §5.8.2;
    distcloth/parallel/steal.py).  Off: the static top-level assignment."""
    enabled: bool = True
    a: float = 2.0               # task creation threshold tau = a * sigma + b (sigma: pool size)
    b: float = 8.0
    chunk: int = 256             # traversal tests between two polls for steal requests


@dataclass(frozen=True)
class OutputSpec:
    file: str = "out/result.h5"
    every: float = 0.1
    preview: bool = True


@dataclass(frozen=True)
class SceneConfig:
    scene: str
    cloth: tuple[ClothSpec, ...]
    effects: tuple[str, ...] = ("gravity", "membrane", "bending")
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)
    drag: float = 0.0
    time: TimeSpec = field(default_factory=TimeSpec)
    solver: tuple[tuple[str, Any], ...] = tuple(DEFAULT_SOLVER.items())   # PETSc options (no prefix)
    mat_type: str = "baij"
    warm_start: bool = False       # start each solve from the previous step's solution
    pc_rebuild_every: int = 1      # rebuild the preconditioner every k-th solve, reuse it between
    output: OutputSpec = field(default_factory=OutputSpec)
    drape: DrapeSpec = field(default_factory=DrapeSpec)
    work_stealing: StealSpec = field(default_factory=StealSpec)
    colliders: tuple[ColliderSpec, ...] = ()
    source_text: str = ""          # the resolved config as YAML, for the output file

    def has(self, effect: str) -> bool:
        return effect in self.effects

    @property
    def solver_options(self) -> dict[str, Any]:
        return dict(self.solver)
