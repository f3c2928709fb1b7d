"""`hoh-cosim study clinical --quick`: a small study on a local Dask cluster, what it writes, and the
mistakes it refuses before anything runs."""

from __future__ import annotations

import contextlib
import csv
import importlib.util
import io
import json
import re
from pathlib import Path

import numpy as np
import pytest

from hoh_cosim.cli import main
from hoh_cosim.cosim.scenario import load_scenario
from hoh_cosim.presets import figure_lines, load_preset
from hoh_cosim.study.clinical import (
    ASSISTED,
    FREEHAND,
    MODES,
    STUDY_PRESETS,
    TASKS,
    _shared_modes,
    study_modes,
    study_variants,
)

# one worker runs this module (tests/xdist_groups.py): the study runs once
pytestmark = pytest.mark.xdist_group(__name__)

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"
OPERATORS = 2
SET = "controller.hold.swing_s=0.1"
SCANNING = ("view", "scan", "press")  # the tasks without the patient moving away
LETS_GO = ("hold", "clinical")  # the presets that hold the contact: their hands let go
HAVE_RERUN = importlib.util.find_spec("rerun") is not None  # the view (or test) extra


@pytest.fixture(scope="module")
def study(tmp_path_factory: pytest.TempPathFactory) -> tuple[int, Path]:
    out = tmp_path_factory.mktemp("clinical") / "study"
    said = io.StringIO()
    with contextlib.redirect_stdout(said):
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
                # through every assisted mode, a --set that changes no run: the hold presets' own
                # value, and the other presets' hold is off
                "--set",
                SET,
                "--figures",
                str(out.parent / "figures.json"),
                *(["--record-view"] if HAVE_RERUN else []),
            ]
        )
    (out.parent / "said.txt").write_text(said.getvalue())  # what the command printed
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
    assert f"every assisted mode with --set {SET}" in report.splitlines()[2]
    said = (out.parent / "said.txt").read_text().splitlines()
    assert said[1] == f"  every assisted mode with --set {SET}", said[:3]
    assert json.loads((out / "summary.json").read_text())["overrides"] == [SET]
    assert "Fang 2017 beside ours" in report
    assert "32 to 73" in report
    assert not [p for p in out.parent.iterdir() if p.name.startswith(".")]  # no staging left
    # the presets' figures, as `hoh-cosim presets` shows them
    figures = json.loads((out.parent / "figures.json").read_text())
    assert figures["_measured_by"].startswith(f"hoh-cosim study clinical --operators {OPERATORS}")
    assert set(figures) - {"_measured_by"} == set(STUDY_PRESETS)
    for name in STUDY_PRESETS:
        lines = figure_lines(figures[name])
        assert lines[0].startswith("hand force less than freehand, every operator: view "), lines
        assert any(line.startswith("release: ") for line in lines), (name, lines)


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
        # every run made contact, and its metrics were all measurable
        assert float(r["contact_force_mean_N"]) > 3.0
        for key in ("hand_force_rms_N", "jitter_image_mm", "path_rms_error_m"):
            assert r[key] != "", (r["task"], r["mode"], key)
        if r["task"] in SCANNING:  # none lost the contact while scanning
            assert r["contact_losses"] == "0", (r["task"], r["mode"])
            assert r["recovery_time_s"] == "", (r["task"], r["mode"])
        # a goal never reached and held is a result, not a metric that failed: in the short study
        # the transparency laws may not settle the view within 2 mm and 10 %, the hold keeps the
        # force it found, not the hand's target, and after the probe check the view's force swings
        # about twice as wide through the breaths (3.0 against 1.5 N std in the full study; the
        # follow and glide presets' check too)
        if r["mode"] in (FREEHAND, "seed") and r["task"] != "recover":
            assert r["task_time_s"] != "", (r["task"], r["mode"])
    with (out / "operators.csv").open() as f:
        assert len(list(csv.DictReader(f))) == OPERATORS


@pytest.mark.skipif(not HAVE_RERUN, reason="the views need rerun-sdk (the view or test extra)")
def test_record_view_keeps_one_recording_of_each_kept_run_with_the_arm_and_the_run_s_time(
    study,
) -> None:
    """`--record-view`: one recording per operator (the first three), task and mode in `views/`,
    each read back by Rerun's reader with the arm drawn over the run's whole time."""
    from rerun.chunk import RrdReader

    _, out = study
    views = out / "views"
    assert {p.name for p in views.iterdir()} == {
        f"operator-{i + 1:02d}-{task}-{mode}.rrd"
        for i in range(min(OPERATORS, 3))
        for task in TASKS
        for mode in MODES
    }
    times: dict[str, list[float]] = {}
    for chunk in RrdReader(views / "operator-02-press-clinical.rrd").stream():
        if chunk.is_static or "sim_time" not in chunk.timeline_names:
            continue
        column = chunk.to_record_batch().column("sim_time").cast("int64").to_pylist()
        times.setdefault(chunk.entity_path, []).extend(t * 1e-9 for t in column)
    arm = [path for path in times if path.startswith("/world/arm/link")]
    assert len(arm) == 6, sorted(times)
    assert min(times[arm[-1]]) < 0.1
    assert max(times[arm[-1]]) > TASKS["press"].quick_task_s - 0.1


