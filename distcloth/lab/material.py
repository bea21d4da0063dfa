"""The material a lab session tests: a named fabric or a piece of a scene."""
from __future__ import annotations

import os
from dataclasses import dataclass

import yaml

from ..config.fabrics import FABRICS
from ..config.load import load_config, read_scene_file
from ..config.schema import ConfigError


@dataclass(frozen=True)
class LabMaterial:
    label: str          # what the report calls it
    raw: dict           # the material mapping, as a scene's cloth[i].material
    base_dir: str       # where its relative paths (tension curves) are read from


def lab_material(what: str, piece: str | None = None, overrides=()) -> LabMaterial:
    """A preset name, or a scene file whose piece ``piece`` (default: the first)
    gives the material; the scene is checked whole first (ConfigError).
    ``overrides``: material ``key=value`` texts (YAML values) applied after."""
    found = _material(what, piece)
    raw = dict(found.raw)
    for text in overrides:
        key, sep, value = text.partition("=")
        if not sep or not key.strip():
            raise ConfigError("--set", text, "key=value, a key of the material")
        try:
            raw[key.strip()] = yaml.safe_load(value)
        except yaml.YAMLError:
            raise ConfigError("--set " + key.strip(), value, "a YAML value") from None
    label = found.label + "".join(f", {t}" for t in overrides)
    return LabMaterial(label, raw, found.base_dir)


def _material(what: str, piece: str | None) -> LabMaterial:
    if what in FABRICS:
        return LabMaterial(f"preset {what}", {"preset": what}, os.getcwd())
    if not os.path.isfile(what):
        raise ConfigError("lab SCENE-OR-PRESET", what,
                          "a fabric preset (" + ", ".join(FABRICS) + ") or a scene file")
    cfg = load_config(what)
    names = [c.name for c in cfg.cloth]
    index = 0
    if piece is not None:
        if piece not in names:
            raise ConfigError("--piece", piece, "a piece of " + what + ": " + ", ".join(names))
        index = names.index(piece)
    pieces = read_scene_file(what)["cloth"]
    pieces = [pieces] if isinstance(pieces, dict) else pieces
    raw = pieces[index].get("material", {}) or {}
    return LabMaterial(f"{os.path.basename(what)}, piece {names[index]}", dict(raw),
                       os.path.dirname(os.path.abspath(what)))
