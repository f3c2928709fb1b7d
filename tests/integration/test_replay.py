"""Replaying a session log (hoh_cosim.hardware.replay and `hoh-cosim replay`) on a real log: one
short rehearsal (the real runner, drivers and session log against emulated devices, in processes of
their own) recorded once for the module, then replayed as it is, with other settings, cut short,
and through the command line.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pytest

from hoh_cosim.cli import main
from hoh_cosim.control.controller import ControllerParams
from hoh_cosim.control.estimator import EstimatorParams
from hoh_cosim.errors import ConfigError, InputFileError
from hoh_cosim.hardware.replay import replay
from hoh_cosim.hardware.session_log import SessionLog, read_session
from hoh_cosim.params import leaves
from tests.xdist_groups import REAL_TIME

if TYPE_CHECKING:
    from hoh_cosim.rehearsal.rehearse import RehearsalResult

pytestmark = [
    pytest.mark.skipif(sys.platform == "win32", reason="the rehearsal needs POSIX ptys"),
    REAL_TIME,  # the recording
]
pytest.importorskip("mcap")
pytest.importorskip("serial")

SECONDS = 4.0
RATE_HZ = 500.0  # rehearse's default robot rate
CYCLES = round(SECONDS * RATE_HZ)
PNG = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def rehearsal(tmp_path_factory) -> RehearsalResult:
    """The one rehearsal of this module: 4 s of the circle task after a 100-sample rebias."""
    from hoh_cosim.rehearsal.rehearse import Rehearsal, rehearse  # POSIX only (ptys)

    path = tmp_path_factory.mktemp("rehearsal") / "s.mcap"
    return rehearse(Rehearsal(seconds=SECONDS, log_path=path, rebias_samples=100))


@pytest.fixture(scope="module")
def log(rehearsal) -> Path:
    return rehearsal.log_path


@pytest.fixture(scope="module")
def cycles(rehearsal) -> int:
    """The cycles recorded: CYCLES unless the session ended early (see the first test)."""
    assert rehearsal.session.cycles > CYCLES // 2, rehearsal.session.cause
    return rehearsal.session.cycles


@pytest.fixture(scope="module")
def truncated(log, tmp_path_factory) -> Path:
    """The rehearsal's log with only its first 60 % of bytes, as a killed runner may leave it."""
    path = tmp_path_factory.mktemp("truncated") / "cut.mcap"
    data = log.read_bytes()
    path.write_bytes(data[: int(0.6 * len(data))])
    return path


@pytest.fixture(autouse=True)
def _in_tmp_path(tmp_path, monkeypatch):
    """A default runs/replay-<name>, or anything else written by mistake, lands in tmp_path."""
    monkeypatch.chdir(tmp_path)