def test_modes_that_run_the_same_are_run_once_and_reported_under_each(study, tmp_path) -> None:
    """Two presets that give every component the same parameters run the same: each of their runs
    is run once (a user's file that changes nothing of the seed's law against the seed); a preset
    that differs anywhere is run on its own."""
    same = tmp_path / "same.yaml"
    same.write_text("description: the seed's law again\nextends: seed\n")
    other = tmp_path / "other.yaml"
    other.write_text("description: x\nextends: seed\ncontroller: {contact_torque: false}\n")
    modes = study_modes(["seed", str(same), str(other)])
    assert _shared_modes(SCENARIOS, modes) == {"same": "seed"}
    # the default presets are all different
    _, out = study
    summary = json.loads((out / "summary.json").read_text())
    assert summary["equal_laws"] == []


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
    # a short study judges no target (but the release's, one scenario run per preset)
    for mode, targets in summary["targets"].items():
        for key in ("hand_force_reduction_met", "jitter_improvement_met", "recovery_met"):
            assert targets[key] is None, (mode, key)
        assert targets.get("hold_met") is None
        assert isinstance(targets["release_met"], bool)
        release = summary["release"][mode]
        assert release["drift_m"] > 0.0
    assert set(summary["presets"]) == set(ASSISTED)
    assert summary["presets"]["clinical"]["changes"]["controller.recovery.enabled"] is True


def test_the_transparency_laws_and_hold_on_release_are_modes(study) -> None:
    assert {"transparent", *LETS_GO} <= set(ASSISTED)
    assert MODES["transparent"].preset == "transparent"
    assert [m for m in ASSISTED if MODES[m].lets_go] == list(LETS_GO)
    _, out = study
    summary = json.loads((out / "summary.json").read_text())
    # the transparency laws act: they brake after a release, where the seed's law never does
    for task in SCANNING:
        flags = " ".join(summary["tasks"][task]["transparent"]["controller_flags"])
        assert "braking to rest" in flags, (task, flags)
        assert "braking to rest" not in " ".join(summary["tasks"][task]["seed"]["controller_flags"])


def test_the_follow_mode_takes_the_breath_out_of_the_contact(study) -> None:
    """Following the breath while the hand steers: on every task the contact force swings less
    than with the same checked probe and no follow (the full study, means over operators: 1.5,
    1.7 and 1.2 N std against 3.0, 3.6 and 1.7 N on the view, the scan and the press), and the
    flag says it acted."""
    assert load_preset("follow").controller.follow.enabled
    assert not load_preset("checked").controller.follow.enabled
    _, out = study
    for operator, task, row, checked in _paired(out, "follow", "checked"):
        std, checked_std = float(row["contact_force_std_N"]), float(checked["contact_force_std_N"])
        # the press's std is mostly its own rise to 15 N, the breath's share smaller
        bound = checked_std if task == "press" else 0.8 * checked_std
        assert std < bound, (operator, task, std, checked_std)
        assert "following the breath" in row["controller_flags"], (operator, task)
        assert "following the breath" not in checked["controller_flags"]


def test_the_glide_mode_spares_the_hand_on_the_scan_and_steadies_the_image(study) -> None:
    """Glide on the follow mode: on every operator's scan the hand pushes less than with the follow
    alone (the full study: 66-79 % less than freehand against 49-60 %); quieter along the probe in
    contact, the image is steadier than the follow mode's on the whole (the full study: 0.62, 0.68
    and 0.74 of its jitter on the view, the scan and the press, per operator on average; the quick
    study's 0.51-0.77), no run's much less steady; and the breath is still followed."""
    assert load_preset("glide").controller.glide.enabled
    assert not load_preset("follow").controller.glide.enabled
    _, out = study
    ratios = []
    for operator, task, row, follow in _paired(out, "glide", "follow"):
        assert "following the breath" in row["controller_flags"], (operator, task)
        jitter = float(row["jitter_image_mm"]) / float(follow["jitter_image_mm"])
        assert jitter < 1.3, (operator, task, jitter)
        ratios.append(jitter)
        if task == "scan":
            effort = float(row["hand_force_rms_N"]) / float(follow["hand_force_rms_N"])
            assert effort < 0.85, (operator, effort)
    assert len(ratios) == OPERATORS * len(TASKS)
    assert float(np.mean(ratios)) < 0.85, ratios


