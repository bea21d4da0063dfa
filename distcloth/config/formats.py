"""Value formats that a type annotation does not describe: files, stress
curves, PETSc options.

A field names its format with ``read=`` (describe.py).  A format has a
reader ``(value, key, ctx) -> typed value`` that raises ConfigError naming
``key``, the text of what it allows (messages and docs/config.md) and, where
the typed value is not plain YAML data, how to write it back.
"""
from __future__ import annotations

import os
import re
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from .checks import join, read_float, read_list, read_str, read_vector
from .describe import entries
from ..body.skeleton import JOINT_NAMES
from .schema import DEFAULT_SOLVER, OPTION_PREFIX, ConfigError, LinearSystemSpec, SceneConfig

MESH_SUFFIXES = (".obj", ".ply")
OUTPUT_SUFFIXES = (".h5", ".hdf5")
OPTION_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")  # PETSc names may hold capitals (pc_hypre_boomeramg_P_max)
# PETSc viewer types that write a file (or open a window or socket) without a file name
FILE_VIEWER_TYPES = {"binary", "hdf5", "vtk", "draw", "socket", "matlab", "saws", "glvis",
                     "adios", "exodusii", "mathematica", "cgns"}
# PyYAML (YAML 1.1) wants a dot in a float: '1e-8' comes back as a string
YAML11_MISSED_FLOAT = re.compile(r"^[-+]?[0-9]+[eE][-+]?[0-9]+$")
# the scene section of distcloth's own solver settings (the keys solver: once held)
LINEAR_SYSTEM = next(e.key for e in entries(SceneConfig) if e.type is LinearSystemSpec)


@dataclass(frozen=True)
class Format:
    read: Callable[[Any, str, Any], Any]
    allowed: str
    dump: Callable[[Any], Any] | None = None
    any_key: bool = False          # a mapping of free names: --set takes any key below it


def read_mesh_file(value: Any, key: str, ctx: Any) -> str:
    """The absolute path of an existing OBJ or PLY file; relative paths are
    relative to the scene file, so a scene and its meshes move together."""
    return _existing_file(value, key, ctx, MESH_SUFFIXES, MESH_FILE_TEXT)


def _existing_file(value: Any, key: str, ctx: Any, suffixes, allowed: str) -> str:
    path = read_str(value, key, allowed)
    if not path.lower().endswith(suffixes):
        raise ConfigError(key, value, allowed)
    full = os.path.abspath(os.path.join(ctx.base_dir, os.path.expanduser(path)))
    if not os.path.isfile(full):
        raise ConfigError(key, value, f"{allowed} (not found: {full})")
    return full


def read_pattern_file(value: Any, key: str, ctx: Any) -> str:
    """The absolute path of an existing sewing pattern (GarmentCode
    specification JSON, or the compact form in YAML or JSON), relative to
    the scene file; its contents are checked when the scene is built."""
    return _existing_file(value, key, ctx, PATTERN_SUFFIXES, PATTERN_FILE_TEXT)


def read_motion_file(value: Any, key: str, ctx: Any) -> str:
    """The absolute path of an existing BVH file, relative to the scene file;
    its contents are checked when the collider is built."""
    return _existing_file(value, key, ctx, MOTION_SUFFIXES, MOTION_FILE_TEXT)


def read_joint_map(value: Any, key: str, ctx: Any) -> tuple[tuple[str, str], ...]:
    """Body joint -> capture joint name: the body's joints (a fixed list),
    any names on the capture's side (checked against the file when the
    collider is built)."""
    if not isinstance(value, dict):
        raise ConfigError(key, value, JOINT_MAP_TEXT)
    out = []
    for name, joint in value.items():
        if name not in JOINT_NAMES:
            raise ConfigError(join(key, name), joint, f"a body joint: one of {' | '.join(JOINT_NAMES)}")
        out.append((name, read_str(joint, join(key, name), "a joint name of the motion file")))
    return tuple(out)


def read_mesh_files(value: Any, key: str, ctx: Any) -> tuple[str, ...]:
    """One OBJ/PLY file (static, or moved by motion) or a list of them (a
    deforming sequence, one file per frame)."""
    if not isinstance(value, list):
        return (read_mesh_file(value, key, ctx),)
    if not value:
        raise ConfigError(key, value, "a non-empty list of OBJ or PLY files")
    return tuple(read_mesh_file(f, join(key, i), ctx) for i, f in enumerate(value))


def _dump_mesh_files(files: tuple[str, ...]) -> str | list[str]:
    return files[0] if len(files) == 1 else list(files)


def read_output_file(value: Any, key: str, ctx: Any) -> str:
    """Kept relative to the current directory, as given (normalised)."""
    path = read_str(value, key, OUTPUT_FILE_TEXT)
    name = os.path.basename(path).lower()
    if not name.endswith(OUTPUT_SUFFIXES) or name in OUTPUT_SUFFIXES:
        raise ConfigError(key, value, OUTPUT_FILE_TEXT)
    return os.path.normpath(path)


