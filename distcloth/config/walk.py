"""Reading, checking and writing back any described section (describe.py).

:func:`read_spec` walks the fields of a schema dataclass: each value is
checked by the reader its type calls for (checks.py), with the field's bounds
and choices, or by its named format (formats.py); an absent or null key takes
the field's default.  Rules that tie keys together run before and after the
walk, per section type (rules.py, passed in through the :class:`Context`).
:func:`key_tree` gives the keys a section may hold (unknown-key checks and
``--set`` paths); :func:`to_data` writes a section back as plain data.
"""
from __future__ import annotations

import functools
import math
from collections.abc import Callable, Mapping
from dataclasses import MISSING, dataclass, field, is_dataclass, replace
from pathlib import Path
from typing import Any

from .checks import (BOOL_TEXT, bounds_text, choice_text, exactly_one_of, integer_text, join,
                     number_text, read_bool, read_choice, read_float, read_int, read_mapping,
                     read_str, read_vector)
from .describe import (Entry, Setting, entries, entry, is_section, list_element, one_of_groups,
                       vector_elements)
from .formats import FORMATS
from .schema import ConfigError

# The key tree: a dict lists the keys of a mapping, a one-element list is a
# list of such mappings, LEAF is a value checked by its reader, ANY_KEY a
# mapping of free names (PETSc options).
LEAF = None
ANY_KEY = "any key"


@dataclass(frozen=True)
class Rules:
    """Cross-field rules of one section type: ``before(section, key, ctx)``
    may check or rewrite the raw mapping, ``after(spec, section, key, ctx)``
    checks (or completes) the built dataclass."""
    before: Callable[[dict, str, Context], dict] | None = None
    after: Callable[[Any, dict, str, Context], Any] | None = None


@dataclass(frozen=True)
class Context:
    base_dir: str                  # where relative mesh paths are looked for
    source_name: str               # the scene file (its stem names the scene)
    rules: Mapping[type, Rules] = field(default_factory=dict)
    index: int | None = None       # position in the enclosing list
    parent: Mapping[str, Any] = field(default_factory=dict)   # the enclosing section's values so far

    def below(self, **changes: Any) -> Context:
        return replace(self, **changes)


NO_RULES = Rules()


# --- keys ---------------------------------------------------------------------

@functools.cache
def key_tree(spec_type: type) -> dict:
    """The keys a section of ``spec_type`` may hold (shared: do not modify)."""
    tree: dict = {}
    for e in entries(spec_type):
        if e.setting.internal:
            continue
        if e.setting.inline:
            tree.update(key_tree(e.setting.inline))
        else:
            _place(tree, e.key, _subtree(e))
    return tree


def _subtree(e: Entry) -> Any:
    if e.setting.read:
        return ANY_KEY if FORMATS[e.setting.read].any_key else LEAF
    if is_section(e.type):
        return key_tree(e.type)
    element = list_element(e.type)
    if element is not None and is_section(element):
        return [key_tree(element)]
    return LEAF


def _place(mapping: dict, dotted: str, value: Any) -> None:
    *parents, last = dotted.split(".")
    for part in parents:
        mapping = mapping.setdefault(part, {})
    mapping[last] = value


# --- what a key allows ---------------------------------------------------------

def allowed_text(value_type: Any, s: Setting) -> str:
    """What a value of this type and description may be, as messages say it."""
    if s.read:
        return FORMATS[s.read].allowed
    if is_section(value_type):
        return "a mapping with keys " + ", ".join(key_tree(value_type))
    element = list_element(value_type)
    if element is not None:
        text = f"a {'non-empty ' if s.nonempty else ''}list of {s.what or _plural(element, s)}"
        if s.choices:
            text += ": " + ", ".join(s.choices)
        if is_section(element):
            for names in one_of_groups(element).values():
                text += ", each with one of " + ", ".join(names)
        return text
    elements = vector_elements(value_type)
    if elements is not None:
        return f"a list of {len(elements)} {_plural(elements[0], s)}"
    if value_type is bool:
        return BOOL_TEXT
    if value_type is int:
        return integer_text(s.at_least, s.at_most)
    if value_type is float:
        return number_text(s.above, s.at_least, s.at_most)
    if value_type is str:
        return choice_text(s.choices) if s.choices else "a non-empty string"
    raise TypeError(f"no reader for {value_type}")


def required_text(e: Entry) -> str:
    return "required: " + (e.setting.what or allowed_text(e.type, e.setting))


def _plural(element: Any, s: Setting) -> str:
    if element is float:
        return "numbers" + bounds_text(s.above, s.at_least, s.at_most)
    if element is int:
        if s.at_least is not None and s.at_most is not None:
            return f"integers from {s.at_least:g} to {s.at_most:g}"
        return "integers" + bounds_text(None, s.at_least, s.at_most)
    if element is str:
        return "names"
    inner = vector_elements(element)
    if inner is not None:
        return f"lists of {len(inner)} {_plural(inner[0], s)}"
    return "mappings"


# --- reading ------------------------------------------------------------------