def test_hold_on_release_holds_the_breathing_contact_and_hands_back(study) -> None:
    """In the hold mode the hand lets go in contact on the breathing patient and takes the handle
    again: the robot held the force (its std bounded, no contact lost) and handed back."""
    _, out = study
    summary = json.loads((out / "summary.json").read_text())
    assert set(summary["hold_on_release"]) == set(LETS_GO)
    hold = summary["hold_on_release"]["hold"]
    lets_go = {n for n, t in TASKS.items() if t.quick_hand_off is not None and not t.patient}
    assert set(hold) == lets_go == {"view", "press"}
    for task, entry in hold.items():
        for key in ("contact_force_std_N", "contact_losses", "handback_jump_m"):
            assert key in entry, (task, key)
        assert entry["contact_force_std_N"]["n"] == OPERATORS
        # the hands-off force against the force at the release: every operator has one, within
        # what the retake's band and the checked probe's error leave (the full study: -0.2 to
        # +1.7 N on the view, -2.2 to +0.7 N on the press; -0.4 to +2.9 and -4.6 to +0.2 N
        # without the retake, docs/decisions/0052-hold-retake.md); without the
        # check the hand's push left with its opening, 4.3-11.7 N of the press
        change = entry["contact_force_change_N"]
        assert change["n"] == OPERATORS
        assert -6.0 < change["min"] <= change["max"] < 3.5
        # held through at least a breath with the hand off, steadier than a robot that holds
        # still (1.5-2.1 N, docs/decisions/0039-clinical-study-world.md) and no contact lost
        assert entry["contact_force_std_N"]["max"] < 0.8, task
        assert entry["contact_losses"]["max"] == 0, task
        assert entry["hold_s"]["min"] > 4.0, task
    view = hold["view"]
    assert view["handbacks"]["min"] >= 1  # the next view's touch handed back
    assert 0.0 < view["handback_jump_m"]["max"] < 0.005
    # what the hand did not ask for, across the pressing direction
    assert view["handback_unasked_m"]["n"] == OPERATORS
    assert 0.0 <= view["handback_unasked_m"]["max"] < 0.005
    assert summary["targets"]["hold"]["hold_met"] is None  # a short study
    with (out / "runs.csv").open() as f:
        rows = [r for r in csv.DictReader(f) if r["mode"] == "hold" and r["task"] in lets_go]
    assert all("hand released in contact" in r["controller_flags"] for r in rows)
    assert all(r["hold_s"] == "" for r in _rows(out, FREEHAND))


def _keyed_runs(out: Path) -> dict[tuple[str, str, str], dict[str, str]]:
    """`runs.csv`'s rows by operator, task and mode."""
    with (out / "runs.csv").open() as f:
        return {(r["operator"], r["task"], r["mode"]): r for r in csv.DictReader(f)}


def _paired(out: Path, mode: str, against: str) -> list[tuple[str, str, dict, dict]]:
    """Each run of `mode` with the same operator's run of the same task in `against`: (operator,
    task, row, the other row)."""
    rows = _keyed_runs(out)
    return [(o, t, row, rows[(o, t, against)]) for (o, t, m), row in rows.items() if m == mode]


def _rows(out: Path, mode: str) -> list[dict[str, str]]:
    with (out / "runs.csv").open() as f:
        return [r for r in csv.DictReader(f) if r["mode"] == mode]


def test_the_probe_check_comes_first_and_takes_the_probe_sensors_error_off_the_hand(study) -> None:
    # the checked preset's runs begin with the probe check: the task, the breaths and the run's end
    # 20 s later than under the seed's, the online map on; so do the hold's
    keyed = dict(study_variants(SCENARIOS, 1, seed=5, quick=True))
    check = load_preset("checked").probe_check_s
    assert check == 20.0
    for task in TASKS:
        seed, checked = keyed[(0, task, "seed")], keyed[(0, task, "checked")]
        assert checked.duration_s == pytest.approx(seed.duration_s + check)
        for variant, preset, start in ((seed, "seed", 3.0), (checked, "checked", 3.0 + check)):
            assert variant.preset == preset
            scenario = load_scenario(
                variant.scenario, variant.overrides, variant.duration_s, preset=variant.preset
            )
            estimator = scenario.component_of_kind("estimator").params
            assert (estimator.probe_correction.kind == "online") == (preset == "checked")
            assert scenario.component_of_kind("operator").params.start_s == start
        assert keyed[(0, task, "hold")].preset == "hold"
        assert load_preset("hold").probe_check_s == check
    # Along the probe the hand pushed past the FSE103's gain error (0.15 sigma per axis) under the
    # seed's law; with the housing mapped, it does not: on the view and the press, whose force is
    # held, every operator's hand force is lower after the check (a quick study of three
    # operators: 1.2-1.4 N against 2.2-2.4 N RMS on the view, 0.9-2.0 N against 3.1-3.6 N on the
    # press).
    _, out = study
    seed = {(r["operator"], r["task"]): r for r in _rows(out, "seed")}
    for r in _rows(out, "checked"):
        if r["task"] in ("view", "press"):
            before = float(seed[(r["operator"], r["task"])]["hand_force_rms_N"])
            assert float(r["hand_force_rms_N"]) < 0.8 * before, (r["operator"], r["task"])