def read_curve(value: Any, key: str, ctx: Any) -> tuple[tuple[float, float], ...]:
    """[[e, S], ...]: at least two points, from [0, 0], e increasing, S increasing."""
    read_list(value, key, CURVE_TEXT)
    points = tuple(read_vector(p, join(key, i), 2, read_float, "numbers [e, S]")
                   for i, p in enumerate(value))
    if len(points) < 2 or points[0] != (0.0, 0.0) or any(
            b[0] <= a[0] or b[1] <= a[1] for a, b in zip(points, points[1:])):
        raise ConfigError(key, [list(p) for p in points], CURVE_TEXT)
    return points


def read_petsc_options(value: Any, key: str, ctx: Any) -> tuple[tuple[str, Any], ...]:
    """PETSc options: the defaults, replaced or extended by the scene's.
    Whether PETSc knows an option is checked later, by the solver code."""
    if not isinstance(value, dict):
        raise ConfigError(key, value, PETSC_OPTIONS_TEXT)
    if not value:     # solver: {} says no more than no section: the size preset
        return ()
    moved = {e.key for e in entries(LinearSystemSpec)}
    options = dict(DEFAULT_SOLVER)
    for name, entry in value.items():
        option_key = join(key, name)
        _check_option_name(name, option_key, entry)
        if name in moved:
            raise ConfigError(option_key, entry, f"moved: write {LINEAR_SYSTEM}.{name}")
        if entry is not None:
            options[name] = _read_option_value(entry, option_key)
            if writes_files(options[name]):
                raise ConfigError(option_key, entry, "not a viewer that writes a file or opens "
                                  "a window (ascii:PATH, :PATH, binary, hdf5, draw, ...): a scene "
                                  "cannot make PETSc write files; give it on the command line "
                                  f"(-{OPTION_PREFIX}{name} {entry})")
    return tuple(options.items())


def writes_files(value: Any) -> bool:
    """Whether a PETSc option value is a viewer that writes a file or opens a
    window or socket: 'ascii:PATH', ':PATH', 'binary', 'hdf5:PATH', 'draw', ..."""
    if not isinstance(value, str):
        return False
    kind, _, rest = value.partition(":")
    return kind.strip().lower() in FILE_VIEWER_TYPES or bool(rest.split(":")[0].strip())


def _check_option_name(name: Any, key: str, entry: Any) -> None:
    if isinstance(name, str) and name.startswith("-"):
        raise ConfigError(key, entry, "a PETSc option without the leading '-': "
                          f"write {name.lstrip('-')}")
    if isinstance(name, str) and name.startswith(OPTION_PREFIX):
        raise ConfigError(key, entry, f"a PETSc option without the prefix {OPTION_PREFIX} "
                          f"(distcloth adds it): write {name[len(OPTION_PREFIX):]}")
    if not isinstance(name, str) or not OPTION_NAME.match(name):
        raise ConfigError(key, entry, "a PETSc option name: letters, digits and _,"
                          " starting with a letter")


def _read_option_value(entry: Any, key: str) -> Any:
    if isinstance(entry, str) and YAML11_MISSED_FLOAT.match(entry):
        return float(entry)     # 'ksp_rtol: 1e-8' means the number, as '1.0e-8' would
    if isinstance(entry, bool) or (isinstance(entry, str) and entry):
        return entry
    if isinstance(entry, (int, float)):
        return entry if isinstance(entry, int) else read_float(entry, key)
    raise ConfigError(key, entry, "a string, a finite number or a boolean")


MESH_FILE_TEXT = "an existing " + " or ".join(MESH_SUFFIXES) + " file"
PATTERN_SUFFIXES = (".json", ".yaml", ".yml")
PATTERN_FILE_TEXT = ("an existing sewing pattern file: " + ", ".join(PATTERN_SUFFIXES)
                     + " (GarmentCode specification or the compact form)")
JOINT_MAP_TEXT = "a mapping of body joints to the motion file's joint names"
MOTION_SUFFIXES = (".bvh",)
MOTION_FILE_TEXT = "an existing .bvh motion capture file"
OUTPUT_FILE_TEXT = "a file name ending in " + " or ".join(OUTPUT_SUFFIXES)
CURVE_TEXT = "a list of [Green strain, stress N/m] pairs from [0, 0], both increasing"
PETSC_OPTIONS_TEXT = "a mapping of PETSc options without '-' and prefix"

FORMATS: dict[str, Format] = {
    "mesh_file": Format(read_mesh_file, MESH_FILE_TEXT),
    "pattern_file": Format(read_pattern_file, PATTERN_FILE_TEXT),
    "mesh_files": Format(read_mesh_files, f"{MESH_FILE_TEXT}, or a non-empty list of them",
                         dump=_dump_mesh_files),
    "motion_file": Format(read_motion_file, MOTION_FILE_TEXT),
    "joint_map": Format(read_joint_map, JOINT_MAP_TEXT, dump=dict, any_key=True),
    "output_file": Format(read_output_file, OUTPUT_FILE_TEXT),
    "curve": Format(read_curve, CURVE_TEXT),
    "petsc_options": Format(read_petsc_options, PETSC_OPTIONS_TEXT, dump=dict, any_key=True),
}
