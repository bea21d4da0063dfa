"""YAML scene file (plus ``--set`` overrides) -> checked :class:`SceneConfig`.

Every value is checked here, before any work starts, so that a bad scene
stops the run with one line naming the key path (docs/config.md).  A null
value means "not given": the default is used, as ``shear: null`` documents;
keys without a default (cloth, mesh, grid size and resolution) must be given.
Whether PETSc knows a solver option is checked later, by the solver code.
"""
from __future__ import annotations

import copy
import dataclasses
import os
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from .fabrics import FABRICS
from .checks import (exactly_one_of, format_value, join, read_bool, read_choice, read_float,
                     read_int, read_list, read_mapping, read_section, read_str, read_vector)
from .schema import (DEFAULT_SOLVER, DRAPE_METHODS, DRAPE_STOP_ON, EFFECTS, GRID_CORNERS,
                     GRID_EDGES, GRID_PATTERNS, INTEGRATORS, MAT_TYPES, MATERIAL_MODELS,
                     COLLIDER_SHAPES, COLLIDER_METHODS, IMAGE_AXES, SHAPE_KEYS, ClothSpec, ColliderSpec, ConfigError,
                     MotionSpec, DrapeSpec, StealSpec, GridSpec, MaterialSpec, MeshSpec,
                     OutputSpec, PinSpec, SceneConfig, TimeSpec, BENDING_MODELS,
                     STRAIN_MODELS)

# --- the key tree: every key a scene may hold --------------------------------
# A dict lists the keys of a mapping, a one-element list is a list of such
# mappings, LEAF is a value checked by its reader, ANY_KEY is the solver
# section (free PETSc option names).  Used both to refuse unknown keys and to
# check the paths of --set overrides.
LEAF = None
ANY_KEY = "any key"


def _leaves(*names: str) -> dict:
    return dict.fromkeys(names, LEAF)


GRID_KEYS = _leaves("size", "resolution", "pattern")
MESH_KEYS = {"grid": GRID_KEYS, **_leaves("file", "scale", "center", "rotation")}
BOX_KEYS = _leaves("min", "max")
PIN_KEYS = {**_leaves("edge", "corner", "indices"), "box": BOX_KEYS, **_leaves("axis")}
PIN_SELECTORS = ("edge", "corner", "indices", "box")
MATERIAL_KEYS = _leaves("model", "density", "stretch", "shear", "bending", "damping",
                        "E_weft", "E_warp", "nu_weft", "nu_warp", "G", "strain", "weft",
                        "bending_model", "preset", "tension_weft", "tension_warp",
                        "shear_curve")
CLOTH_KEYS = {"name": LEAF, "mesh": MESH_KEYS, "pins": [PIN_KEYS], "material": MATERIAL_KEYS,
              "thickness": LEAF}
MOTION_KEYS = _leaves("times", "translations", "rotations")
COLLIDER_KEYS = {**_leaves("name", "shape", "normal", "offset", "center", "radius", "a", "b",
                           "half_extents", "friction", "thickness", "file", "frame_rate",
                           "scale", "method", "resolution", "axis"), "motion": MOTION_KEYS}
MESH_COLLIDER_KEYS = ("file", "frame_rate", "scale", "method", "resolution", "axis")
TIME_KEYS = _leaves("end", "step", "integrator", "newton_iterations", "newton_tolerance",
                    "newmark_beta", "newmark_gamma", "adaptive", "max_halvings", "max_strain",
                    "energy_guard", "max_energy_gain", "require_newton_convergence")
OUTPUT_KEYS = _leaves("file", "every", "preview")
DRAPE_KEYS = _leaves("method", "stop_on", "tolerance", "max_iterations", "frame_every")
STEAL_KEYS = _leaves("enabled", "a", "b", "chunk")
SCENE_KEYS = {"scene": LEAF, "cloth": [CLOTH_KEYS], **_leaves("effects", "gravity", "drag"),
              "time": TIME_KEYS, "solver": ANY_KEY, "output": OUTPUT_KEYS, "drape": DRAPE_KEYS,
              "colliders": [COLLIDER_KEYS], "work_stealing": STEAL_KEYS}

MESH_SUFFIXES = (".obj", ".ply")
OUTPUT_SUFFIXES = (".h5", ".hdf5")
SOLVER_PREFIX = "distcloth_"
OPTION_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")  # PETSc names may hold capitals (pc_hypre_boomeramg_P_max)
# PyYAML (YAML 1.1) wants a dot in a float: '1e-8' comes back as a string
YAML11_MISSED_FLOAT = re.compile(r"^[-+]?[0-9]+[eE][-+]?[0-9]+$")
MAX_NEWTON_ITERATIONS = 100

# defaults come from the dataclasses, so schema.py stays their one source
DEFAULT_MESH, DEFAULT_MATERIAL = MeshSpec(), MaterialSpec()
DEFAULT_TIME, DEFAULT_OUTPUT = TimeSpec(), OutputSpec()
DEFAULT_SCENE = SceneConfig(scene="", cloth=())


# --- public entry points ------------------------------------------------------

def load_config(path: str, overrides: Sequence[str] = ()) -> SceneConfig:
    """Read the scene file at ``path``, apply ``key.path=value`` overrides,
    check everything and return the typed configuration."""
    raw = read_scene_file(path)
    raw = apply_overrides(raw, overrides)
    return config_from_dict(raw, os.path.dirname(os.path.abspath(path)), path)


