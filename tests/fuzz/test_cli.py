"""The command line on fuzzed files of each kind: exit status 2, the loader's one line on stderr
(naming the file), no traceback, nothing on stdout, and no output written that would claim
success. The files are mutations (`tests.fuzz.targets`) that their loader refuses."""

from __future__ import annotations

import re
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

from hoh_cosim.calibration import read_calibration, read_poses_csv
from hoh_cosim.cli import main
from hoh_cosim.cosim.scenario import load_scenario
from hoh_cosim.errors import HohError
from hoh_cosim.hardware.config import load_config
from hoh_cosim.hardware.replay import replay
from hoh_cosim.study.sweep import load_sweep
from tests.fuzz.targets import TARGETS, billion_laughs, bounded


def refusal(load: Callable[[Path], Any], path: Path) -> str | None:
    """The loader's message for the file, or None if it loads."""
    try:
        load(path)
    except HohError as exc:
        return str(exc)
    return None


def assert_refused(
    status: int, capsys: pytest.CaptureFixture[str], message: str, *unwritten: Path
) -> None:
    out, err = capsys.readouterr()
    assert status == 2, err
    assert err == f"hoh-cosim: {message}\n"
    assert "Traceback" not in err
    assert out == ""
    for path in unwritten:
        assert not path.exists(), path


@bounded(5)
@given(data=TARGETS["scenario"].strategy(None))
def test_run_refuses_a_fuzzed_scenario(workspace, capsys, data):
    path = workspace.file(".yaml", data)
    message = refusal(load_scenario, path)
    assume(message is not None)
    out = workspace.directory / "run"
    status = main([str(path), "--out", str(out), "--engine", "inprocess", "--quiet"])
    assert_refused(status, capsys, message, out)


@bounded(4)
@given(data=TARGETS["sweep"].strategy(None))
def test_sweep_refuses_a_fuzzed_sweep(workspace, capsys, data):
    path = workspace.file(".yaml", data)
    message = refusal(load_sweep, path)
    assume(message is not None)
    out = workspace.directory / "sweep"
    status = main(["sweep", str(path), "--out", str(out), "--workers", "0", "--quiet"])
    assert_refused(status, capsys, message, out)


@bounded(5)
@given(data=TARGETS["rig"].strategy(None))
def test_hw_run_refuses_a_fuzzed_rig_file(workspace, capsys, data):
    path = workspace.file(".yaml", data)
    message = refusal(load_config, path)
    assume(message is not None)
    log = workspace.directory / "session.mcap"
    status = main(["hw", "run", str(path), "--log", str(log)])
    assert_refused(status, capsys, message, log)


@bounded(5)
@given(data=TARGETS["calibration"].strategy(None))
def test_hw_run_refuses_a_fuzzed_calibration(workspace, capsys, data):
    path = workspace.file(".json", data)
    message = refusal(read_calibration, path)
    assume(message is not None)
    rig = workspace.directory / "rig.yaml"
    rig.write_text(f"robot: {{host: 127.0.0.1}}\nprobe: null\ncalibration: {path.name}\n")
    log = workspace.directory / "session.mcap"
    status = main(["hw", "run", str(rig), "--log", str(log)])
    assert_refused(status, capsys, message, log)


@bounded(5)
@given(data=TARGETS["poses"].strategy(None))
def test_identify_gravity_refuses_a_fuzzed_pose_file(workspace, capsys, data):
    path = workspace.file(".csv", data)
    message = refusal(read_poses_csv, path)
    assume(message is not None)
    out = workspace.directory / "calibration.json"
    status = main(["identify-gravity", str(path), "--out", str(out)])
    assert_refused(status, capsys, message, out)


@bounded(5)
@given(st.data())
def test_replay_refuses_a_log_cut_too_short(workspace, capsys, data):
    seed = workspace.session_seed.read_bytes()
    path = workspace.file(".mcap", seed[: data.draw(st.integers(0, len(seed) // 3), label="cut")])
    message = refusal(replay, path)
    assume(message is not None)
    out = workspace.directory / "replay"
    status = main(["replay", str(path), "--out", str(out)])
    assert_refused(status, capsys, message, out)


def test_the_installed_command_refuses_a_billion_laughs(tmp_path):
    """The real process, as a user runs it: aliases that expand to 10**9 values."""
    path = tmp_path / "laughs.yaml"
    path.write_text(f"name: {billion_laughs(9)}\nduration_s: 1\ncomponents: {{plant: {{}}}}\n")
    result = subprocess.run(
        [sys.executable, "-m", "hoh_cosim", str(path), "--out", str(tmp_path / "run")],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=tmp_path,
    )
    assert result.returncode == 2, result.stderr
    assert re.fullmatch(
        rf"hoh-cosim: {re.escape(str(path))}: name\[\d\]: aliases expand the document beyond 10 "
        r"times its size \(more than \d+ values and characters\)\n",
        result.stderr,
    ), result.stderr
    assert result.stdout == ""
    assert not (tmp_path / "run").exists()
