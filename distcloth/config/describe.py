"""How a scene key is declared: once, on its dataclass field.

A field of a schema dataclass carries a :class:`Setting` in its metadata: a
one-line doc, the unit, bounds or choices, and where its YAML key differs
from the field.  The field's annotation gives the type, its default the
default.  Everything else is generated from these descriptions: reading and
checking (walk.py), the key tree of ``--set`` paths, the resolved YAML
(resolved.py) and the key reference of docs/config.md (docs.py).

    stretch: float = setting(10.0, doc="uniaxial membrane stiffness Y", unit="N/m", above=0)
    strain: str = choice("stvk", STRAIN_MODELS, doc="...")
    time: TimeSpec = section(TimeSpec, doc="...")
"""
from __future__ import annotations

import dataclasses
import functools
import types
import typing
from dataclasses import MISSING, dataclass
from typing import Any

METADATA_KEY = "distcloth"
GIVEN = object()        # Only.value: the sibling key is present, whatever its value


@dataclass(frozen=True)
class Only:
    """A key that applies only while a sibling field has ``value`` (or is
    given, with GIVEN); giving it otherwise is the error ``message``, and the
    resolved YAML leaves it out."""
    field: str
    value: Any
    message: str

    def holds(self, sibling: Any) -> bool:
        return sibling is not None if self.value is GIVEN else sibling == self.value

    @property
    def condition(self) -> str:
        """The condition as docs/config.md states it."""
        return self.field if self.value is GIVEN else f"{self.field}: {self.value}"


@dataclass(frozen=True)
class Setting:
    doc: str                          # one line: what the key means
    unit: str = ""
    above: float | None = None        # bounds: of the value, or of each number in a list
    at_least: float | None = None
    at_most: float | None = None
    choices: tuple[str, ...] = ()     # allowed strings (of the value, or of each list element)
    nonzero: bool = False             # a vector that must not be all zeros (a direction)
    nonempty: bool = False            # a list that needs at least one element
    what: str = ""                    # the value in error messages, where the type says too little
    key: str = ""                     # the YAML key, if not the field's name ('box.min': nested)
    auto: str = ""                    # default made when absent: '{index}' and '{stem}' filled in
    one_of: str = ""                  # a group of keys of which exactly one must be given
    only: Only | None = None          # the key applies only with a sibling's value
    read: str = ""                    # a named value format (formats.py) instead of the type's
    inline: type | None = None        # the fields of this dataclass sit in the parent's mapping
    internal: bool = False            # not a scene key (SceneConfig.source_text)


def setting(default: Any = MISSING, *, doc: str, **described: Any) -> Any:
    """A described field; without ``default`` the key is required (or ``auto``)."""
    metadata = {METADATA_KEY: Setting(doc=doc, **described)}
    if default is MISSING:
        return dataclasses.field(metadata=metadata)
    return dataclasses.field(default=default, metadata=metadata)


def choice(default: Any, choices: tuple[str, ...], *, doc: str, **described: Any) -> Any:
    """A described field whose value (or each element) is one of ``choices``."""
    return setting(default, doc=doc, choices=tuple(choices), **described)


def section(spec_type: type, *, doc: str) -> Any:
    """A nested section whose default is ``spec_type()``: null means all defaults."""
    return dataclasses.field(default_factory=spec_type, metadata={METADATA_KEY: Setting(doc=doc)})


@dataclass(frozen=True)
class Entry:
    """One described field of a schema dataclass, its annotation resolved."""
    name: str              # the dataclass field
    key: str               # the YAML key
    type: Any              # the annotation without '| None'
    optional: bool         # null is a value of it (the annotation had '| None')
    default: Any           # MISSING: no default
    setting: Setting

    @property
    def doc(self) -> str:
        return self.setting.doc


@functools.cache
def entries(spec_type: type) -> tuple[Entry, ...]:
    """The described fields of ``spec_type``, in declaration order; a field
    without a description is a programming error."""
    hints = typing.get_type_hints(spec_type)
    out = []
    for f in dataclasses.fields(spec_type):
        described = f.metadata.get(METADATA_KEY)
        if not isinstance(described, Setting):
            raise TypeError(f"{spec_type.__name__}.{f.name} has no description (describe.setting)")
        value_type, optional = _strip_none(hints[f.name])
        if f.default is not MISSING:
            default = f.default
        elif f.default_factory is not MISSING:
            default = f.default_factory()
        else:
            default = MISSING
        only = described.only
        if only is not None and only.field not in {e.name for e in out}:
            raise TypeError(f"{spec_type.__name__}.{f.name}: only= names {only.field}, "
                            "which must be declared before it")
        out.append(Entry(f.name, described.key or f.name, value_type, optional, default, described))
    return tuple(out)


def needs(spec_type: type, e: Entry, condition: Only) -> bool:
    """Whether ``e`` applies only under ``condition``, directly or through the
    key its own condition names."""
    only = e.setting.only
    return only is not None and (only == condition
                                 or needs(spec_type, entry(spec_type, only.field), condition))


def entry(spec_type: type, name: str) -> Entry:
    """The entry of field ``name``."""
    return next(e for e in entries(spec_type) if e.name == name)


def _strip_none(hint: Any) -> tuple[Any, bool]:
    if isinstance(hint, types.UnionType) or typing.get_origin(hint) is typing.Union:
        args = [a for a in typing.get_args(hint) if a is not type(None)]
        if len(args) != 1:
            raise TypeError(f"unsupported union {hint}")
        return args[0], True
    return hint, False


def is_section(value_type: Any) -> bool:
    return dataclasses.is_dataclass(value_type) and isinstance(value_type, type)


def list_element(value_type: Any) -> Any | None:
    """T for ``tuple[T, ...]``, else None."""
    args = typing.get_args(value_type)
    if typing.get_origin(value_type) is tuple and len(args) == 2 and args[1] is Ellipsis:
        return args[0]
    return None


def vector_elements(value_type: Any) -> tuple | None:
    """(T1, T2, ...) for a fixed-length ``tuple[T1, T2, ...]``, else None."""
    args = typing.get_args(value_type)
    if typing.get_origin(value_type) is tuple and args and Ellipsis not in args:
        return args
    return None


def one_of_groups(spec_type: type) -> dict[str, tuple[str, ...]]:
    """Each one_of group of ``spec_type``: the top-level YAML keys, in order."""
    groups: dict[str, list[str]] = {}
    for e in entries(spec_type):
        if e.setting.one_of:
            top = e.key.split(".")[0]
            keys = groups.setdefault(e.setting.one_of, [])
            if top not in keys:
                keys.append(top)
    return {name: tuple(keys) for name, keys in groups.items()}


def sections(spec_type: type) -> list[type]:
    """``spec_type`` and every section below it (inline ones included), depth first."""
    found: list[type] = []

    def visit(t: type) -> None:
        if t in found:
            return
        found.append(t)
        for e in entries(t):
            inner = e.setting.inline or list_element(e.type) or e.type
            if is_section(inner):
                visit(inner)

    visit(spec_type)
    return found