def read_scene_file(path: str) -> dict:
    """The scene file's top-level mapping; every failure names the file."""
    try:
        with open(path, encoding="utf-8") as stream:
            text = stream.read()
    except OSError as err:
        raise ConfigError(path, err.strerror, "a readable YAML scene file") from None
    except UnicodeDecodeError:
        raise ConfigError(path, "not UTF-8 text", "a readable YAML scene file") from None
    try:
        raw = yaml.load(text, Loader=_StrictLoader)
    except yaml.YAMLError as err:
        problem, where = _yaml_problem(err)
        raise ConfigError(path, problem, "valid YAML" + where) from None
    if not isinstance(raw, dict):
        raise ConfigError(path, raw, "a YAML mapping with keys " + ", ".join(SCENE_KEYS))
    return raw


def config_from_dict(raw: dict, base_dir: str, source_name: str) -> SceneConfig:
    """Check a raw scene mapping and build the typed configuration.

    ``base_dir``: where relative mesh paths are looked for (the scene file's
    directory); ``source_name``: the scene file, whose stem names the scene
    by default and which errors about the whole mapping name."""
    if not isinstance(raw, dict):
        raise ConfigError(source_name, raw, "a YAML mapping with keys " + ", ".join(SCENE_KEYS))
    top = read_mapping(raw, "", SCENE_KEYS)
    # checked in the documented key order, so the first error is the first in the file
    scene = _optional(top, "", "scene", Path(source_name).stem, read_str)
    cloth = _read_cloth(top.get("cloth"), "cloth", base_dir)
    effects = _read_effects(top.get("effects"), "effects")
    gravity = _optional(top, "", "gravity", DEFAULT_SCENE.gravity, _read_vec3)
    drag = _optional(top, "", "drag", DEFAULT_SCENE.drag, read_float, at_least=0)
    time = _read_time(top.get("time"), "time")
    solver, mat_type, warm_start, rebuild = _read_solver(top.get("solver"), "solver")
    output = _read_output(top.get("output"), "output", time)
    drape = _read_drape(top.get("drape"), "drape")
    colliders = _read_colliders(top.get("colliders"), "colliders", base_dir)
    stealing = _read_stealing(top.get("work_stealing"), "work_stealing")
    if "collisions" in effects and not colliders:
        raise ConfigError("effects", list(effects),
                          "the collisions effect needs at least one entry under colliders:")
    config = SceneConfig(drape=drape, colliders=colliders, work_stealing=stealing, scene=scene, cloth=cloth, effects=effects, gravity=gravity, drag=drag,
                         time=time, solver=solver, mat_type=mat_type, warm_start=warm_start, pc_rebuild_every=rebuild,
                         output=output)
    source_text = yaml.dump(config_to_dict(config), Dumper=_ResolvedDumper, sort_keys=False)
    return dataclasses.replace(config, source_text=source_text)


def format_config_error(err: ConfigError) -> str:
    """The one line a run stops with (docs/config.md)."""
    return (f"distcloth: config error: {_one_line(err.key)}: {format_value(err.value)}"
            f" — {_one_line(err.allowed)}")


class _StrictLoader(yaml.SafeLoader):
    """yaml.safe_load, but a key given twice in one mapping is an error: PyYAML
    would silently keep the last, and a second 'time:' section would hide the first."""

    def construct_mapping(self, node, deep=False):
        seen = set()
        for key_node, _ in node.value:
            if key_node.tag == "tag:yaml.org,2002:merge":   # '<<' may be overridden
                continue
            key = self.construct_object(key_node, deep=True)
            try:
                duplicate = key in seen
            except TypeError:            # unhashable: the base class says so
                continue
            if duplicate:
                raise yaml.constructor.ConstructorError(
                    "while constructing a mapping", node.start_mark,
                    f"found duplicate key {key}", key_node.start_mark)
            seen.add(key)
        return super().construct_mapping(node, deep)


# --- --set overrides ------------------------------------------------------------

def apply_overrides(raw: dict, overrides: Sequence[str]) -> dict:
    """A copy of ``raw`` with each ``key.path=value`` override set in turn.

    The value is parsed as YAML and checked later like the file's values;
    only the path is checked here, against the key tree.  Integer parts
    address list elements (``cloth.0.material.stretch=20``)."""
    result = copy.deepcopy(raw)
    for text in overrides:
        _apply_override(result, text)
    return result


