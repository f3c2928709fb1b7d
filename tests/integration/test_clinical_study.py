"""`hoh-cosim study clinical --quick`: a small study on a local Dask cluster, what it writes, and the
mistakes it refuses before anything runs."""

from __future__ import annotations

import csv
import json
import re
from pathlib import Path

import pytest

from hoh_cosim.cli import main
from hoh_cosim.study.clinical import ASSISTED, MODES, TASKS, study_variants

# one worker runs this module (tests/xdist_groups.py): the study runs once
pytestmark = pytest.mark.xdist_group(__name__)

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"
OPERATORS = 2


@pytest.fixture(scope="module")
def study(tmp_path_factory: pytest.TempPathFactory) -> tuple[int, Path]:
    out = tmp_path_factory.mktemp("clinical") / "study"
    status = main(
        [
            "study",
            "clinical",
            "--quick",
            "--operators",
            str(OPERATORS),
            "--workers",
            "2",
            "--scenarios",
            str(SCENARIOS),
            "--out",
            str(out),
            "--quiet",
        ]
    )
    return status, out


def test_it_writes_the_page_the_table_and_the_summary(study) -> None:
    status, out = study
    assert status == 0
    for name in (
        "index.html",
        "report.md",
        "runs.csv",
        "runs.parquet",
        "operators.csv",
        "summary.json",
        "effort.png",
        "reduction.png",
        "breath.png",
        "jitter.png",
    ):
        assert (out / name).is_file(), name
    page = (out / "index.html").read_text()
    for image in re.findall(r"<img src='([^']+)'", page):
        assert (out / image).is_file(), image
    report = (out / "report.md").read_text()
    assert "Fang 2017 beside ours" in report
    assert "32 to 73" in report
    assert not [p for p in out.parent.iterdir() if p.name.startswith(".")]  # no staging left


def test_every_operator_does_every_task_in_every_mode(study) -> None:
    _, out = study
    with (out / "runs.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == OPERATORS * len(TASKS) * len(MODES)
    assert {(r["operator"], r["task"], r["mode"]) for r in rows} == {
        (str(i + 1), t, m) for i in range(OPERATORS) for t in TASKS for m in MODES
    }
    assert {r["status"] for r in rows} == {"ok"}
    for r in rows:
        # every run made contact, never lost it, and its metrics were all measurable
        assert float(r["contact_force_mean_N"]) > 3.0
        assert r["contact_losses"] == "0"
        for key in ("hand_force_rms_N", "jitter_image_mm", "task_time_s", "path_rms_error_m"):
            assert r[key] != "", (r["task"], r["mode"], key)
    with (out / "operators.csv").open() as f:
        assert len(list(csv.DictReader(f))) == OPERATORS


def test_the_summary_pairs_each_assisted_mode_with_freehand(study) -> None:
    _, out = study
    summary = json.loads((out / "summary.json").read_text())
    assert summary["operators"] == OPERATORS
    assert summary["failed_runs"] == []
    for task in TASKS:
        for mode in ASSISTED:
            entry = summary["tasks"][task][mode]
            for key in ("hand_force_reduction_pct", "jitter_improvement_pct"):
                s = entry[key]
                assert s["n"] == OPERATORS
                assert isinstance(s["mean"], float)
                assert s["min"] == min(s["per_operator"])
                low, high = s["ci95"]
                assert low <= s["mean"] <= high
    # a short study judges no target; the hold-on-release figures come with that mode
    assert all(t["hand_force_reduction_met"] is None for t in summary["targets"].values())
    text = json.dumps(summary)
    for absent in ("handback_jump_m", "hold_on_release"):
        assert absent not in text


def test_an_operator_is_the_same_person_and_patient_in_every_run() -> None:
    keyed = study_variants(SCENARIOS, 2, seed=5, quick=True)
    by_operator: dict[int, set] = {}
    for (i, _task, mode), variant in keyed:
        person = tuple(
            o
            for o in variant.overrides
            if o.startswith(("breathing.", "operator.stiffness", "operator.tremor"))
            and not o.startswith("breathing.start_s")
        )
        by_operator.setdefault(i, set()).add((variant.seed, person))
        assert any(o.startswith(f"{MODES[mode].grip}.grip_stiffness") for o in variant.overrides)
        # the breathing starts with the task: on the robot after the rebias, freehand at once
        start = "3.0" if MODES[mode].assisted else "0.0"
        assert f"breathing.start_s={start}" in variant.overrides
    assert all(len(kinds) == 1 for kinds in by_operator.values())
    assert by_operator[0] != by_operator[1]


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (["--operators", "0"], r"--operators: expected an integer from 1 to 1000, got 0"),
        (["--scheduler", "bogus"], r"--scheduler bogus: expected a Dask scheduler's address"),
        (["--scheduler", "tcp://127.0.0.1:1"], r"--scheduler tcp://127.0.0.1:1: cannot reach"),
        (["--seed", "-1"], r"--seed: expected an integer >= 0, got -1"),
        (["--workers", "-2"], r"--workers: expected an integer >= 0, got -2"),
    ],
)
def test_a_mistake_is_one_line_and_nothing_is_written(
    options: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "study"
    status = main(
        ["study", "clinical", "--quick", "--scenarios", str(SCENARIOS), "--out", str(out), *options]
    )
    err = capsys.readouterr().err
    assert status == 2
    assert len(err.strip().splitlines()) == 1, err
    assert re.search(message, err), err
    assert not out.exists()
    assert list(tmp_path.iterdir()) == []


def test_an_out_that_is_a_file_is_refused(tmp_path: Path, capsys) -> None:
    out = tmp_path / "study"
    out.write_text("mine")
    status = main(
        ["study", "clinical", "--quick", "--scenarios", str(SCENARIOS), "--out", str(out)]
    )
    assert status == 2
    assert "exists and is not a directory" in capsys.readouterr().err
    assert out.read_text() == "mine"
