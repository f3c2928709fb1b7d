"""`hoh-cosim hw calibrate`: the seed's gravity calibration on the robot (seed 000, 3.D).

The robot visits static orientations (by default the 32 of `SequencerParams`: tilts of 15, 30, 45
and 60° in 8 horizontal directions from where it starts, at the same position), and at each one:
servos there (the sequencer's law, speed-limited), waits for the arm to settle, and averages
`samples` FT-150 samples (1000, the seed's count) while checking that it holds still. Then it returns
to the start, identifies the tool with the foundation's routine (eq. 4-8) and writes
`calibration.json` atomically with `poses.csv` beside it (readable by `hoh-cosim identify-gravity`).
The robot is stopped on every way out.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hoh_cosim.calibration import write_calibration, write_poses_csv
from hoh_cosim.control.frames import matrix_to_rotvec
from hoh_cosim.control.gravity import GravityCalibration, identify_gravity
from hoh_cosim.control.sequencer import SequencerParams, servo_twist, tilted_orientations
from hoh_cosim.control.vectors import GRAVITY_B, Rot3, Vec
from hoh_cosim.errors import IdentificationError, RunError
from hoh_cosim.hardware.robot import Robot, named_problem
from hoh_cosim.hardware.runner import _realtime_interpreter
from hoh_cosim.hardware.streams import Mailbox

__all__ = ["CalibrationRun", "calibrate", "save"]

POSITION_TOLERANCE_M = 5e-4
ANGLE_TOLERANCE_RAD = np.radians(0.2)
STILL_SPEED_M_S = 0.002


@dataclass
class CalibrationRun:
    calibration: GravityCalibration
    R_BS: np.ndarray  # (n, 3, 3)
    wrench_S: np.ndarray  # (n, 6) averaged raw readings
    samples: list[int]  # samples averaged per pose


class _Cycles:
    """The robot at its rate: every cycle a twist is sent and the watchdog kicked."""

    def __init__(self, robot: Robot, acceleration: float) -> None:
        self.robot = robot
        self.pacer = robot.pacer()
        self.acceleration = acceleration

    def step(self, twist: Vec) -> Any:
        self.pacer.wait()
        state = self.robot.state()
        problem = named_problem(self.robot, state)
        if problem is not None:
            raise RunError(f"{self.robot.describe()}: {problem}")
        self.robot.speed_l(twist, self.acceleration)
        self.robot.kick_watchdog()
        return state


def _move(
    cycles: _Cycles, p_target: Vec, R_target: Rot3, params: SequencerParams, timeout_s: float
) -> None:
    deadline = time.monotonic() + timeout_s
    state = cycles.step(np.zeros(6))
    while True:
        error_p = float(np.linalg.norm(p_target - state.p_BT_B))
        error_R = float(np.linalg.norm(matrix_to_rotvec(R_target @ state.R_BT.T)))
        if error_p < POSITION_TOLERANCE_M and error_R < ANGLE_TOLERANCE_RAD:
            return
        if time.monotonic() > deadline:
            raise RunError(
                f"the robot did not reach the pose within {timeout_s:g} s "
                f"({1e3 * error_p:.1f} mm, {np.degrees(error_R):.2f}° away)"
            )
        state = cycles.step(servo_twist(p_target, R_target, state.p_BT_B, state.R_BT, params))


def _average(
    cycles: _Cycles, ft: Mailbox, samples: int, R_TS: Rot3, timeout_s: float
) -> tuple[Vec, Rot3, int]:
    _, seen = ft.latest()
    values, R_sum = [], np.zeros((3, 3))
    deadline = time.monotonic() + timeout_s
    while len(values) < samples:
        state = cycles.step(np.zeros(6))
        speed = float(np.linalg.norm(state.twist_B[:3]))
        if speed > STILL_SPEED_M_S:
            raise RunError(f"the robot moved at {1e3 * speed:.1f} mm/s while averaging")
        sample, count = ft.latest()
        if count > seen and sample is not None:
            if not np.all(np.isfinite(sample.values)):
                raise RunError("the FT-150 sent non-finite values while averaging")
            values.append(sample.values)
            R_sum += state.R_BT @ R_TS
            seen = count
        if time.monotonic() > deadline:
            raise RunError(
                f"only {len(values)} of {samples} FT-150 samples in {timeout_s:g} s "
                f"({ft.error or 'the stream is slow'})"
            )
    U, _, Vt = np.linalg.svd(R_sum / len(values))
    return np.mean(values, axis=0), U @ Vt, len(values)


def _poses(
    cycles: _Cycles,
    ft: Any,
    R_TS: Rot3,
    params: SequencerParams,
    samples: int,
    announce: Callable[[str], None],
) -> tuple[list[Rot3], list[Vec], list[int]]:
    """Each pose in turn, back to the start: the orientations, mean wrenches and sample counts."""
    start = cycles.step(np.zeros(6))
    p_start, R_start = start.p_BT_B.copy(), start.R_BT.copy()
    targets = tilted_orientations(R_start, params)
    rate = ft.mailbox.stats.rate_hz
    hold_timeout = max(10.0, 3.0 * samples / rate) if np.isfinite(rate) else 60.0
    R_list, wrench_list, counts = [], [], []
    for i, R_target in enumerate(targets):
        announce(f"pose {i + 1} of {len(targets)}")
        _move(cycles, p_start, R_target, params, timeout_s=3.0 * params.move_s + 5.0)
        settle_end = time.monotonic() + params.settle_s
        while time.monotonic() < settle_end:
            cycles.step(np.zeros(6))
        mean, R_BS, n = _average(cycles, ft.mailbox, samples, R_TS, hold_timeout)
        R_list.append(R_BS)
        wrench_list.append(mean)
        counts.append(n)
    announce("back to the start")
    _move(cycles, p_start, R_start, params, timeout_s=3.0 * params.move_s + 5.0)
    return R_list, wrench_list, counts


def calibrate(
    robot: Robot,
    ft: Any,
    *,
    R_TS: Rot3,
    params: SequencerParams | None = None,
    samples: int = 1000,
    acceleration: float = 1.0,
    g_B: Vec = GRAVITY_B,
    realtime_priority: int | None = None,
    announce: Callable[[str], None] = lambda message: None,
) -> CalibrationRun:
    """Drive the poses, average, identify. `ft` is a started-or-not FT-150 source. The cycles
    run as the runner's do (with `realtime_priority`, SCHED_FIFO for the loop and its readers),
    since the robot's watchdog wants every one: a busy machine otherwise starves the loop past it
    and the program on the robot stops."""
    params = params or SequencerParams()
    robot.connect()
    ft.start()
    try:
        deadline = time.monotonic() + 5.0
        while ft.mailbox.latest()[1] == 0:
            if time.monotonic() > deadline:
                raise RunError(f"{ft.describe()}: no data within 5 s ({ft.mailbox.error})")
            time.sleep(0.01)
        helpers = getattr(robot, "helper_thread_ids", ())
        with _realtime_interpreter(realtime_priority, announce, helpers):
            R_list, wrench_list, counts = _poses(
                _Cycles(robot, acceleration), ft, R_TS, params, samples, announce
            )
    finally:
        robot.stop()
        ft.stop()
        robot.close()
    R_BS = np.array(R_list)
    wrench = np.array(wrench_list)
    try:
        cal = identify_gravity(R_BS, wrench, g_B)
    except IdentificationError as exc:
        raise RunError(f"identification failed: {exc}") from None
    return CalibrationRun(cal, R_BS, wrench, counts)


def save(run: CalibrationRun, out: Path) -> Path:
    """calibration.json at `out` and poses.csv beside it; returns the poses file's path."""
    write_calibration(out, run.calibration)
    poses = out.with_name("poses.csv")
    write_poses_csv(poses, run.R_BS, run.wrench_S)
    return poses