def _apply_override(raw: dict, text: str) -> None:
    path, equals, value_text = text.partition("=")
    path = path.strip()
    parts = path.split(".")
    if not equals or "" in parts:
        raise ConfigError("--set", text, "key.path=value, e.g. time.step=0.01")
    try:
        value = yaml.safe_load(value_text)
    except yaml.YAMLError as err:
        problem, _ = _yaml_problem(err)
        raise ConfigError(path, value_text, f"a YAML value ({problem})") from None

    node: Any = raw          # the raw value at parts[:depth]
    tree: Any = SCENE_KEYS   # its entry in the key tree
    for depth, part in enumerate(parts):
        here = ".".join(parts[:depth])
        last = depth == len(parts) - 1
        if isinstance(tree, dict):
            if part not in tree:
                where = here or "the top level"
                raise ConfigError(path, value, f"no such key; allowed under {where}: "
                                  + ", ".join(tree))
            slot, child_tree = part, tree[part]
        elif tree == ANY_KEY:
            if not last:
                raise ConfigError(path, value, f"{here} options take single values")
            slot, child_tree = part, LEAF
        else:
            # a list of mappings, or a leaf whose value is a list (vectors, effects)
            if node is None:
                raise ConfigError(path, value, f"{here} is not in the scene: set it whole")
            if not isinstance(node, list):
                raise ConfigError(path, value, f"{here} is a single value")
            if not (part.isascii() and part.isdigit() and int(part) < len(node)):
                raise ConfigError(path, value, f"an index 0 <= i < {len(node)}: {here} has "
                                  f"{len(node)} element(s)")
            if tree is LEAF and not last:
                raise ConfigError(path, value, f"{here}.{part} is a single value")
            slot, child_tree = int(part), (tree[0] if tree else LEAF)
        if last:
            node[slot] = value
            return
        node = _override_child(node, slot, child_tree, path, value, join(here, part))
        tree = child_tree


def _override_child(node: Any, slot: Any, child_tree: Any, path: str, value: Any,
                    child_path: str) -> Any:
    """The raw value at ``node[slot]``, made a mapping or list as the key tree
    says so that the override can go on down."""
    child = node.get(slot) if isinstance(node, dict) else node[slot]
    if isinstance(child_tree, list):
        if isinstance(child, dict):      # a single mapping is a one-element list
            child = node[slot] = [child]
        if child is None:
            raise ConfigError(path, value, f"{child_path} is not in the scene: set it whole")
        if not isinstance(child, list):
            raise ConfigError(path, value, f"{child_path} is not a list")
    elif isinstance(child_tree, dict) or child_tree == ANY_KEY:
        if child is None:                # an absent section: start it
            child = node[slot] = {}
        if not isinstance(child, dict):
            raise ConfigError(path, value, f"{child_path} is not a mapping")
    return child


# --- sections -------------------------------------------------------------------

def _optional(section: dict, key: str, name: str, default: Any, read, *args, **kwargs) -> Any:
    """``section[name]`` checked by ``read``, or ``default`` if absent or null."""
    value = section.get(name)
    return default if value is None else read(value, join(key, name), *args, **kwargs)


def _required(section: dict, key: str, name: str, what: str, read, *args, **kwargs) -> Any:
    value = section.get(name)
    if value is None:
        raise ConfigError(join(key, name), value, f"required: {what}")
    return read(value, join(key, name), *args, **kwargs)


def _read_vec3(value: Any, key: str) -> tuple[float, float, float]:
    return read_vector(value, key, 3, read_float, "numbers")


def _read_cloth(value: Any, key: str, base_dir: str) -> tuple[ClothSpec, ...]:
    if isinstance(value, dict):          # a single mapping is a one-piece list
        value = [value]
    if not isinstance(value, list) or not value:
        raise ConfigError(key, value, "a non-empty list of cloth pieces")
    pieces: list[ClothSpec] = []
    first_with_name: dict[str, int] = {}
    for index, raw_piece in enumerate(value):
        piece = _read_piece(raw_piece, join(key, index), index, base_dir)
        if piece.name in first_with_name:
            raise ConfigError(join(join(key, index), "name"), piece.name,
                              f"a name no other piece has (cloth.{first_with_name[piece.name]}"
                              " has it)")
        first_with_name[piece.name] = index
        pieces.append(piece)
    return tuple(pieces)


def _read_piece(value: Any, key: str, index: int, base_dir: str) -> ClothSpec:
    section = read_mapping(value, key, CLOTH_KEYS)
    mesh = _required(section, key, "mesh", "a mapping with grid: or file:", _read_mesh, base_dir)
    return ClothSpec(
        name=_optional(section, key, "name", f"piece{index}", read_str),
        mesh=mesh,
        pins=_read_pins(section.get("pins"), join(key, "pins"), mesh),
        material=_read_material(section.get("material"), join(key, "material")),
        thickness=_optional(section, key, "thickness", ClothSpec.thickness, read_float, at_least=0),
    )


def _read_mesh(value: Any, key: str, base_dir: str) -> MeshSpec:
    section = read_mapping(value, key, MESH_KEYS)
    kind = exactly_one_of(section, key, ("grid", "file"))
    placement = dict(
        center=_optional(section, key, "center", DEFAULT_MESH.center, _read_vec3),
        rotation=_optional(section, key, "rotation", DEFAULT_MESH.rotation, _read_vec3),
    )
    if kind == "grid":
        if section.get("scale") is not None:
            raise ConfigError(join(key, "scale"), section["scale"], "only for file meshes")
        return MeshSpec(grid=_read_grid(section["grid"], join(key, "grid")), **placement)
    return MeshSpec(
        file=_read_mesh_file(section["file"], join(key, "file"), base_dir),
        scale=_optional(section, key, "scale", DEFAULT_MESH.scale, read_float, above=0),
        **placement,
    )


