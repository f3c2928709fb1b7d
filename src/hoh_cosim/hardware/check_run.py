"""`hoh-cosim hw check`'s motion: rest, pushes on the probe tip, a few static poses, rest again.

The robot holds its start position throughout and only tilts the tool about it (the rig's workspace
is the start's), slowly (`CheckPlan`: 0.3 rad/s on a rig), through `directions` poses tilted by
`tilt_deg` about horizontal axes (`control.sequencer.tilted_orientations`, as `hw calibrate`), and
back. Every sample each sensor delivers is kept (`RecordingMailbox`), with the windows in which the
robot held still; `hoh_cosim.hardware.check` judges them. The order:

    rest      hold still `rest_s`: noise at rest, the zero
    poses     move, settle `settle_s`, hold `hold_s`, for each pose
    rest      back at the start, hold still `rest_s`: the zero again, for the drift
    pushes    the operator is told to push the probe's tip (`push`), the robot holds still for
              `push_window_s` (skipped without a probe sensor); last, since a housing's play
              keeps part of a push (seed 3.B.2) and would pass for drift

The robot is stopped on every way out (`finally`), and a cycle in which the robot reports a
problem or moves while it should hold still ends the check (RunError).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from hoh_cosim.control.frames import matrix_to_rotvec
from hoh_cosim.control.sequencer import SequencerParams, servo_twist, tilted_orientations
from hoh_cosim.control.vectors import Rot3, Vec
from hoh_cosim.errors import ConfigError, RunError
from hoh_cosim.hardware.calibrate import STILL_SPEED_M_S, _Cycles
from hoh_cosim.hardware.check import CheckRecord, Claims, SensorVerdict, Stream, Window, judge
from hoh_cosim.hardware.robot import Robot
from hoh_cosim.hardware.runner import _realtime_interpreter
from hoh_cosim.hardware.streams import Mailbox, Sample, now

__all__ = ["REHEARSAL_PLAN", "CheckPlan", "RecordingMailbox", "check_on_rig", "record_check"]


class RecordingMailbox(Mailbox):
    """A mailbox that also keeps every sample published into it, for the check's judgement."""

    def __init__(self) -> None:
        super().__init__()
        self._kept: list[Sample] = []
        self._keep_lock = threading.Lock()

    def publish(self, sample: Sample) -> None:
        super().publish(sample)
        with self._keep_lock:
            self._kept.append(sample)

    def kept(self) -> list[Sample]:
        with self._keep_lock:
            return list(self._kept)


@dataclass(frozen=True)
class CheckPlan:
    """How long each part of the check lasts and how the robot moves (a rig's defaults: about
    45 s in all, within the issue's 2 minutes)."""

    rest_s: float = 3.0
    push_window_s: float = 8.0
    tilt_deg: float = 45.0
    directions: int = 3
    settle_s: float = 0.5
    hold_s: float = 2.0
    max_angular_speed: float = 0.3  # [rad/s]
    gain_orientation: float = 2.0  # [1/s]
    angle_tolerance_deg: float = 0.5
    move_timeout_s: float = 15.0

    def sequencer(self) -> SequencerParams:
        return SequencerParams(
            tilts=1,
            tilt_min_deg=self.tilt_deg,
            tilt_max_deg=self.tilt_deg,
            directions=self.directions,
            gain_orientation=self.gain_orientation,
            max_angular_speed=self.max_angular_speed,
        )


REHEARSAL_PLAN = CheckPlan(
    rest_s=1.0,
    push_window_s=7.0,
    settle_s=0.2,
    hold_s=0.5,
    max_angular_speed=1.0,
    gain_orientation=4.0,
    angle_tolerance_deg=1.0,
)
"""The rehearsal's: short rests and holds (enough samples for every figure at 50 Hz), faster
moves against the emulated arm; the pushes as long (the emulated hand's three 2 s pushes)."""


def _hold(cycles: _Cycles, seconds: float, R_TS: Rot3, kind: str) -> Window:
    """Hold still for `seconds`; the window with the wrist's mean orientation."""
    start = now()
    R_sum, n = np.zeros((3, 3)), 0
    while now() - start < seconds:
        state = cycles.step(np.zeros(6))
        speed = float(np.linalg.norm(state.twist_B[:3]))
        if speed > STILL_SPEED_M_S:
            raise RunError(f"the robot moved at {1e3 * speed:.1f} mm/s while holding still")
        R_sum += state.R_BT @ R_TS
        n += 1
    U, _, Vt = np.linalg.svd(R_sum / max(n, 1))
    return Window(kind, start, now(), U @ Vt)


def _move(cycles: _Cycles, p_target: Vec, R_target: Rot3, plan: CheckPlan) -> None:
    params = plan.sequencer()
    tolerance = np.radians(plan.angle_tolerance_deg)
    deadline = time.monotonic() + plan.move_timeout_s
    state = cycles.step(np.zeros(6))
    while True:
        error_p = float(np.linalg.norm(p_target - state.p_BT_B))
        error_R = float(np.linalg.norm(matrix_to_rotvec(R_target @ state.R_BT.T)))
        if error_p < 1e-3 and error_R < tolerance:
            return
        if time.monotonic() > deadline:
            raise RunError(
                f"the robot did not reach the check's pose within {plan.move_timeout_s:g} s "
                f"({1e3 * error_p:.1f} mm, {np.degrees(error_R):.2f}° away)"
            )
        state = cycles.step(servo_twist(p_target, R_target, state.p_BT_B, state.R_BT, params))