def test_an_operator_is_the_same_person_and_patient_in_every_run() -> None:
    keyed = study_variants(SCENARIOS, 2, seed=5, quick=True)
    by_operator: dict[int, set] = {}
    for (i, task, mode), variant in keyed:
        person = tuple(
            o
            for o in variant.overrides
            if o.startswith(("breathing.", "operator.stiffness", "operator.tremor"))
            and not o.startswith(("breathing.start_s", "breathing.away_s"))
        )
        by_operator.setdefault(i, set()).add((variant.seed, person))
        assert any(o.startswith(f"{MODES[mode].grip}.grip_stiffness") for o in variant.overrides)
        # the breathing starts with the task: on the robot after the rebias (and the probe check,
        # in the presets that have one), freehand at once; the recover task's patient moves away
        # 12 s after it
        start = 0.0
        if MODES[mode].assisted:
            start = 3.0 + load_preset(MODES[mode].preset).probe_check_s
        assert f"breathing.start_s={start}" in variant.overrides
        assert (f"breathing.away_s={start + 12.0}" in variant.overrides) == (task == "recover")
    assert all(len(kinds) == 2 for kinds in by_operator.values())  # the recover task's patient
    assert by_operator[0] != by_operator[1]


def test_a_set_reaches_every_assisted_mode_and_leaves_freehand_alone() -> None:
    """`--set` comes after each assisted mode's preset, so it wins over it (the seed preset's
    pinned slope too); each operator's draw and the task's settings still come after it."""
    texts = ("controller.translation.slope=[0.04,0.04,0.04]", "operator.force_kp=0.05")
    modes = study_modes(STUDY_PRESETS, texts)
    assert modes[FREEHAND] == MODES[FREEHAND]
    keyed = study_variants(SCENARIOS, 2, seed=5, quick=True, modes=modes)
    assert len(keyed) == len(study_variants(SCENARIOS, 2, seed=5, quick=True))
    for (_, _task, mode), variant in keyed:
        if not MODES[mode].assisted:
            assert not set(texts) & set(variant.overrides)
            continue
        assert variant.overrides[:2] == texts
        scenario = load_scenario(
            variant.scenario, variant.overrides, variant.duration_s, preset=variant.preset
        )
        slope = scenario.component_of_kind("controller").params.translation.slope
        assert list(slope) == [0.04, 0.04, 0.04]
        assert scenario.component_of_kind("operator").params.force_kp == 0.05


def test_the_patient_moves_away_and_the_contact_comes_back(study) -> None:
    """The recover task: the patient moves 15 mm away within 0.3 s while the view is held. The
    hand brings the contact back freehand and on the handle; with the hand off, the clinical
    preset's recovery does (the hold preset has none: its hold ends at rest)."""
    _, out = study
    rows = _keyed_runs(out)
    for (operator, task, mode), row in rows.items():
        if task != "recover":
            continue
        assert row["recovery_peak_N"] != "", (operator, mode)
        assert float(row["recovery_peak_N"]) < 25.0, (operator, mode)
        if mode in (FREEHAND, "seed", "glide", "clinical"):
            assert row["recovery_time_s"] != "", (operator, mode)
            assert float(row["recovery_time_s"]) < 3.0, (operator, mode)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["targets"]["clinical"]["recovery_never_back"] == 0


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (["--operators", "0"], r"--operators: expected an integer from 1 to 1000, got 0"),
        (["--scheduler", "bogus"], r"--scheduler bogus: expected a Dask scheduler's address"),
        (["--scheduler", "tcp://127.0.0.1:1"], r"--scheduler tcp://127.0.0.1:1: cannot reach"),
        (["--seed", "-1"], r"--seed: expected an integer >= 0, got -1"),
        (["--workers", "-2"], r"--workers: expected an integer >= 0, got -2"),
        (
            ["--set", "controller.translation.slop=1"],
            r"--set controller\.translation\.slop: unknown parameter of AdmittanceGains",
        ),
        (["--set", "controller"], r"--set controller: expected component\.parameter=value"),
        (
            ["--set", "operator.stiffness=300"],
            r"--set operator\.stiffness: the study sets it in every run \(each operator's draw",
        ),
        (["--set", "breathing.start_s=1"], r"--set breathing\.start_s: the study sets it"),
        (["--preset", "turbo"], r"preset 'turbo': unknown \(presets: seed, transparent, "),
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