def _read_grid(value: Any, key: str) -> GridSpec:
    section = read_mapping(value, key, GRID_KEYS)
    return GridSpec(
        size=_required(section, key, "size", "[width, height] in m", read_vector, 2,
                       _read_positive, "numbers > 0"),
        resolution=_required(section, key, "resolution", "[nu, nv] vertices", read_vector, 2,
                             _read_resolution, "integers >= 2"),
        pattern=_optional(section, key, "pattern", GridSpec.pattern, read_choice, GRID_PATTERNS),
    )


def _read_positive(value: Any, key: str) -> float:
    return read_float(value, key, above=0)


def _read_resolution(value: Any, key: str) -> int:
    return read_int(value, key, at_least=2)


def _read_mesh_file(value: Any, key: str, base_dir: str) -> str:
    """The absolute path of an existing OBJ or PLY file; relative paths are
    relative to the scene file, so a scene and its meshes move together."""
    allowed = "an existing " + " or ".join(MESH_SUFFIXES) + " file"
    path = read_str(value, key, allowed)
    if not path.lower().endswith(MESH_SUFFIXES):
        raise ConfigError(key, value, allowed)
    full = os.path.abspath(os.path.join(base_dir, os.path.expanduser(path)))
    if not os.path.isfile(full):
        raise ConfigError(key, value, f"{allowed} (not found: {full})")
    return full


def _read_pins(value: Any, key: str, mesh: MeshSpec) -> tuple[PinSpec, ...]:
    if value is None:
        return ()
    if isinstance(value, dict):          # a single pin, as for cloth pieces
        value = [value]
    read_list(value, key, "pins, each with one of " + ", ".join(PIN_SELECTORS))
    return tuple(_read_pin(pin, join(key, i), mesh) for i, pin in enumerate(value))


def _read_pin(value: Any, key: str, mesh: MeshSpec) -> PinSpec:
    section = read_mapping(value, key, PIN_KEYS)
    # axis: hold the vertices only along this direction, free across it
    axis = _optional(section, key, "axis", None, _read_vec3)
    if axis is not None and float(np.linalg.norm(axis)) == 0.0:
        raise ConfigError(join(key, "axis"), list(axis), "a non-zero direction")
    pin = _read_pin_selection({k: v for k, v in section.items() if k != "axis"}, key, mesh)
    return dataclasses.replace(pin, axis=axis)


def _read_pin_selection(section: dict, key: str, mesh: MeshSpec) -> PinSpec:
    kind = exactly_one_of(section, key, PIN_SELECTORS)
    entry, entry_key = section[kind], join(key, kind)
    if kind in ("edge", "corner"):
        if mesh.grid is None:
            raise ConfigError(entry_key, entry,
                              f"{kind} pins only on grid meshes; use indices or box")
        names = GRID_EDGES if kind == "edge" else GRID_CORNERS
        return PinSpec(**{kind: read_choice(entry, entry_key, names)})
    if kind == "indices":
        return PinSpec(indices=_read_indices(entry, entry_key, mesh))
    box = read_mapping(entry, entry_key, BOX_KEYS)
    low = _required(box, entry_key, "min", "[x, y, z] in m", _read_vec3)
    high = _required(box, entry_key, "max", "[x, y, z] in m", _read_vec3)
    if any(a > b for a, b in zip(low, high)):
        raise ConfigError(entry_key, entry, "min <= max in every component")
    return PinSpec(box_min=low, box_max=high)


def _read_indices(value: Any, key: str, mesh: MeshSpec) -> tuple[int, ...]:
    """Vertex indices of the piece; a file mesh's vertex count is known only
    once the scene builder reads it, so only grids are bounded here."""
    if not isinstance(value, list) or not value:
        raise ConfigError(key, value, "a non-empty list of vertex indices")
    count = None if mesh.grid is None else mesh.grid.resolution[0] * mesh.grid.resolution[1]
    indices = []
    for i, entry in enumerate(value):
        index = read_int(entry, join(key, i), at_least=0)
        if count is not None and index >= count:
            raise ConfigError(join(key, i), entry,
                              f"a vertex index 0 <= i < {count} (the grid's vertex count)")
        indices.append(index)
    return tuple(indices)


