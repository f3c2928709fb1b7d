"""Reading YAML files: a text read again gives the same document, a changed text the new one, and
every call a document of its own."""

from __future__ import annotations

from pathlib import Path

from hoh_cosim.yamlfile import read_yaml


def test_a_document_read_again_is_equal_and_its_own(tmp_path: Path) -> None:
    path = tmp_path / "a.yaml"
    path.write_text("gains: [1, 2]\nname: x\n", encoding="utf-8")
    first = read_yaml(path)
    first["gains"].append(3)  # a caller may change its copy
    second = read_yaml(path)
    assert second == {"gains": [1, 2], "name": "x"}
    assert second is not first
    assert second["gains"] is not first["gains"]


def test_a_changed_file_is_read_anew(tmp_path: Path) -> None:
    path = tmp_path / "a.yaml"
    path.write_text("k: 1\n", encoding="utf-8")
    assert read_yaml(path) == {"k": 1}
    path.write_text("k: 2\n", encoding="utf-8")  # same size, same path, maybe the same mtime
    assert read_yaml(path) == {"k": 2}
    other = tmp_path / "b.yaml"
    other.write_text("k: 1\n", encoding="utf-8")  # the first text again, in another file
    assert read_yaml(other) == {"k": 1}
