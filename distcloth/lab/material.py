"""The material a lab session tests: a named fabric or a piece of a scene."""
from __future__ import annotations

import os
from dataclasses import dataclass

from ..config.fabrics import FABRICS
from ..config.load import load_config, read_scene_file
from ..config.schema import ConfigError


@dataclass(frozen=True)
class LabMaterial:
    label: str          # what the report calls it
    raw: dict           # the material mapping, as a scene's cloth[i].material
    base_dir: str       # where its relative paths (tension curves) are read from


def lab_material(what: str, piece: str | None = None) -> LabMaterial:
    """A preset name, or a scene file whose piece ``piece`` (default: the first)
    gives the material; the scene is checked whole first (ConfigError)."""
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