def _read_material(value: Any, key: str) -> MaterialSpec:
    section = read_section(value, key, MATERIAL_KEYS)
    preset = _optional(section, key, "preset", None, read_choice, tuple(FABRICS))
    if preset is not None:
        # the preset's values, a continuum membrane unless the scene says otherwise,
        # and every value the scene gives on top
        if section.get("model", "fem") != "fem":
            raise ConfigError(join(key, "model"), section["model"],
                              "fem with a preset (presets are continuum fabrics)")
        base = {k: v for k, v in FABRICS[preset].items() if k != "source"}
        section = {"model": "fem", **base, **{k: v for k, v in section.items() if v is not None}}
    d = DEFAULT_MATERIAL
    material = MaterialSpec(preset=preset, 
        model=_optional(section, key, "model", d.model, read_choice, MATERIAL_MODELS),
        density=_optional(section, key, "density", d.density, read_float, above=0),
        stretch=_optional(section, key, "stretch", d.stretch, read_float, above=0),
        shear=_optional(section, key, "shear", d.shear, read_float, at_least=0),
        bending=_optional(section, key, "bending", d.bending, read_float, at_least=0),
        damping=_optional(section, key, "damping", d.damping, read_float, at_least=0),
        E_weft=_optional(section, key, "E_weft", d.E_weft, read_float, above=0),
        E_warp=_optional(section, key, "E_warp", d.E_warp, read_float, above=0),
        nu_weft=_optional(section, key, "nu_weft", d.nu_weft, read_float, at_least=0),
        nu_warp=_optional(section, key, "nu_warp", d.nu_warp, read_float, at_least=0),
        G=_optional(section, key, "G", d.G, read_float, above=0),
        strain=_optional(section, key, "strain", d.strain, read_choice, STRAIN_MODELS),
        weft=_optional(section, key, "weft", d.weft, _read_vec3),
        bending_model=_optional(section, key, "bending_model", d.bending_model, read_choice,
                                BENDING_MODELS),
        tension_weft=_optional(section, key, "tension_weft", None, _read_curve),
        tension_warp=_optional(section, key, "tension_warp", None, _read_curve),
        shear_curve=_optional(section, key, "shear_curve", None, _read_curve),
    )
    if material.model == "mass_spring":
        for name in ("E_weft", "E_warp", "nu_weft", "nu_warp", "G", "bending_model",
                     "tension_weft", "tension_warp", "shear_curve"):
            if section.get(name) is not None and not (name == "bending_model"
                                                      and material.bending_model == "flexion"):
                raise ConfigError(join(key, name), section[name],
                                  "only with model: fem (mass_spring uses stretch, shear and "
                                  "flexion springs)")
    else:
        if material.bending_model == "flexion":
            raise ConfigError(join(key, "bending_model"), "flexion",
                              "dihedral, isometric, dihedral_shell or isometric_shell with model: fem")
        e_weft, e_warp, nu_weft, nu_warp, _ = material.orthotropic()
        # seed 000 Eq. 22 is symmetric only when nu_weft E_warp = nu_warp E_weft
        if abs(nu_weft * e_warp - nu_warp * e_weft) > 1e-9 * max(nu_weft * e_warp, nu_warp * e_weft, 1e-300):
            raise ConfigError(join(key, "nu_warp"), nu_warp,
                              f"nu_warp = nu_weft * E_warp / E_weft = {nu_weft * e_warp / e_weft:.6g} "
                              "(otherwise the stiffness of seed 000 Eq. 22 is not symmetric)")
        if nu_weft * nu_warp >= 1.0:
            raise ConfigError(join(key, "nu_warp"), nu_warp, "nu_weft * nu_warp < 1")
        tabulated = any(c is not None for c in (material.tension_weft, material.tension_warp,
                                                material.shear_curve))
        if tabulated and material.strain != "stvk":
            raise ConfigError(join(key, "strain"), material.strain,
                              "stvk with tension_weft / tension_warp / shear_curve tables")
        if float(np.linalg.norm(material.weft)) == 0.0:
            raise ConfigError(join(key, "weft"), list(material.weft), "a non-zero direction")
    return material


def _read_effects(value: Any, key: str) -> tuple[str, ...]:
    if value is None:
        return DEFAULT_SCENE.effects
    read_list(value, key, "effect names: " + ", ".join(EFFECTS))
    effects: list[str] = []
    for i, name in enumerate(value):
        read_choice(name, join(key, i), EFFECTS)
        if name in effects:
            raise ConfigError(join(key, i), name, "each effect at most once")
        effects.append(name)
    return tuple(effects)


def _read_time(value: Any, key: str) -> TimeSpec:
    section = read_section(value, key, TIME_KEYS)
    d = DEFAULT_TIME
    end = _optional(section, key, "end", d.end, read_float, above=0)
    step = _optional(section, key, "step", d.step, read_float, above=0)
    if step > end:
        raise ConfigError(join(key, "step"), step,
                          f"a number > 0 and <= time.end ({end:g})")
    return TimeSpec(
        end=end,
        step=step,
        integrator=_optional(section, key, "integrator", d.integrator, read_choice, INTEGRATORS),
        newton_iterations=_optional(section, key, "newton_iterations", d.newton_iterations,
                                    read_int, at_least=1, at_most=MAX_NEWTON_ITERATIONS),
        newton_tolerance=_optional(section, key, "newton_tolerance", d.newton_tolerance,
                                   read_float, above=0),
        newmark_beta=_optional(section, key, "newmark_beta", d.newmark_beta, read_float,
                               at_least=0, at_most=0.5),
        newmark_gamma=_optional(section, key, "newmark_gamma", d.newmark_gamma, read_float,
                                above=0, at_most=1),
        adaptive=_optional(section, key, "adaptive", d.adaptive, read_bool),
        max_halvings=_optional(section, key, "max_halvings", d.max_halvings, read_int,
                               at_least=1, at_most=30),
        max_strain=_optional(section, key, "max_strain", d.max_strain, read_float, above=0),
        energy_guard=_optional(section, key, "energy_guard", d.energy_guard, read_bool),
        max_energy_gain=_optional(section, key, "max_energy_gain", d.max_energy_gain, read_float,
                                  above=0),
        require_newton_convergence=_optional(section, key, "require_newton_convergence",
                                             d.require_newton_convergence, read_bool),
    )


