"""`hoh-cosim hw check --rehearse`: the commissioning check with the real drivers against the
rehearsal world, healthy and with the issue's planted faults, each caught with its cause named;
the session refused on a failing sensor unless overridden by name; bad input in one line, exit 2.

Four rehearsals (about 70 s in all): a healthy rig with its FSE103, the wrist's three faults at once
without a probe sensor, and the FSE103's two faults. The 50 healthy rehearsals and each fault alone
are `hoh-cosim hw check --rehearse --repeat 50` (docs/decisions/0071-hw-check.md)."""

from __future__ import annotations

import json

import pytest

from hoh_cosim.cli import main
from tests.xdist_groups import REAL_TIME


def _check(tmp_path, capsys, *args: str) -> tuple[int, str, str, dict | None]:
    out = tmp_path / "check.json"
    status = main(["hw", "check", "--rehearse", "--out", str(out), *args])
    captured = capsys.readouterr()
    report = json.loads(out.read_text()) if out.exists() else None
    return status, captured.out, captured.err, report


@REAL_TIME
def test_a_healthy_rig_passes_and_the_report_has_its_keys(tmp_path, capsys):
    status, out, err, report = _check(tmp_path, capsys, "--seed", "7")
    assert status == 0, out + err
    lines = [line for line in out.splitlines() if line.startswith(("FT-150", "FSE103"))]
    assert len(lines) == 2, out
    assert lines[0].startswith("FT-150: ok (rate ")
    assert lines[1].startswith("FSE103: ok (rate ")
    assert "run sessions with the probe check" in lines[1]  # the seed's housing redirects force
    assert set(report) == {
        *("kind", "probe_sensor", "faults", "seed", "duration_s", "ok", "sensors"),
        *("overrides", "session", "refused_by"),
    }
    assert report["session"] == "allowed"
    assert report["ok"] is True
    assert set(report["sensors"]) == {"ft150", "fse103"}
    assert set(report["sensors"]["fse103"]["findings"]) == {
        *("rate", "regularity", "noise", "drift", "pushes", "linearity", "response", "frame"),
    }
    assert report["duration_s"] < 120.0  # the 2 minutes, with a rig's holds shortened


@REAL_TIME
def test_the_wrists_faults_are_named_and_refuse_a_session_unless_overridden(tmp_path, capsys):
    faults = ("--fault", "ft_sign_flipped", "--fault", "ft_dead_channel", "--fault", "ft_rate_low")
    status, out, err, report = _check(
        tmp_path, capsys, "--probe-sensor", "none", *faults, "--override", "ft150"
    )
    assert status == 0, out + err  # overridden by name
    line = next(line for line in out.splitlines() if line.startswith("FT-150"))
    assert line.startswith("FT-150: FAIL rate 50.0 Hz against 200 Hz ±20 %"), line
    assert "Fx sign flipped: gain -" in line
    assert "Fy flat: σ 0 N at rest" in line
    assert line.endswith("(overridden)")
    assert report["session"] == "allowed"
    assert report["overrides"] == ["ft150"]
    failed = {k for k, f in report["sensors"]["ft150"]["findings"].items() if not f["ok"]}
    assert {"rate", "regularity", "noise", "axis signs"} <= failed


@REAL_TIME
@pytest.mark.parametrize(
    ("fault", "cause"),
    [
        ("probe_frame_rotated", "frame off eq. 2 by "),
        (
            "fse103_nonlinear_housing",
            "the housing is nonlinear beyond what the online map corrects; run the probe check",
        ),
    ],
)
def test_the_probe_sensors_faults_are_named_and_refuse_a_session(tmp_path, capsys, fault, cause):
    status, out, err, report = _check(tmp_path, capsys, "--fault", fault)
    assert status == 1, out
    assert "FT-150: ok" in out
    line = next(line for line in out.splitlines() if line.startswith("FSE103"))
    assert line.startswith("FSE103: FAIL "), line
    assert cause in line
    assert "session refused: fse103 failed (--override fse103 to run anyway)" in err
    assert report["session"] == "refused"
    assert report["refused_by"] == ["fse103"]


@REAL_TIME
def test_the_load_cell_passes_healthy_and_is_named_saturated_with_its_figure(tmp_path, capsys):
    status, out, err, _ = _check(tmp_path, capsys, "--probe-sensor", "loadcell", "--seed", "3")
    assert status == 0, out + err
    assert "load cell: ok (rate " in out
    status, out, err, report = _check(
        tmp_path, capsys, "--probe-sensor", "loadcell", "--fault", "loadcell_saturated"
    )
    assert status == 1, out
    line = next(line for line in out.splitlines() if line.startswith("load cell"))
    assert line.startswith("load cell: FAIL saturated: pushes of "), line
    counts = float(line.split("moved it ")[1].split(" counts")[0])
    needed = float(line.split("against >= ")[1].split(" ")[0])
    assert counts < needed / 2, line
    assert report["refused_by"] == ["loadcell"]


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--fault", "loadcel_saturated"], "--fault: expected one of ft_sign_flipped, "),
        (["--probe-sensor", "ati"], "--probe-sensor: expected one of fse103, loadcell, none, got"),
        (
            ["--probe-sensor", "none", "--fault", "probe_frame_rotated"],
            "--fault probe_frame_rotated: needs --probe-sensor fse103, got none",
        ),
        (["--repeat", "-1"], "--repeat: expected N >= 1 healthy runs and no --fault, got -1"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(tmp_path, capsys, args, message):
    status = main(["hw", "check", "--rehearse", "--out", str(tmp_path / "c.json"), *args])
    err = capsys.readouterr().err
    assert status == 2
    assert message in err
    assert len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "c.json").exists()


def test_a_check_needs_a_rig_file_or_a_rehearsal(capsys):
    assert main(["hw", "check"]) == 2
    assert (
        "hw check: give CONFIG.yaml for a robot, or --rehearse, not both" in capsys.readouterr().err
    )


def test_a_rig_check_refuses_a_rig_without_calibration_before_it_moves(tmp_path, capsys):
    rig = tmp_path / "rig.yaml"
    rig.write_text("robot:\n  host: 192.0.2.1\nprobe: null\n")
    status = main(["hw", "check", str(rig), "--out", str(tmp_path / "c.json")])
    err = capsys.readouterr().err
    assert status == 2
    assert "rig.yaml: calibration: missing (run 'hoh-cosim hw calibrate')" in err
    assert main(["hw", "check", str(rig), "--probe-sensor", "fse103"]) == 2
    assert "--probe-sensor: " in capsys.readouterr().err
    assert main(["hw", "check", str(rig), "--fault", "ft_rate_low"]) == 2
    assert "--fault: a fault is planted only in a rehearsal" in capsys.readouterr().err
