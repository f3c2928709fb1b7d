"""Against a real UR controller or URSim: opt-in with UR_HOST set (nothing moves).

UR_HOST=192.168.1.10 python -m pytest -m hardware tests/integration/test_ur_hardware.py
"""

from __future__ import annotations

import os

import numpy as np
import pytest

from hoh_cosim.hardware.robot import RtdeRobot

UR_HOST = os.environ.get("UR_HOST")

pytestmark = [
    pytest.mark.hardware,
    pytest.mark.skipif(not UR_HOST, reason="needs a UR controller: set UR_HOST"),
]


def test_state_is_read_and_a_zero_command_is_taken_and_the_robot_stopped():
    robot = RtdeRobot(UR_HOST, watchdog_hz=10.0)
    robot.connect()
    try:
        state = robot.state()
        assert state.problem() is None, state.problem()
        np.testing.assert_allclose(state.R_BT @ state.R_BT.T, np.eye(3), atol=1e-6)
        assert robot.period_s in (0.002, 0.008)
        pacer = robot.pacer()
        for _ in range(50):
            pacer.wait()
            robot.speed_l(np.zeros(6), 0.5)
            robot.kick_watchdog()
    finally:
        robot.stop()
        robot.close()