def _read_solver(value: Any, key: str) -> tuple[tuple[tuple[str, Any], ...], str, bool, int]:
    """PETSc options: the defaults, replaced or extended by the scene's; the
    distcloth-only mat_type and warm_start are taken out."""
    if value is None:
        value = {}
    if not isinstance(value, dict):
        raise ConfigError(key, value, "a mapping of PETSc options without '-' and prefix")
    options = dict(DEFAULT_SOLVER)
    mat_type = DEFAULT_SCENE.mat_type
    warm_start = DEFAULT_SCENE.warm_start
    rebuild = DEFAULT_SCENE.pc_rebuild_every
    for name, entry in value.items():
        option_key = join(key, name)
        _check_option_name(name, option_key, entry)
        if entry is None:
            continue
        if name == "mat_type":
            mat_type = read_choice(entry, option_key, MAT_TYPES)
        elif name == "warm_start":
            warm_start = read_bool(entry, option_key)
        elif name == "pc_rebuild_every":
            rebuild = read_int(entry, option_key, at_least=1)
        else:
            options[name] = _read_option_value(entry, option_key)
    if options.get("pc_type") == "gamg" and mat_type == "baij":
        raise ConfigError(join(key, "pc_type"), "gamg", "gamg with solver.mat_type: aij (PETSc's "
                          "GAMG cannot build its graph from the default BAIJ matrix)")
    return tuple(options.items()), mat_type, warm_start, rebuild


def _check_option_name(name: Any, key: str, entry: Any) -> None:
    if isinstance(name, str) and name.startswith("-"):
        raise ConfigError(key, entry, "a PETSc option without the leading '-': "
                          f"write {name.lstrip('-')}")
    if isinstance(name, str) and name.startswith(SOLVER_PREFIX):
        raise ConfigError(key, entry, f"a PETSc option without the prefix {SOLVER_PREFIX} "
                          f"(distcloth adds it): write {name[len(SOLVER_PREFIX):]}")
    if not isinstance(name, str) or not OPTION_NAME.match(name):
        raise ConfigError(key, entry, "a PETSc option name: letters, digits and _,"
                          " starting with a letter")


def _read_option_value(entry: Any, key: str) -> Any:
    allowed = "a string, a finite number or a boolean"
    if isinstance(entry, str) and YAML11_MISSED_FLOAT.match(entry):
        return float(entry)     # 'ksp_rtol: 1e-8' means the number, as '1.0e-8' would
    if isinstance(entry, bool) or (isinstance(entry, str) and entry):
        return entry
    if isinstance(entry, (int, float)):
        return entry if isinstance(entry, int) else read_float(entry, key)
    raise ConfigError(key, entry, allowed)


def _read_output(value: Any, key: str, time: TimeSpec) -> OutputSpec:
    section = read_section(value, key, OUTPUT_KEYS)
    d = DEFAULT_OUTPUT
    every = _optional(section, key, "every", d.every, read_float, above=0)
    if every < time.step:
        raise ConfigError(join(key, "every"), every,
                          f"a number >= time.step ({time.step:g}): frames cannot be more "
                          "frequent than steps")
    return OutputSpec(
        file=_optional(section, key, "file", d.file, _read_output_file),
        every=every,
        preview=_optional(section, key, "preview", d.preview, read_bool),
    )


def _read_curve(value: Any, key: str) -> tuple[tuple[float, float], ...]:
    """[[e, S], ...]: at least two points, from [0, 0], e increasing, S increasing."""
    allowed = "a list of [Green strain, stress N/m] pairs from [0, 0], both increasing"
    read_list(value, key, allowed)
    points = tuple(read_vector(p, join(key, i), 2, read_float, "numbers [e, S]")
                   for i, p in enumerate(value))
    if len(points) < 2 or points[0] != (0.0, 0.0) or any(
            b[0] <= a[0] or b[1] <= a[1] for a, b in zip(points, points[1:])):
        raise ConfigError(key, [list(p) for p in points], allowed)
    return points


def _read_drape(value: Any, key: str) -> DrapeSpec:
    section = read_section(value, key, DRAPE_KEYS)
    d = DrapeSpec()
    return DrapeSpec(
        method=_optional(section, key, "method", d.method, read_choice, DRAPE_METHODS),
        stop_on=_optional(section, key, "stop_on", d.stop_on, read_choice, DRAPE_STOP_ON),
        tolerance=_optional(section, key, "tolerance", d.tolerance, read_float, above=0),
        max_iterations=_optional(section, key, "max_iterations", d.max_iterations, read_int,
                                 at_least=1),
        frame_every=_optional(section, key, "frame_every", d.frame_every, read_int, at_least=1),
    )


def _read_stealing(value: Any, key: str) -> StealSpec:
    section = read_section(value, key, STEAL_KEYS)
    d = StealSpec()
    return StealSpec(
        enabled=_optional(section, key, "enabled", d.enabled, read_bool),
        a=_optional(section, key, "a", d.a, read_float, at_least=0),
        b=_optional(section, key, "b", d.b, read_float, at_least=1),
        chunk=_optional(section, key, "chunk", d.chunk, read_int, at_least=1),
    )


def _read_output_file(value: Any, key: str) -> str:
    """Kept relative to the current directory, as given (normalised)."""
    allowed = "a file name ending in " + " or ".join(OUTPUT_SUFFIXES)
    path = read_str(value, key, allowed)
    name = os.path.basename(path).lower()
    if not name.endswith(OUTPUT_SUFFIXES) or name in OUTPUT_SUFFIXES:
        raise ConfigError(key, value, allowed)
    return os.path.normpath(path)