def run_cli(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    status = main(argv)
    out, err = capsys.readouterr()
    return status, out, err


def assert_one_line_rejection(status: int, out: str, err: str) -> None:
    assert status == 2, (status, err)
    assert "Traceback" not in err
    assert err.count("\n") == 1, err
    assert err.endswith("\n"), err
    assert err.startswith("hoh-cosim: "), err
    assert out == ""


def make_log(path: Path, *, rows: int, parameters: bool) -> Path:
    """A small log written by SessionLog itself: `rows` cycles of plausible values, with or
    without the 'parameters' event that replay needs."""
    log = SessionLog(path, {"kind": "test", "R_TS": np.diag([1.0, -1.0, -1.0])}).start()
    try:
        log.event(0, 0.0, "rebias", "done")
        if parameters:
            detail = {
                "period_s": 0.002,
                "estimator": {leaf.name: leaf.value for leaf in leaves(EstimatorParams())},
                "controller": {leaf.name: leaf.value for leaf in leaves(ControllerParams())},
            }
            log.event(0, 0.0, "parameters", json.dumps(detail))
        for k in range(rows):
            log.row.start(k, k * 0.002, True, True)
            log.row.set("/robot.rotvec_BT", np.zeros(3))
            log.row.set("/ft150.count", k + 1)
            log.row.set("/fse103.count", k // 4 + 1)
            log.cycle()
        log.event(max(rows - 1, 0), max(rows - 1, 0) * 0.002, "end", "done")
    finally:
        log.close()
    return path


# --- the recording ----------------------------------------------------------------------------


MACHINE_EVENTS = ("remeasure", "starved")
"""The events a busy machine adds to a clean session: its timing, not the session's."""


def test_the_rehearsal_recorded_a_whole_clean_session(rehearsal, log):
    """The recording the other tests replay. (A real-time session: on a machine too busy to keep
    500 Hz it may end early on a stale stream; the other tests then replay what was recorded.)"""
    report = f"{rehearsal.session.cause}; {rehearsal.session.timing.report()}"
    assert rehearsal.session.clean, report
    assert rehearsal.session.cycles == CYCLES, report
    session = read_session(log)
    assert session.complete is True
    assert len(session.messages["/command"]) == CYCLES
    events = [e["event"] for e in session.messages["/events"]]
    # the rebias, the parameters, the mode (guiding once rebiased), the end; a busy machine may
    # add what it did to the session's timing (a rate measured again at the rebias, a starved
    # stream), nothing else
    told = [e for e in events if e not in MACHINE_EVENTS]
    assert told == ["rebias", "parameters", "mode", "end"], events


# --- replaying as recorded ------------------------------------------------------------------------


def test_replay_without_overrides_reproduces_the_recording_exactly(log, cycles):
    result = replay(log)
    assert len(result.t) == cycles
    # what replay calls recorded is what the log holds, cycle by cycle
    session = read_session(log)
    recorded_t = [m["t"] for m in session.messages["/command"]]  # to the log's 1 ns
    np.testing.assert_allclose(result.t, recorded_t, rtol=0, atol=1e-9)
    np.testing.assert_allclose(result.t, np.arange(cycles) / RATE_HZ, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(result.old["F_hand_B"], session.series("/estimate", "F_hand_B"))
    np.testing.assert_array_equal(result.old["twist_B"], session.series("/command", "twist_B"))
    # and the hand pushed the robot: the comparison is not of zeros (how far it moved depends on
    # how busy the machine was: a rehearsal runs in real time)
    assert np.max(np.linalg.norm(result.old["twist_B"][:, :3], axis=1)) > 0.0
    assert np.max(np.linalg.norm(result.old["F_hand_B"], axis=1)) > 0.5

    assert np.max(np.abs(result.new["F_hand_B"] - result.old["F_hand_B"])) == 0.0
    assert np.max(np.abs(result.new["twist_B"] - result.old["twist_B"])) == 0.0
    np.testing.assert_array_equal(result.new["status"], result.old["status"])


def test_replay_summary_says_the_replay_matches(log, cycles):
    summary = replay(log).summary()
    assert summary["cycles"] == cycles
    assert summary["complete_log"] is True
    assert summary["twist_difference_max_m_s"] == 0.0
    assert summary["hand_force_difference_rms_N"] == 0.0
    assert summary["speed_rms_new_m_s"] == summary["speed_rms_old_m_s"] > 0.0
    assert summary["stops_new"] == summary["stops_old"]


def test_replay_runs_with_the_recorded_parameters(log):
    result = replay(log)
    session = read_session(log)
    recorded = json.loads(
        next(e for e in session.messages["/events"] if e["event"] == "parameters")["detail"]
    )
    assert recorded["period_s"] == 1.0 / RATE_HZ
    assert {leaf.name: leaf.value for leaf in leaves(result.estimator)} == recorded["estimator"]
    assert {leaf.name: leaf.value for leaf in leaves(result.controller)} == recorded["controller"]
    # the session's own: the rebias, not the defaults
    assert result.estimator.ft_rebias_packets == 0
    assert not np.array_equal(result.estimator.ft_bias, EstimatorParams().ft_bias)


# --- replaying with other settings ---------------------------------------------------------------


def test_replay_with_another_filter_differs_on_the_same_cycles(log, cycles):
    as_recorded = replay(log)
    result = replay(log, ["estimator.filter=butterworth"])
    assert result.estimator.filter == "butterworth"
    assert as_recorded.estimator.filter != "butterworth"
    assert len(result.t) == cycles
    np.testing.assert_array_equal(result.t, as_recorded.t)
    # the recording stays what it was
    np.testing.assert_array_equal(result.old["twist_B"], as_recorded.old["twist_B"])
    dv = np.abs(result.new["twist_B"] - result.old["twist_B"])
    assert np.max(dv) > 0.0
    assert np.max(np.abs(result.new["F_hand_B"] - result.old["F_hand_B"])) > 0.01
    summary = result.summary()
    assert summary["cycles"] == cycles
    assert summary["twist_difference_max_m_s"] > 0.0


def test_replay_with_contact_compensation_off_sets_only_that(log):
    result = replay(log, ["controller.contact_compensation=false"])
    assert result.controller.contact_compensation is False
    recorded = replay(log).controller
    changed = {
        leaf.name
        for leaf, other in zip(leaves(result.controller), leaves(recorded), strict=True)
        if leaf.value != other.value
    }
    assert changed == {"contact_compensation"}
    # the estimator is untouched by a controller setting
    np.testing.assert_array_equal(result.new["F_hand_B"], result.old["F_hand_B"])


@pytest.mark.parametrize(
    ("override", "message"),
    [
        (
            "nope.x=1",
            "--set nope.x=1: expected estimator.parameter=value or controller.parameter=value",
        ),
        (
            "controller.nope=1",
            "--set controller.nope: unknown parameter of ControllerParams (one of: translation, "
            "rotation, contact_compensation, compensation_onset_N, contact_torque, virtual_fixture, "
            "fixture_threshold_N, "
            "fixture_up_B, fixture_normal, limits, release, variable, passivity, hold, follow, glide, "
            "recovery, touch_down_N, lift_off_N, use_probe, ft_period_s, probe_period_s)",
        ),
        (
            "estimator.filter=median",
            "--set estimator.filter: expected one of kalman, steady_kalman, lead_lowpass, "
            "butterworth, "
            "one_euro, none, got 'median'",
        ),
    ],
)
def test_a_bad_override_is_a_one_line_config_error(log, override, message):
    with pytest.raises(ConfigError) as info:
        replay(log, [override])
    assert str(info.value) == message


# --- the command line ---------------------------------------------------------------------------


def test_cli_replay_writes_the_summary_and_the_plot(log, tmp_path, capsys, cycles):
    out = tmp_path / "replay"
    status, stdout, stderr = run_cli(["replay", str(log), "--out", str(out)], capsys)
    assert status == 0, stderr
    assert stderr == ""
    summary = json.loads((out / "replay.json").read_text(encoding="utf-8"))
    assert summary["cycles"] == cycles
    assert summary["complete_log"] is True
    assert summary["twist_difference_max_m_s"] == 0.0
    assert summary["hand_force_difference_rms_N"] == 0.0
    png = (out / "replay.png").read_bytes()
    assert png.startswith(PNG)
    assert len(png) > 10_000
    assert f"wrote {out}" in stdout
    assert "twist_difference_max_m_s" in stdout


def test_cli_replay_with_an_override_reports_the_difference(log, tmp_path, capsys, cycles):
    out = tmp_path / "replay"
    argv = ["replay", str(log), "--set", "estimator.filter=butterworth", "--out", str(out)]
    status, _, stderr = run_cli(argv, capsys)
    assert status == 0, stderr
    summary = json.loads((out / "replay.json").read_text(encoding="utf-8"))
    assert summary["cycles"] == cycles
    assert summary["twist_difference_max_m_s"] > 0.0


@pytest.mark.parametrize(
    ("override", "message"),
    [
        (
            "nope.x=1",
            "--set nope.x=1: expected estimator.parameter=value or controller.parameter=value",
        ),
        ("controller.nope=1", "--set controller.nope: unknown parameter of ControllerParams ("),
    ],
    ids=["unknown-block", "unknown-parameter"],
)
def test_cli_replay_with_a_bad_override_exits_2_with_one_line(
    log, tmp_path, capsys, override, message
):
    out = tmp_path / "replay"
    argv = ["replay", str(log), "--set", override, "--out", str(out)]
    status, stdout, stderr = run_cli(argv, capsys)
    assert_one_line_rejection(status, stdout, stderr)
    assert stderr.startswith(f"hoh-cosim: {message}"), stderr
    assert not out.exists()


# --- logs replay cannot use ----------------------------------------------------------------------


def test_a_log_without_its_parameters_is_a_one_line_input_file_error(tmp_path, capsys):
    path = make_log(tmp_path / "no-parameters.mcap", rows=50, parameters=False)
    session = read_session(path)
    assert len(session.messages["/command"]) == 50  # rows, but no parameters
    expected = f"{path}: /events: no 'parameters' event: the session ended before its loop"
    with pytest.raises(InputFileError) as info:
        replay(path)
    assert str(info.value) == expected

    out = tmp_path / "replay"
    status, stdout, stderr = run_cli(["replay", str(path), "--out", str(out)], capsys)
    assert_one_line_rejection(status, stdout, stderr)
    assert stderr == f"hoh-cosim: {expected}\n"
    assert not out.exists()


def test_a_log_without_cycles_is_a_one_line_input_file_error(tmp_path):
    path = make_log(tmp_path / "no-cycles.mcap", rows=0, parameters=True)
    with pytest.raises(InputFileError) as info:
        replay(path)
    assert str(info.value) == f"{path}: /command: no control cycle was recorded"


def test_a_file_that_is_not_a_log_exits_2_with_one_line(tmp_path, capsys):
    path = tmp_path / "notes.mcap"
    path.write_text("not a session log\n", encoding="utf-8")
    status, stdout, stderr = run_cli(["replay", str(path), "--out", str(tmp_path / "r")], capsys)
    assert_one_line_rejection(status, stdout, stderr)
    assert stderr.startswith(f"hoh-cosim: {path}: not a session log"), stderr


# --- a log cut short ----------------------------------------------------------------------------


def test_a_truncated_log_replays_what_is_there(log, truncated, cycles):
    whole = replay(log)
    part = replay(truncated)
    assert part.session.complete is False
    n = len(part.t)
    assert cycles // 4 < n < cycles
    # the cycles there are, from the first on, replayed as in the whole log
    np.testing.assert_array_equal(part.t, whole.t[:n])
    for name in ("F_hand_B", "twist_B", "status"):
        np.testing.assert_array_equal(part.old[name], whole.old[name][:n])
        np.testing.assert_array_equal(part.new[name], whole.new[name][:n])
    summary = part.summary()
    assert summary["complete_log"] is False
    assert summary["cycles"] == n
    assert summary["twist_difference_max_m_s"] == 0.0


def test_cli_replay_of_a_truncated_log_notes_that_it_ends_early(
    truncated, tmp_path, capsys, cycles
):
    out = tmp_path / "replay"
    status, stdout, stderr = run_cli(["replay", str(truncated), "--out", str(out)], capsys)
    assert status == 0, stderr
    assert stderr == (
        f"note: {truncated} ends early (the session was cut off); replayed what is there\n"
    )
    summary = json.loads((out / "replay.json").read_text(encoding="utf-8"))
    assert summary["complete_log"] is False
    assert 0 < summary["cycles"] < cycles
    assert (out / "replay.png").read_bytes().startswith(PNG)
    assert f"wrote {out}" in stdout