def _first_data(sources: list[Any], timeout_s: float = 5.0) -> None:
    deadline = time.monotonic() + timeout_s
    for source in sources:
        while source.mailbox.latest()[1] == 0:
            if time.monotonic() > deadline:
                raise RunError(
                    f"{source.describe()}: no data within {timeout_s:g} s "
                    f"({source.mailbox.error or 'nothing arrived'})"
                )
            time.sleep(0.01)


def record_check(
    robot: Robot,
    ft: Any,
    probe: Any | None,
    *,
    R_TS: Rot3,
    plan: CheckPlan,
    push: Callable[[], None],
    acceleration: float = 1.0,
    realtime_priority: int | None = None,
    announce: Callable[[str], None] = lambda message: None,
) -> CheckRecord:
    """Drive the check and record it. `ft` and `probe` are sources built on `RecordingMailbox`es;
    `push` tells the operator to push the probe's tip (in a rehearsal, the emulated hand). The
    cycles run as the runner's do (`runner._realtime_interpreter`: with `realtime_priority`,
    SCHED_FIFO for the loop and its readers), since the robot's watchdog wants every one."""
    sources = [s for s in (ft, probe) if s is not None]
    robot.connect()
    for source in sources:
        source.start()
    try:
        _first_data(sources)
        helpers = getattr(robot, "helper_thread_ids", ())
        with _realtime_interpreter(realtime_priority, announce, helpers):
            windows = _drive(robot, probe, R_TS, plan, push, acceleration, announce)
    finally:
        robot.stop()
        for source in sources:
            source.stop()
        robot.close()
    ft_stream = Stream.of(ft.mailbox.kept(), ft.mailbox.stats.bad_frames, axes=6)
    probe_stream = (
        Stream.of(probe.mailbox.kept(), probe.mailbox.stats.bad_frames, axes=3)
        if probe is not None
        else None
    )
    return CheckRecord(ft_stream, probe_stream, tuple(windows))


def _drive(
    robot: Robot,
    probe: Any | None,
    R_TS: Rot3,
    plan: CheckPlan,
    push: Callable[[], None],
    acceleration: float,
    announce: Callable[[str], None],
) -> list[Window]:
    """The check's motion (module docstring); its windows."""
    windows: list[Window] = []
    cycles = _Cycles(robot, acceleration)
    start = cycles.step(np.zeros(6))
    p_start, R_start = start.p_BT_B.copy(), start.R_BT.copy()
    announce("hold still: noise at rest and the zero")
    windows.append(_hold(cycles, plan.rest_s, R_TS, "rest"))
    poses = tilted_orientations(R_start, plan.sequencer())
    for i, R_target in enumerate(poses):
        announce(f"pose {i + 1} of {len(poses)}")
        _move(cycles, p_start, R_target, plan)
        _hold(cycles, plan.settle_s, R_TS, "settle")
        windows.append(_hold(cycles, plan.hold_s, R_TS, "pose"))
    announce("back to the start")
    _move(cycles, p_start, R_start, plan)
    _hold(cycles, plan.settle_s, R_TS, "settle")
    windows.append(_hold(cycles, plan.rest_s, R_TS, "rest"))
    if probe is not None:
        announce("push the probe's tip a few times, now, in different directions")
        push()
        windows.append(_hold(cycles, plan.push_window_s, R_TS, "pushes"))
        announce("pushes done: hands off")
    return windows


def check_on_rig(
    config: Any,
    probe_sensor: str | None,
    *,
    plan: CheckPlan | None = None,
    announce: Callable[[str], None] = lambda message: None,
) -> tuple[list[SensorVerdict], dict[str, Any]]:
    """The check on the rig `config` describes (`hardware.config.HardwareConfig`): its robot over
    RTDE, its FT-150 stream, its probe sensor; the rig's claims from its file and calibration.
    The operator is told on the terminal when to push the probe's tip."""
    from hoh_cosim.calibration import read_calibration
    from hoh_cosim.hardware.ft150 import FT150Stream
    from hoh_cosim.hardware.probe_port import probe_port
    from hoh_cosim.hardware.robot import RtdeRobot

    rig_probe = "none" if config.probe is None else config.probe.sensor
    if probe_sensor is not None and probe_sensor != rig_probe:
        raise ConfigError(
            f"--probe-sensor: {config.path} has probe sensor {rig_probe}, got {probe_sensor}"
        )
    if config.calibration is None:
        raise ConfigError(f"{config.path}: calibration: missing (run 'hoh-cosim hw calibrate')")
    calibration = read_calibration(config.calibration)
    claims = Claims(
        ft_rate_hz=1.0 / config.estimator.ft_packet_period_s,
        probe_rate_hz=1.0 / config.estimator.probe_packet_period_s,
        R_SP=config.estimator.R_SP,
        tool=calibration.tool,
        g_B=calibration.gravity_B,
    )
    robot = RtdeRobot(
        config.robot.host,
        frequency_hz=config.robot.frequency_hz,
        watchdog_hz=config.robot.watchdog_hz,
    )
    ft = FT150Stream(config.ft150.host, config.ft150.port, mailbox=RecordingMailbox())
    probe = None if config.probe is None else probe_port(config.probe, mailbox=RecordingMailbox())
    started = time.monotonic()
    record = record_check(
        robot,
        ft,
        probe,
        R_TS=config.robot.R_TS,
        plan=plan or CheckPlan(),
        push=lambda: None,  # the operator reads the announcement
        acceleration=config.robot.acceleration,
        realtime_priority=config.robot.realtime_priority,
        announce=announce,
    )
    about = {
        "kind": "robot",
        "robot": config.robot.host,
        "probe_sensor": rig_probe,
        "duration_s": round(time.monotonic() - started, 2),
    }
    return judge(record, claims, rig_probe), about