def _read_colliders(value: Any, key: str, base_dir: str) -> tuple[ColliderSpec, ...]:
    """Analytic and mesh colliders; checked whether or not the collisions effect is on."""
    if value is None:
        return ()
    read_list(value, key, "colliders, each a mapping with name and shape")
    out: list[ColliderSpec] = []
    first: dict[str, int] = {}
    for i, entry in enumerate(value):
        spec = _read_collider(entry, join(key, i), i, base_dir)
        if spec.name in first:
            raise ConfigError(join(join(key, i), "name"), spec.name,
                              f"a name no other collider has (colliders.{first[spec.name]} has it)")
        first[spec.name] = i
        out.append(spec)
    return tuple(out)


def _read_collider(value: Any, key: str, index: int, base_dir: str) -> ColliderSpec:
    section = read_mapping(value, key, COLLIDER_KEYS)
    name = _optional(section, key, "name", f"collider{index}", read_str)
    shape = _required(section, key, "shape", "one of " + " | ".join(COLLIDER_SHAPES),
                      read_choice, COLLIDER_SHAPES)
    wanted = SHAPE_KEYS[shape]
    takes = wanted + (MESH_COLLIDER_KEYS[1:] if shape == "mesh" else ())
    for other in ("normal", "offset", "center", "radius", "a", "b", "half_extents") + MESH_COLLIDER_KEYS:
        if other not in takes and section.get(other) is not None:
            raise ConfigError(join(key, other), section[other],
                              f"not a key of a {shape}; a {shape} takes " + ", ".join(takes))
    common = dict(
        friction=_optional(section, key, "friction", ColliderSpec.friction, read_float, at_least=0),
        thickness=_optional(section, key, "thickness", ColliderSpec.thickness, read_float,
                            at_least=0),
        motion=_optional(section, key, "motion", None, _read_motion))
    if shape == "mesh":
        return ColliderSpec(name=name, shape=shape, geometry=(), **common,
                            **_read_mesh_collider(section, key, base_dir))
    geometry: list[tuple[str, Any]] = []
    for name_ in wanted:
        what = {"normal": "[x, y, z], non-zero", "offset": "a number in m (normal . y = offset)",
                "center": "[x, y, z] in m", "radius": "a number > 0 in m",
                "a": "[x, y, z] in m", "b": "[x, y, z] in m",
                "half_extents": "[x, y, z], each > 0, in m"}[name_]
        if name_ in ("normal", "center", "a", "b"):
            v = _required(section, key, name_, what, _read_vec3)
        elif name_ == "half_extents":
            v = _required(section, key, name_, what, read_vector, 3, _read_positive, "numbers > 0")
        elif name_ == "radius":
            v = _required(section, key, name_, what, read_float, above=0)
        else:
            v = _required(section, key, name_, what, read_float)
        if name_ == "normal" and float(np.linalg.norm(v)) == 0.0:
            raise ConfigError(join(key, "normal"), list(v), "a non-zero direction")
        geometry.append((name_, v))
    return ColliderSpec(name=name, shape=shape, geometry=tuple(geometry), **common)


def _read_mesh_collider(section: dict, key: str, base_dir: str) -> dict:
    """file: one OBJ/PLY (static, or moved by motion) or a list of them (a
    deforming sequence, one file per frame at frame_rate frames per second)."""
    raw = section.get("file")
    if raw is None:
        raise ConfigError(join(key, "file"), None, "an OBJ or PLY file, or a list of them "
                          "(one per frame)")
    many = isinstance(raw, list)
    if many and not raw:
        raise ConfigError(join(key, "file"), raw, "a non-empty list of OBJ or PLY files")
    files = tuple(_read_mesh_file(f, join(join(key, "file"), i), base_dir)
                  for i, f in enumerate(raw)) if many else (
        _read_mesh_file(raw, join(key, "file"), base_dir),)
    rate = _optional(section, key, "frame_rate", None, read_float, above=0)
    if len(files) > 1 and rate is None:
        raise ConfigError(join(key, "frame_rate"), None,
                          "frames per second (> 0): needed with a list of files")
    if len(files) == 1 and rate is not None:
        raise ConfigError(join(key, "frame_rate"), rate, "only with a list of files (a sequence)")
    method = _optional(section, key, "method", ColliderSpec.method, read_choice, COLLIDER_METHODS)
    if method != "image":
        for k in ("resolution", "axis"):
            if section.get(k) is not None:
                raise ConfigError(join(key, k), section[k], "only with method: image")
    return dict(
        files=files, frame_rate=rate,
        scale=_optional(section, key, "scale", ColliderSpec.scale, read_float, above=0),
        method=method,
        resolution=_optional(section, key, "resolution", ColliderSpec.resolution, read_vector, 2,
                             _read_map_size, "integers from 8 to 8192"),
        axis=_optional(section, key, "axis", ColliderSpec.axis, read_choice, IMAGE_AXES))


def _read_map_size(value: Any, key: str) -> int:
    return read_int(value, key, at_least=8, at_most=8192)


