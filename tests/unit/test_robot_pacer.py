"""The cycle pacer and the robot state's verdict, without a robot."""

from __future__ import annotations

import numpy as np
import pytest

from hoh_cosim.hardware import robot
from hoh_cosim.hardware.robot import ROBOT_MODE_RUNNING, Pacer, RobotState, named_problem


def state(**changes) -> RobotState:
    values = dict(
        p_BT_B=np.zeros(3),
        R_BT=np.eye(3),
        twist_B=np.zeros(6),
        robot_mode=ROBOT_MODE_RUNNING,
        safety_mode=1,
        protective_stop=False,
        emergency_stop=False,
        program_running=True,
        timestamp_s=0.0,
    )
    values.update(changes)
    return RobotState(**values)


@pytest.mark.parametrize(
    ("changes", "problem"),
    [
        ({}, None),
        ({"emergency_stop": True, "protective_stop": True}, "the robot is emergency-stopped"),
        ({"protective_stop": True}, "the robot is in a protective stop"),
        ({"program_running": False}, "the control program on the robot is not running"),
        ({"robot_mode": 5}, "the robot is not running (robot mode 5)"),
    ],
)
def test_the_state_says_why_the_robot_cannot_be_commanded(changes, problem):
    assert state(**changes).problem() == problem


class _Readings:
    """A robot whose successive `state()` readings are given: the two RTDE streams' race."""

    period_s = 0.002

    def __init__(self, *readings: RobotState) -> None:
        self.readings = list(readings)

    def state(self) -> RobotState:
        return self.readings.pop(0) if len(self.readings) > 1 else self.readings[0]


def test_a_stopped_program_is_read_again_for_the_stop_that_stopped_it():
    stopped = state(program_running=False)
    later = _Readings(stopped, state(program_running=False, protective_stop=True))
    assert named_problem(later, stopped) == "the robot is in a protective stop"
    # no reason comes: the stopped program is the cause, after the settling time and no longer
    alone = _Readings(stopped)
    assert named_problem(alone, stopped, settle_s=0.02) == (
        "the control program on the robot is not running"
    )
    # a named stop or a running robot is not read again
    assert (
        named_problem(_Readings(), state(emergency_stop=True)) == "the robot is emergency-stopped"
    )
    assert named_problem(_Readings(), state()) is None


class SimulatedClock:
    """The `time` of hoh_cosim.hardware.robot on a simulated clock, so that a pacer test neither
    waits on the wall clock nor depends on how busy the machine is: `sleep` advances it exactly,
    and every reading advances it by `tick_s` (the pacer spins on the clock until its target)."""

    def __init__(self, tick_s: float = 1e-6) -> None:
        self.now = 1000.0
        self.tick_s = tick_s

    def perf_counter(self) -> float:
        self.now += self.tick_s
        return self.now

    monotonic = perf_counter

    def sleep(self, seconds: float) -> None:
        assert seconds >= 0.0
        self.now += seconds


@pytest.fixture
def clock(monkeypatch) -> SimulatedClock:
    simulated = SimulatedClock()
    monkeypatch.setattr(robot, "time", simulated)
    return simulated


def test_the_pacer_keeps_an_absolute_schedule(clock):
    period = 0.004
    pacer = Pacer(period)
    start = clock.perf_counter()
    assert pacer.wait() == 0.0  # the first cycle starts the schedule
    for _ in range(50):
        clock.sleep(0.25 * period)  # the cycle's work
        pacer.wait()
    elapsed = clock.perf_counter() - start
    # 50 periods after the first start, not 50 periods plus the work between the waits
    assert elapsed == pytest.approx(50 * period, abs=0.5 * period)
    assert pacer.overruns == 0


def test_a_late_cycle_is_reported_and_an_overrun_restarts_the_schedule(clock):
    period = 0.002
    pacer = Pacer(period)
    pacer.wait()
    pacer.wait()
    clock.sleep(5 * period)  # the work of this cycle takes five periods
    late = pacer.wait()
    assert late > 3 * period
    assert pacer.overruns == 1
    # the schedule restarted from now: the next cycle is on time, not four periods behind
    assert pacer.wait() < period