def read_spec(spec_type: type, value: Any, key: str, ctx: Context) -> Any:
    """The section at ``key`` (a raw mapping) checked into a ``spec_type``."""
    tree = key_tree(spec_type)
    section = read_mapping(value, key, tree)
    for names in one_of_groups(spec_type).values():
        exactly_one_of(section, key, names)
    rules = ctx.rules.get(spec_type, NO_RULES)
    if rules.before is not None:
        section = rules.before(section, key, ctx)
    values: dict[str, Any] = {}
    inner = ctx.below(parent=values)
    for e in entries(spec_type):
        if e.setting.internal:
            continue
        only = e.setting.only          # its sibling comes first (describe.entries)
        if only is not None and not only.holds(values[only.field]):
            raw = _raw_value(section, tree, e.key, key)
            if raw is not None:
                raise ConfigError(join(key, e.key), raw, only.message)
        values[e.name] = _read_entry(e, section, tree, key, inner)
    spec = spec_type(**values)
    if rules.after is not None:
        spec = rules.after(spec, section, key, ctx)
    return spec


def read_field(spec_type: type, name: str, section: dict, key: str, ctx: Context) -> Any:
    """One field of a section, read on its own (for rules that need it first)."""
    return _read_entry(entry(spec_type, name), section, key_tree(spec_type), key, ctx)


def _read_entry(e: Entry, section: dict, tree: dict, key: str, ctx: Context) -> Any:
    if e.setting.inline:
        # the inline keys that are given, as (key, value) pairs in declaration order
        given = ((g.key, _read_entry(g, section, tree, key, ctx))
                 for g in entries(e.setting.inline))
        return tuple((k, v) for k, v in given if v is not None)
    path = join(key, e.key)
    raw = _raw_value(section, tree, e.key, key)
    if raw is None:
        return _missing(e, path, ctx)
    return _read_value(e.type, raw, path, e.setting, ctx)


def _raw_value(section: dict, tree: dict, dotted: str, key: str) -> Any:
    """The raw value at a (possibly dotted) key; the mappings on the way are checked."""
    *parents, last = dotted.split(".")
    node = section
    for part in parents:
        key, tree = join(key, part), tree[part]
        node = node.get(part)
        if node is None:
            return None
        node = read_mapping(node, key, tree)
    return node.get(last)


def _missing(e: Entry, path: str, ctx: Context) -> Any:
    if e.default is not MISSING:
        return e.default
    if e.setting.auto:
        return e.setting.auto.format(index=ctx.index, stem=Path(ctx.source_name).stem)
    if e.setting.nonempty:
        raise ConfigError(path, None, allowed_text(e.type, e.setting))
    raise ConfigError(path, None, required_text(e))


def _read_value(value_type: Any, raw: Any, path: str, s: Setting, ctx: Context) -> Any:
    if s.read:
        return FORMATS[s.read].read(raw, path, ctx)
    if is_section(value_type):
        return read_spec(value_type, raw, path, ctx)
    each = replace(s, nonempty=False, nonzero=False, what="")   # applies to every element
    element = list_element(value_type)
    if element is not None:
        if is_section(element) and isinstance(raw, dict):
            raw = [raw]                  # a single mapping is a one-element list
        if not isinstance(raw, list) or (s.nonempty and not raw):
            raise ConfigError(path, raw, allowed_text(value_type, s))
        return tuple(_read_value(element, item, join(path, i), each, ctx.below(index=i))
                     for i, item in enumerate(raw))
    elements = vector_elements(value_type)
    if elements is not None:
        vector = read_vector(raw, path, len(elements),
                             lambda item, k: _read_value(elements[0], item, k, each, ctx),
                             _plural(elements[0], s))
        if s.nonzero and math.sqrt(sum(c * c for c in vector)) == 0.0:
            raise ConfigError(path, list(vector), "a non-zero direction")
        return vector
    if value_type is bool:
        return read_bool(raw, path)
    if value_type is int:
        return read_int(raw, path, at_least=s.at_least, at_most=s.at_most)
    if value_type is float:
        return read_float(raw, path, above=s.above, at_least=s.at_least, at_most=s.at_most)
    if value_type is str:
        return read_choice(raw, path, s.choices) if s.choices else read_str(raw, path)
    raise TypeError(f"no reader for {value_type}")


# --- writing back ----------------------------------------------------------------

def to_data(spec: Any) -> dict:
    """``spec`` as plain YAML-ready data that :func:`read_spec` reads back to an
    equal dataclass: null values and keys whose condition fails are left out."""
    out: dict = {}
    for e in entries(type(spec)):
        s = e.setting
        value = getattr(spec, e.name)
        if s.internal or value is None:
            continue
        if s.only is not None and not s.only.holds(getattr(spec, s.only.field)):
            continue
        if s.inline:
            out.update((k, _data(v, s)) for k, v in value)
        else:
            _place(out, e.key, _data(value, s))
    return out


def _data(value: Any, s: Setting) -> Any:
    if s.read and FORMATS[s.read].dump is not None:
        return FORMATS[s.read].dump(value)
    if is_dataclass(value):
        return to_data(value)
    if isinstance(value, tuple):
        return [_data(v, s) for v in value]
    return value
