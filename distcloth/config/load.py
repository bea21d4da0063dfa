"""YAML scene file (plus ``--set`` overrides) -> checked :class:`SceneConfig`.

Every value is checked here, before any work starts, so that a bad scene
stops the run with one line naming the key path (docs/config.md).  The keys,
their defaults and what they allow are the field descriptions of schema.py;
walk.py reads any section from them, rules.py adds the rules between keys.
Whether PETSc knows a solver option is checked later, by the solver code.
"""
from __future__ import annotations

import copy
import dataclasses
import os
from collections.abc import Mapping, Sequence
from typing import Any

import yaml

from .checks import format_value, join
from .describe import entries
from .formats import LINEAR_SYSTEM
from .resolved import config_to_dict, source_text
from .rules import RULES
from .schema import OPTION_PREFIX, ConfigError, LinearSystemSpec, SceneConfig
from .walk import ANY_KEY, LEAF, Context, key_tree, read_spec

# every key a scene may hold: unknown keys and --set paths are checked against it
SCENE_KEYS = key_tree(SceneConfig)

__all__ = ["ConfigError", "apply_overrides", "command_line_key", "config_from_dict",
           "config_to_dict", "format_config_error", "load_config", "own_option_names",
           "read_scene_file"]


# --- public entry points ------------------------------------------------------

def load_config(path: str, overrides: Sequence[str] = (),
                options: Mapping[str, str] | None = None) -> SceneConfig:
    """Read the scene file at ``path``, apply ``key.path=value`` overrides and
    then distcloth's own command-line options (``options``: name -> value text
    of each ``-distcloth_<name> <value>``, names from :func:`own_option_names`),
    check everything and return the typed configuration."""
    options = dict(options or {})
    raw = read_scene_file(path)
    raw = apply_overrides(raw, overrides)
    try:
        raw = apply_overrides(raw, [f"{LINEAR_SYSTEM}.{name}={text}"
                                    for name, text in options.items()])
        return config_from_dict(raw, os.path.dirname(os.path.abspath(path)), path)
    except ConfigError as err:
        raise _from_command_line(err, options) from None


def own_option_names() -> tuple[str, ...]:
    """The keys of linear_system:, which the command line also sets as
    ``-distcloth_<name> <value>``, as PETSc options are written."""
    return tuple(e.key for e in entries(LinearSystemSpec))


def command_line_key(name: str) -> str:
    """How an error names the command-line option ``-distcloth_<name>``."""
    return f"command line -{OPTION_PREFIX}{name}"


def _from_command_line(err: ConfigError, options: Mapping[str, str]) -> ConfigError:
    """``err``, naming the command-line option if that is where the bad value came from."""
    for name in options:
        if err.key == f"{LINEAR_SYSTEM}.{name}":
            return ConfigError(command_line_key(name), err.value, err.allowed)
    return err


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
    config = read_spec(SceneConfig, raw, "", Context(base_dir, source_name, RULES))
    return dataclasses.replace(config, source_text=source_text(config))


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


# --- helpers ----------------------------------------------------------------------

def _yaml_problem(err: yaml.YAMLError) -> tuple[str, str]:
    """What PyYAML found wrong, and where ('' if it does not say)."""
    problem = getattr(err, "problem", None) or str(err).splitlines()[0]
    mark = getattr(err, "problem_mark", None)
    where = "" if mark is None else f" (error at line {mark.line + 1}, column {mark.column + 1})"
    return problem, where


def _one_line(text: str) -> str:
    return " ".join(str(text).splitlines())
