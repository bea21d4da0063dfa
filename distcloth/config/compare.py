"""The first difference between two resolved configurations (a resumed run's
scene against the one its checkpoint was written with)."""
from __future__ import annotations

from typing import Any

import yaml

from .checks import join
from .schema import ConfigError

# keys a resumed run may change: how long it runs and what it writes, not the physics
RESUMABLE = ("time.end", "output.file", "output.preview", "output.checkpoint")


def first_difference(old: Any, new: Any, key: str = "",
                     ignore: tuple[str, ...] = RESUMABLE) -> tuple[str, Any, Any] | None:
    """(key path, old value, new value) of the first difference, in the new
    configuration's key order, leaving out ``ignore`` and the keys below them."""
    if key and any(key == k or key.startswith(k + ".") for k in ignore):
        return None
    if isinstance(old, dict) and isinstance(new, dict):
        for k in list(new) + [k for k in old if k not in new]:
            found = first_difference(old.get(k), new.get(k), join(key, k), ignore)
            if found:
                return found
        return None
    if isinstance(old, list) and isinstance(new, list) and len(old) == len(new):
        for i, (a, b) in enumerate(zip(old, new)):
            found = first_difference(a, b, join(key, i), ignore)
            if found:
                return found
        return None
    return None if old == new else (key or "scene", old, new)


def check_resumable(checkpoint_text: str, scene_text: str) -> None:
    """ConfigError naming the first key where the scene differs from the
    checkpoint's resolved configuration (both YAML texts)."""
    found = first_difference(yaml.safe_load(checkpoint_text), yaml.safe_load(scene_text))
    if found is not None:
        key, old, new = found
        raise ConfigError(key, new, f"{old!r}, as in the checkpoint: a resumed run keeps its "
                                    f"scene (only {', '.join(RESUMABLE)} may change)")
