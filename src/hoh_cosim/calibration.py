"""Gravity-calibration files: the static-pose CSV in, `calibration.json` out (and back in).

POSES.csv has one row per static pose and the header exactly `rx,ry,rz,fx,fy,fz,tx,ty,tz`: the rotation
vector of R_BS [rad] (the wrist sensor's orientation in the base frame) and the raw averaged F/T
reading in the sensor frame [N, N·m]. Every problem is reported as one line that names the file and the
row and column, or the reason.
"""

from __future__ import annotations

import csv
import json
import math
import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from hoh_cosim.control.frames import rotvec_to_matrix
from hoh_cosim.control.gravity import GravityCalibration
from hoh_cosim.control.vectors import Vec, frozen
from hoh_cosim.errors import InputFileError

__all__ = [
    "CALIBRATION_FORMAT",
    "POSE_COLUMNS",
    "POSE_VALUE_LIMIT",
    "calibration_to_dict",
    "poses_csv_text",
    "read_calibration",
    "read_poses_csv",
    "write_calibration",
    "write_json_atomic",
    "write_poses_csv",
]

POSE_COLUMNS = ("rx", "ry", "rz", "fx", "fy", "fz", "tx", "ty", "tz")
WRENCH_COMPONENTS = ("fx", "fy", "fz", "tx", "ty", "tz")
CALIBRATION_FORMAT = "hoh-cosim gravity calibration"
POSE_VALUE_LIMIT = 1e6
"""The largest magnitude of a POSES.csv value. A rotation vector is an angle of a few radians and
no F/T sensor reads a million N or N·m: a larger number is a mistake (a unit, a column), and the
rotation or the least-squares sums of one beyond 1e154 overflow."""
CALIBRATION_VERSION = 1


