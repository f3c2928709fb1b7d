"""`hoh-cosim identify-gravity` and the command's exit statuses, run as a user runs them."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from hoh_cosim.calibration import read_calibration
from tests.data.make_poses import make as make_poses_csv

DATA = Path(__file__).resolve().parents[1] / "data"
POSES = DATA / "poses_seed_tool.csv"


def hoh_cosim(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    exe = shutil.which("hoh-cosim", path=os.path.dirname(sys.executable))
    command = [exe] if exe else [sys.executable, "-m", "hoh_cosim"]
    return subprocess.run([*command, *args], capture_output=True, text=True, cwd=cwd, timeout=120)


def test_reference_poses_file_is_what_its_script_makes():
    assert POSES.read_text() == make_poses_csv()


def test_identifies_the_seed_tool_and_writes_calibration_json(tmp_path):
    out = tmp_path / "calibration.json"
    result = hoh_cosim("identify-gravity", str(POSES), "--out", str(out))
    assert result.returncode == 0, result.stderr
    assert "mass            0.4855" in result.stdout
    assert "(mg = 4.763" in result.stdout
    assert f"wrote {out}" in result.stdout
    data = json.loads(out.read_text())
    for key in (
        "mass_kg",
        "com_m",
        "force_bias_N",
        "torque_bias_Nm",
        "mass_se_kg",
        "com_se_m",
        "force_bias_se_N",
        "torque_bias_se_Nm",
        "condition_number",
        "residuals",
    ):
        assert key in data
    cal = read_calibration(out)
    assert cal.mass_kg * 9.81 == pytest.approx(4.7631, abs=0.005)
    np.testing.assert_allclose(cal.com_m[:2], [-0.01250, -0.00033], atol=2e-4)
    assert cal.n_poses == 32
    assert np.all(cal.residual_rms_after < cal.residual_rms_before[:] + 1e-12)
    assert not list(tmp_path.glob(".*.tmp"))  # the atomic write left nothing behind


def test_gravity_option_changes_the_identified_mass(tmp_path):
    # the same readings under 2x gravity mean half the mass
    out = tmp_path / "cal.json"
    result = hoh_cosim("identify-gravity", str(POSES), "--out", str(out), "--gravity", "0,0,-19.62")
    assert result.returncode == 0, result.stderr
    assert read_calibration(out).mass_kg == pytest.approx(4.7631 / 19.62, abs=0.001)


HEADER = "rx,ry,rz,fx,fy,fz,tx,ty,tz"


def _rows(n=12):
    return POSES.read_text().splitlines()[1 : n + 1]


BAD_FILES = {
    "missing_column": (
        "rx,ry,rz,fx,fy,fz,tx,ty\n1,2,3,4,5,6,7,8\n",
        "line 1: header must be exactly rx,ry,rz,fx,fy,fz,tx,ty,tz: missing column 'tz'",
    ),
    "extra_column": (
        HEADER + ",w\n",
        "line 1: header must be exactly rx,ry,rz,fx,fy,fz,tx,ty,tz: unexpected column 'w'",
    ),
    "wrong_order": (
        "ry,rx,rz,fx,fy,fz,tx,ty,tz\n",
        "line 1: header must be exactly rx,ry,rz,fx,fy,fz,tx,ty,tz: columns in the wrong order",
    ),
    "not_a_number": (
        HEADER + "\n" + "\n".join(_rows(3)) + "\n0,0,0,1,abc,0,0,0,0\n",
        "row 4 (line 5), column fy: expected a number, got 'abc'",
    ),
    "nan": (
        HEADER + "\n0,0,0,1,2,nan,0,0,0\n",
        "row 1 (line 2), column fz: expected a finite number, got 'nan'",
    ),
    "short_row": (
        HEADER + "\n" + _rows(1)[0] + "\n0,0,0,1,2,3,4,5\n",
        "row 2 (line 3): expected 9 values, got 8",
    ),
    "empty": ("", "line 1: expected the header rx,ry,rz,fx,fy,fz,tx,ty,tz, got an empty line"),
    "header_only": (HEADER + "\n", "no poses: the file has a header and no rows"),
    "too_few_poses": (
        HEADER + "\n" + "\n".join(_rows(4)) + "\n",
        "need at least 10 poses for the 10 unknowns (mass, centre of mass, force and "
        "torque bias), got 4",
    ),
    "degenerate": (
        HEADER + "\n" + "\n".join([_rows(1)[0]] * 12) + "\n",
        "the orientations are too alike to separate the mass from the force bias",
    ),
}


@pytest.mark.parametrize("case", sorted(BAD_FILES))
def test_bad_pose_file_exits_2_with_one_line_and_writes_nothing(tmp_path, case):
    content, message = BAD_FILES[case]
    poses = tmp_path / "poses.csv"
    poses.write_text(content)
    out = tmp_path / "calibration.json"
    result = hoh_cosim("identify-gravity", str(poses), "--out", str(out))
    assert result.returncode == 2
    assert result.stdout == ""
    assert result.stderr.count("\n") == 1, result.stderr
    assert result.stderr.startswith(f"hoh-cosim: {poses}: ")
    assert message in result.stderr
    assert "Traceback" not in result.stderr
    assert not out.exists()


def test_missing_pose_file(tmp_path):
    result = hoh_cosim("identify-gravity", str(tmp_path / "nope.csv"))
    assert result.returncode == 2
    assert result.stderr == f"hoh-cosim: {tmp_path / 'nope.csv'}: no such file\n"


def test_unwritable_output_exits_2(tmp_path):
    out = tmp_path / "no" / "such" / "dir" / "cal.json"
    result = hoh_cosim("identify-gravity", str(POSES), "--out", str(out))
    assert result.returncode == 2
    assert result.stderr.startswith(f"hoh-cosim: {out}: cannot write:")
    assert result.stderr.count("\n") == 1


def test_bad_gravity_option_exits_2():
    result = hoh_cosim("identify-gravity", str(POSES), "--gravity", "down")
    assert result.returncode == 2
    assert "expected three comma-separated numbers like 0,0,-9.81, got 'down'" in result.stderr
    assert result.stderr.count("\n") == 1


def test_a_scenario_that_is_not_there_exits_2_and_writes_nothing(tmp_path):
    result = hoh_cosim("scenarios/circles.yaml", cwd=tmp_path)
    assert result.returncode == 2
    assert result.stderr == "hoh-cosim: scenarios/circles.yaml: no such file\n"
    assert list(tmp_path.iterdir()) == []


def test_version():
    result = hoh_cosim("--version")
    assert result.returncode == 0
    assert result.stdout.startswith("hoh-cosim ")