def _read_motion(value: Any, key: str) -> MotionSpec:
    section = read_mapping(value, key, MOTION_KEYS)
    times = _required(section, key, "times", "a non-empty list of increasing times in s",
                      read_list, "times in s")
    if not times:
        raise ConfigError(join(key, "times"), times, "a non-empty list of increasing times in s")
    times = tuple(read_float(t, join(join(key, "times"), i)) for i, t in enumerate(times))
    for i in range(1, len(times)):
        if not times[i] > times[i - 1]:
            raise ConfigError(join(join(key, "times"), i), times[i],
                              f"a time > {times[i - 1]:g} (times strictly increasing)")
    k = len(times)
    keyed = {}
    for name_ in ("translations", "rotations"):
        raw = section.get(name_)
        if raw is None:
            keyed[name_] = tuple((0.0, 0.0, 0.0) for _ in range(k))
            continue
        what = f"a list of {k} [x, y, z] vectors (one per time)"
        if not isinstance(raw, list) or len(raw) != k:
            raise ConfigError(join(key, name_), raw, what)
        keyed[name_] = tuple(_read_vec3(v, join(join(key, name_), i)) for i, v in enumerate(raw))
    return MotionSpec(times=times, **keyed)


def _collider_to_dict(c: ColliderSpec) -> dict:
    out = {"name": c.name, "shape": c.shape,
           **{k: (list(v) if isinstance(v, tuple) else v) for k, v in c.geometry},
           "friction": c.friction, "thickness": c.thickness}
    if c.shape == "mesh":
        out["file"] = c.files[0] if len(c.files) == 1 else list(c.files)
        if c.frame_rate is not None:
            out["frame_rate"] = c.frame_rate
        out.update(scale=c.scale, method=c.method)
        if c.method == "image":
            out.update(resolution=list(c.resolution), axis=c.axis)
    if c.motion is not None:
        out["motion"] = {"times": list(c.motion.times),
                         "translations": [list(v) for v in c.motion.translations],
                         "rotations": [list(v) for v in c.motion.rotations]}
    return out


# --- the resolved configuration as plain data -----------------------------------

def config_to_dict(config: SceneConfig) -> dict:
    """``config`` as YAML-ready plain data that :func:`config_from_dict` reads
    back to an equal configuration (written into the output file)."""
    return {
        "scene": config.scene,
        "cloth": [_piece_to_dict(piece) for piece in config.cloth],
        "effects": list(config.effects),
        "gravity": list(config.gravity),
        "drag": config.drag,
        "time": dataclasses.asdict(config.time),
        "solver": {**dict(config.solver), "mat_type": config.mat_type,
                   "warm_start": config.warm_start, "pc_rebuild_every": config.pc_rebuild_every},
        "output": dataclasses.asdict(config.output),
        "drape": dataclasses.asdict(config.drape),
        **({"colliders": [_collider_to_dict(c) for c in config.colliders]}
           if config.colliders else {}),
        "work_stealing": dataclasses.asdict(config.work_stealing),
    }


class _ResolvedDumper(yaml.SafeDumper):
    """safe_dump, but lists of scalars (vectors, effects, indices) on one line
    as in docs/config.md; mappings stay in block style."""


def _represent_list(dumper: yaml.SafeDumper, data: list) -> yaml.Node:
    flat = not any(isinstance(item, (list, dict)) for item in data)
    return dumper.represent_sequence("tag:yaml.org,2002:seq", data, flow_style=flat)


_ResolvedDumper.add_representer(list, _represent_list)


def _piece_to_dict(piece: ClothSpec) -> dict:
    mesh = piece.mesh
    if mesh.grid is not None:
        shape: dict = {"grid": {"size": list(mesh.grid.size),
                                "resolution": list(mesh.grid.resolution),
                                "pattern": mesh.grid.pattern}}
    else:
        shape = {"file": mesh.file, "scale": mesh.scale}
    return {
        "name": piece.name,
        "mesh": {**shape, "center": list(mesh.center), "rotation": list(mesh.rotation)},
        "pins": [_pin_to_dict(pin) for pin in piece.pins],
        "material": {k: _plain(v) for k, v in dataclasses.asdict(piece.material).items()},
        "thickness": piece.thickness,
    }


def _plain(value):
    """Tuples (nested) as lists, for YAML."""
    return [_plain(v) for v in value] if isinstance(value, (tuple, list)) else value


def _pin_to_dict(pin: PinSpec) -> dict:
    axis = {} if pin.axis is None else {"axis": list(pin.axis)}
    if pin.edge is not None:
        return {"edge": pin.edge, **axis}
    if pin.corner is not None:
        return {"corner": pin.corner, **axis}
    if pin.indices is not None:
        return {"indices": list(pin.indices), **axis}
    return {"box": {"min": list(pin.box_min), "max": list(pin.box_max)}, **axis}


# --- helpers ----------------------------------------------------------------------

def _yaml_problem(err: yaml.YAMLError) -> tuple[str, str]:
    """What PyYAML found wrong, and where ('' if it does not say)."""
    problem = getattr(err, "problem", None) or str(err).splitlines()[0]
    mark = getattr(err, "problem_mark", None)
    where = "" if mark is None else f" (error at line {mark.line + 1}, column {mark.column + 1})"
    return problem, where


def _one_line(text: str) -> str:
    return " ".join(str(text).splitlines())
