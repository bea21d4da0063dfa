"""docs/config.md's key reference is generated from the field descriptions
(python -m distcloth.config.docs): it must be current, every field must say
what it is, and every key must appear in it."""
import dataclasses
import re

import pytest
import yaml

from distcloth.config.describe import entries, sections, setting
from distcloth.config.docs import (BEGIN, DOCS_FILE, END, main, reference, render,
                                   section_doc, section_paths)
from distcloth.config.load import SCENE_KEYS, config_from_dict
from distcloth.config.schema import SceneConfig


def test_docs_config_md_is_current():
    text = DOCS_FILE.read_text(encoding="utf-8")
    assert render(text) == text, ("docs/config.md is stale: run "
                                  ".venv/bin/python -m distcloth.config.docs --write")


def test_the_command_finds_and_rewrites_a_stale_file(tmp_path):
    path = tmp_path / "config.md"
    path.write_text(f"# Scene files\n\nprose\n\n{BEGIN}\nold table\n{END}\n\nmore prose\n")
    assert main([str(path)]) == 1
    assert "old table" in path.read_text()          # checking does not write
    assert main(["--write", str(path)]) == 0
    assert main([str(path)]) == 0
    text = path.read_text()
    assert text.startswith("# Scene files\n\nprose\n\n" + BEGIN)
    assert text.endswith(END + "\n\nmore prose\n") and "old table" not in text


def test_a_file_without_markers_is_refused(tmp_path):
    with pytest.raises(ValueError, match="markers"):
        render("# no markers here\n")


@pytest.mark.parametrize("spec_type", sections(SceneConfig), ids=lambda t: t.__name__)
def test_every_field_has_a_doc_line(spec_type):
    assert section_doc(spec_type), f"{spec_type.__name__} needs a docstring (its section's text)"
    for e in entries(spec_type):
        where = f"{spec_type.__name__}.{e.name}"
        assert e.doc.strip(), f"{where}: empty doc"
        assert "\n" not in e.doc and not e.doc.endswith("."), f"{where}: one line, no full stop"


def test_a_field_without_a_description_is_refused():
    @dataclasses.dataclass(frozen=True)
    class Spec:
        described: int = setting(1, doc="a described field")
        bare: int = 2

    with pytest.raises(TypeError, match="Spec.bare has no description"):
        entries(Spec)


def test_every_scene_key_has_a_row():
    """Each key of the --set key tree, nested keys included, is a row of the
    section of its path."""
    text = reference()
    tables = dict(re.findall(r"### (?:`([^`]*)`|Top level)\n\n.*?\n\n(\| key .*?)\n\n", text + "\n\n",
                             flags=re.S))

    def visit(tree, path):
        rows = tables.get(path, "")
        for key, sub in tree.items():
            if isinstance(sub, dict) and key != "box":       # a section: its own table
                assert f"| `{key}` |" in rows, (path, key)
                visit(sub, f"{path}.{key}" if path else key)
            elif isinstance(sub, list):
                assert f"| `{key}` |" in rows, (path, key)
                index = "<" + "ijk"[path.count("<")] + ">"
                visit(sub[0], f"{path}.{key}.{index}" if path else f"{key}.{index}")
            elif isinstance(sub, dict):                       # box: {min, max}
                for inner in sub:
                    assert f"| `{key}.{inner}` |" in rows, (path, key, inner)
            else:
                assert f"| `{key}` |" in rows, (path, key)

    assert set(tables) == {path for path, _ in section_paths(SceneConfig)}
    visit(SCENE_KEYS, "")


def test_the_example_scene_in_the_docs_is_valid(tmp_path):
    text = DOCS_FILE.read_text(encoding="utf-8")
    example = re.search(r"```yaml\n(.*?)```", text, flags=re.S).group(1)
    config = config_from_dict(yaml.safe_load(example), str(tmp_path), "example.yaml")
    assert config.scene == "hanging_square" and config.linear_system.mat_type == "baij"


@pytest.mark.parametrize("path", ["drape", "cloth.<i>.pins.<j>.motion", "cloth.<i>.loads.<j>"])
def test_sections_have_their_table_with_every_key(path):
    """The drape section (read by distcloth drape only) and the grips' and
    loads' sections each have their table, one row per key."""
    spec_type = dict(section_paths(SceneConfig))[path]
    text = DOCS_FILE.read_text(encoding="utf-8")
    table = text.split(f"### `{path}`\n", 1)[1].split("\n### ", 1)[0]
    for e in entries(spec_type):
        assert f"| `{e.key}` |" in table, (path, e.key)
