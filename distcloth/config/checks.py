"""Small typed readers for raw YAML values.

Each reader takes the raw value and its key path (``cloth.0.material.density``)
and returns the typed value or raises :class:`ConfigError` naming that path.
Rules shared by every reader:

* ``bool`` is never a number (YAML ``yes``/``true`` must not become 1);
* an int is accepted where a float is wanted, never the other way round;
* a string is accepted where a float is wanted only if ``float()`` parses it,
  because PyYAML follows YAML 1.1 and reads ``1e-5`` (no dot) as a string;
* every float is finite.
"""
from __future__ import annotations

import difflib
import math
from collections.abc import Callable, Iterable, Iterator
from typing import Any, TypeVar

from .schema import ConfigError

T = TypeVar("T")

MAX_SHOWN_CHARS = 60


def join(key: str, part: object) -> str:
    """The key path of ``part`` inside ``key`` ('' is the top level)."""
    return f"{key}.{part}" if key else str(part)


def is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def bounds_text(above: float | None = None, at_least: float | None = None,
                at_most: float | None = None) -> str:
    """' > 0', ' >= 1 and <= 100' or ''."""
    parts = []
    if above is not None:
        parts.append(f"> {above:g}")
    if at_least is not None:
        parts.append(f">= {at_least:g}")
    if at_most is not None:
        parts.append(f"<= {at_most:g}")
    return (" " + " and ".join(parts)) if parts else ""


def number_text(above: float | None = None, at_least: float | None = None,
                at_most: float | None = None) -> str:
    return "a finite number" + bounds_text(above, at_least, at_most)


def integer_text(at_least: int | None = None, at_most: int | None = None) -> str:
    return "an integer" + bounds_text(None, at_least, at_most)


def choice_text(choices: Iterable[str]) -> str:
    return "one of " + " | ".join(choices)


BOOL_TEXT = "true or false"


def read_float(value: Any, key: str, *, above: float | None = None,
               at_least: float | None = None, at_most: float | None = None) -> float:
    allowed = number_text(above, at_least, at_most)
    if isinstance(value, str):
        try:
            number = float(value)      # YAML 1.1 reads '1e-5' as a string: accept it
        except ValueError:
            raise ConfigError(key, value, allowed) from None
    elif is_number(value):
        try:
            number = float(value)
        except OverflowError:          # an int too large for a float
            raise ConfigError(key, value, allowed) from None
    else:
        raise ConfigError(key, value, allowed)
    if not math.isfinite(number):
        raise ConfigError(key, value, allowed)
    if ((above is not None and not number > above)
            or (at_least is not None and not number >= at_least)
            or (at_most is not None and not number <= at_most)):
        raise ConfigError(key, value, allowed)
    return number


def read_int(value: Any, key: str, *, at_least: int | None = None,
             at_most: int | None = None) -> int:
    allowed = integer_text(at_least, at_most)
    if not isinstance(value, int) or isinstance(value, bool):
        raise ConfigError(key, value, allowed)
    if (at_least is not None and value < at_least) or (at_most is not None and value > at_most):
        raise ConfigError(key, value, allowed)
    return value


def read_bool(value: Any, key: str) -> bool:
    if not isinstance(value, bool):
        raise ConfigError(key, value, BOOL_TEXT)
    return value


def read_str(value: Any, key: str, allowed: str = "a non-empty string") -> str:
    if not isinstance(value, str) or not value:
        raise ConfigError(key, value, allowed)
    return value


def read_choice(value: Any, key: str, choices: Iterable[str]) -> str:
    choices = tuple(choices)
    if not isinstance(value, str) or value not in choices:
        raise ConfigError(key, value, choice_text(choices))
    return value


def read_list(value: Any, key: str, what: str) -> list:
    if not isinstance(value, list):
        raise ConfigError(key, value, f"a list of {what}")
    return value


def read_vector(value: Any, key: str, length: int,
                read_element: Callable[[Any, str], T], what: str) -> tuple[T, ...]:
    """A list of exactly ``length`` elements, each checked by ``read_element``."""
    if not isinstance(value, list) or len(value) != length:
        raise ConfigError(key, value, f"a list of {length} {what}")
    return tuple(read_element(element, join(key, i)) for i, element in enumerate(value))


def read_mapping(value: Any, key: str, allowed_keys: Iterable[str]) -> dict:
    """A mapping whose keys are all in ``allowed_keys``."""
    allowed_keys = tuple(allowed_keys)
    if not isinstance(value, dict):
        raise ConfigError(key, value, "a mapping with keys " + ", ".join(allowed_keys))
    for name, entry in value.items():
        if name not in allowed_keys:
            raise ConfigError(join(key, name), entry, unknown_key_text(name, allowed_keys))
    return value


def unknown_key_text(name: object, allowed_keys: Iterable[str]) -> str:
    allowed_keys = tuple(allowed_keys)
    close = difflib.get_close_matches(str(name), allowed_keys, n=1)
    hint = f" (did you mean {close[0]}?)" if close else ""
    return f"unknown key{hint}; allowed keys: " + ", ".join(allowed_keys)


def exactly_one_of(mapping: dict, key: str, names: Iterable[str]) -> str:
    """The single key of ``names`` present (non-null) in ``mapping``."""
    names = tuple(names)
    present = [name for name in names if mapping.get(name) is not None]
    if len(present) != 1:
        raise ConfigError(key, mapping, "exactly one of " + ", ".join(names))
    return present[0]


def format_value(value: Any, limit: int = MAX_SHOWN_CHARS) -> str:
    """``value`` on one line, YAML-ish (null, true, 'text', [1, 2], {a: 1}),
    cut to about ``limit`` characters.  Built lazily so that huge or
    self-referencing values (YAML anchors can make cycles) stay cheap."""
    shown = ""
    for piece in _value_pieces(value):
        shown += piece
        if len(shown) > limit:
            return shown[:limit - 1] + "…"
    return shown


def _value_pieces(value: Any) -> Iterator[str]:
    if value is None:
        yield "null"
    elif isinstance(value, bool):
        yield "true" if value else "false"
    elif isinstance(value, (list, tuple)):
        yield "["
        for i, element in enumerate(value):
            if i:
                yield ", "
            yield from _value_pieces(element)
        yield "]"
    elif isinstance(value, dict):
        yield "{"
        for i, (name, element) in enumerate(value.items()):
            if i:
                yield ", "
            yield (name if isinstance(name, str) and name.isprintable() else repr(name)) + ": "
            yield from _value_pieces(element)
        yield "}"
    else:
        yield repr(value)   # repr escapes newlines: always one line
