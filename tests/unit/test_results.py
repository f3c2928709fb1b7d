"""Results directories: one kind's result never replaces another kind's, nor a folder of the user's."""

from __future__ import annotations

from pathlib import Path

import pytest

from hoh_cosim.errors import ConfigError
from hoh_cosim.results import KIND_FILE, check_out_dir, replace_dir


def _fill(*names: str):
    def fill(staging: Path) -> None:
        for name in names:
            (staging / name).write_text("x", encoding="utf-8")

    return fill


def test_a_result_names_its_kind_and_replaces_an_earlier_one_of_the_same_kind(tmp_path):
    out = tmp_path / "run"
    replace_dir(out, _fill("summary.json", "old.txt"), what="run")
    assert (out / KIND_FILE).read_text(encoding="utf-8") == "run\n"
    check_out_dir(out, what="run")
    replace_dir(out, _fill("summary.json"), what="run")
    assert sorted(p.name for p in out.iterdir()) == [KIND_FILE, "summary.json"]
    assert [p.name for p in tmp_path.iterdir()] == ["run"]  # nothing left beside it


@pytest.mark.parametrize(
    ("written", "wanted", "marker"),
    [
        ("run", "clinical study", "operators.csv"),
        ("clinical study", "run", "summary.json"),
        ("clinical study", "report", "report.md"),
        ("clinical study", "sweep", "runs.csv"),
    ],
)
def test_a_result_of_another_kind_is_refused_though_it_has_the_marker(
    tmp_path, written, wanted, marker
):
    out = tmp_path / "out"
    replace_dir(out, _fill("summary.json", "report.md", "runs.csv", "operators.csv"), what=written)
    with pytest.raises(ConfigError, match=rf"holds a hoh-cosim {written}, not a {wanted}; choose"):
        check_out_dir(out, marker=marker, what=wanted)


def test_a_folder_without_a_kind_needs_the_marker(tmp_path):
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("mine", encoding="utf-8")
    with pytest.raises(ConfigError, match=r"holds no summary.json, so it is not a hoh-cosim run"):
        check_out_dir(tmp_path / "mine")
    (tmp_path / "older").mkdir()
    (tmp_path / "older" / "summary.json").write_text("{}", encoding="utf-8")
    check_out_dir(tmp_path / "older")  # a run written before results named their kind