def read_poses_csv(path: str | os.PathLike[str]) -> tuple[Vec, Vec]:
    """R_BS as (n, 3, 3) and the wrenches as (n, 6) from a POSES.csv file."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise InputFileError(path, "", "no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputFileError(path, "", f"cannot read: {exc}") from None
    reader = csv.reader(text.splitlines())
    try:
        rows = list(reader)
    except csv.Error as exc:  # a field longer than the csv module's limit (128 KiB)
        raise InputFileError(path, f"line {reader.line_num}", f"not CSV: {exc}") from None
    if not rows or not any(cell.strip() for cell in rows[0]):
        raise InputFileError(
            path, "line 1", f"expected the header {','.join(POSE_COLUMNS)}, got an empty line"
        )
    header = [cell.strip() for cell in rows[0]]
    if header != list(POSE_COLUMNS):
        missing = [c for c in POSE_COLUMNS if c not in header]
        extra = [c for c in header if c not in POSE_COLUMNS]
        if missing:
            detail = f"missing column {missing[0]!r}"
        elif extra:
            detail = f"unexpected column {extra[0]!r}"
        else:
            detail = f"columns in the wrong order: {','.join(header)}"
        raise InputFileError(
            path, "line 1", f"header must be exactly {','.join(POSE_COLUMNS)}: {detail}"
        )
    values = []
    for line_no, row in enumerate(rows[1:], start=2):
        if not any(cell.strip() for cell in row):
            continue  # blank line
        row_no = len(values) + 1
        where = f"row {row_no} (line {line_no})"
        if len(row) != len(POSE_COLUMNS):
            raise InputFileError(
                path, where, f"expected {len(POSE_COLUMNS)} values, got {len(row)}"
            )
        numbers = []
        for column, cell in zip(POSE_COLUMNS, row, strict=True):
            try:
                x = float(cell)
            except ValueError:
                raise InputFileError(
                    path, f"{where}, column {column}", f"expected a number, got {cell.strip()!r}"
                ) from None
            if not math.isfinite(x):
                raise InputFileError(
                    path,
                    f"{where}, column {column}",
                    f"expected a finite number, got {cell.strip()!r}",
                )
            if abs(x) > POSE_VALUE_LIMIT:
                raise InputFileError(
                    path,
                    f"{where}, column {column}",
                    f"expected a number within ±{POSE_VALUE_LIMIT:g}, got {cell.strip()!r}",
                )
            numbers.append(x)
        values.append(numbers)
    if not values:
        raise InputFileError(path, "", "no poses: the file has a header and no rows")
    data = np.array(values)
    R_BS = np.array([rotvec_to_matrix(r) for r in data[:, :3]])
    return R_BS, data[:, 3:]


def poses_csv_text(R_BS: Vec, wrench: Vec) -> str:
    """POSES.csv content: one row per pose, the rotation vector of R_BS and the averaged reading."""
    from hoh_cosim.control.frames import matrix_to_rotvec

    lines = [",".join(POSE_COLUMNS)]
    for R, w in zip(R_BS, wrench, strict=True):
        values = np.concatenate([matrix_to_rotvec(R), w])
        lines.append(",".join(f"{v:.10g}" for v in values))
    return "\n".join(lines) + "\n"


def write_poses_csv(path: str | os.PathLike[str], R_BS: Vec, wrench: Vec) -> None:
    """POSES.csv written atomically (write beside, then rename)."""
    path = Path(path)
    fd, part = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent or ".")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(poses_csv_text(R_BS, wrench))
        os.replace(part, path)
    except BaseException:
        Path(part).unlink(missing_ok=True)
        raise


def calibration_to_dict(cal: GravityCalibration) -> dict[str, Any]:
    """The `calibration.json` content."""

    def listed(v: Vec) -> list[float]:
        return [float(x) for x in v]

    return {
        "format": CALIBRATION_FORMAT,
        "version": CALIBRATION_VERSION,
        "mass_kg": cal.mass_kg,
        "com_m": listed(cal.com_m),
        "force_bias_N": listed(cal.force_bias_N),
        "torque_bias_Nm": listed(cal.torque_bias_Nm),
        "mass_se_kg": cal.mass_se_kg,
        "com_se_m": listed(cal.com_se_m),
        "force_bias_se_N": listed(cal.force_bias_se_N),
        "torque_bias_se_Nm": listed(cal.torque_bias_se_Nm),
        "condition_number": cal.condition_number,
        "n_poses": cal.n_poses,
        "gravity_B_m_s2": listed(cal.gravity_B),
        "residuals": {
            "components": list(WRENCH_COMPONENTS),
            "units": ["N", "N", "N", "N.m", "N.m", "N.m"],
            "before": "reading minus the identified bias: the tool weight compensation must remove",
            "after": "reading minus the bias and the tool-weight model",
            "rms_before": listed(cal.residual_rms_before),
            "max_abs_before": listed(cal.residual_max_before),
            "rms_after": listed(cal.residual_rms_after),
            "max_abs_after": listed(cal.residual_max_after),
        },
    }


def write_json_atomic(path: str | os.PathLike[str], content: dict[str, Any]) -> None:
    """Write JSON to a temporary file beside `path`, then rename: readers never see half a file."""
    path = Path(path)
    directory = path.parent if str(path.parent) else Path(".")
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=directory)
    except OSError as exc:
        raise InputFileError(path, "", f"cannot write: {exc.strerror or exc}") from None
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            json.dump(content, f, indent=2)
            f.write("\n")
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_calibration(path: str | os.PathLike[str], cal: GravityCalibration) -> None:
    write_json_atomic(path, calibration_to_dict(cal))


def _vector(path: Path, data: dict[str, Any], key: str, size: int) -> Vec:
    value = data.get(key)
    if not isinstance(value, list) or len(value) != size:
        got = f"{len(value)} values" if isinstance(value, list) else repr(value)
        raise InputFileError(path, key, f"expected a list of {size} numbers, got {got}")
    try:
        out = np.array([float(x) for x in value])
    except (TypeError, ValueError, OverflowError):  # OverflowError: an integer beyond a float
        raise InputFileError(path, key, f"expected numbers, got {value!r}") from None
    if not np.all(np.isfinite(out)):
        raise InputFileError(path, key, f"expected finite numbers, got {value!r}")
    return frozen(out)


def _number(path: Path, data: dict[str, Any], key: str) -> float:
    value = data.get(key)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not _finite(value):
        raise InputFileError(path, key, f"expected a finite number, got {value!r}")
    return float(value)


def _finite(value: float) -> bool:
    try:
        return math.isfinite(value)
    except OverflowError:  # an integer beyond the largest float
        return False


def read_calibration(path: str | os.PathLike[str]) -> GravityCalibration:
    """A `calibration.json` written by `write_calibration`, checked key by key."""
    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputFileError(path, "", "no such file") from None
    except json.JSONDecodeError as exc:
        raise InputFileError(
            path, f"line {exc.lineno}, column {exc.colno}", f"not valid JSON: {exc.msg}"
        ) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputFileError(path, "", f"cannot read: {exc}") from None
    except RecursionError:  # the json module parses nested arrays and objects by recursion
        raise InputFileError(path, "", "not valid JSON: nested too deeply") from None
    except ValueError as exc:  # a number of more digits than Python converts (4300)
        raise InputFileError(path, "", f"not valid JSON: {exc}") from None
    if not isinstance(data, dict) or data.get("format") != CALIBRATION_FORMAT:
        raise InputFileError(
            path,
            "format",
            f"expected {CALIBRATION_FORMAT!r}, got "
            f"{data.get('format') if isinstance(data, dict) else data!r}",
        )
    if data.get("version") != CALIBRATION_VERSION:
        raise InputFileError(
            path, "version", f"expected {CALIBRATION_VERSION}, got {data.get('version')!r}"
        )
    residuals = data.get("residuals")
    if not isinstance(residuals, dict):
        raise InputFileError(path, "residuals", f"expected an object, got {residuals!r}")
    n_poses = data.get("n_poses")
    if isinstance(n_poses, bool) or not isinstance(n_poses, int) or n_poses < 1:
        raise InputFileError(path, "n_poses", f"expected a positive integer, got {n_poses!r}")

    def res(key: str) -> Vec:
        try:
            return _vector(path, residuals, key, 6)
        except InputFileError as exc:
            raise InputFileError(path, f"residuals.{key}", exc.problem) from None

    return GravityCalibration(
        mass_kg=_number(path, data, "mass_kg"),
        com_m=_vector(path, data, "com_m", 3),
        force_bias_N=_vector(path, data, "force_bias_N", 3),
        torque_bias_Nm=_vector(path, data, "torque_bias_Nm", 3),
        mass_se_kg=_number(path, data, "mass_se_kg"),
        com_se_m=_vector(path, data, "com_se_m", 3),
        force_bias_se_N=_vector(path, data, "force_bias_se_N", 3),
        torque_bias_se_Nm=_vector(path, data, "torque_bias_se_Nm", 3),
        condition_number=_number(path, data, "condition_number"),
        n_poses=n_poses,
        gravity_B=_vector(path, data, "gravity_B_m_s2", 3),
        residual_rms_before=res("rms_before"),
        residual_max_before=res("max_abs_before"),
        residual_rms_after=res("rms_after"),
        residual_max_after=res("max_abs_after"),
    )
