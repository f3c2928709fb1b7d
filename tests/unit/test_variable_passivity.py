"""The variable admittance law (control/variable_admittance.py) and the passivity observer and
controller with its energy tank (control/passivity.py)."""

from __future__ import annotations

import numpy as np
import pytest

from hoh_cosim.control.admittance import deadband_linear
from hoh_cosim.control.controller import ControllerParams, HandGuidingController
from hoh_cosim.control.passivity import PassivityController, PassivityParams
from hoh_cosim.control.supervisor import Status
from hoh_cosim.control.variable_admittance import VariableAdmittance, VariableAdmittanceParams
from hoh_cosim.errors import ConfigError
from tests.estimates import controller_inputs

SLOPE = np.array([0.0125, 0.0125, 0.0125])
ETA = np.array([0.95, 0.95, 0.25])
DT = 0.008


def test_without_intent_gain_the_law_is_eq10(rng):
    law = VariableAdmittance(VariableAdmittanceParams(intent_gain=0.0))
    for k in range(200):
        F = rng.normal(scale=5.0, size=3)
        np.testing.assert_array_equal(
            law.step(k * DT, F, SLOPE, ETA), deadband_linear(F, SLOPE, ETA)
        )


def test_the_slope_rises_while_the_push_grows_and_falls_while_it_eases():
    law = VariableAdmittance()
    law.step(0.0, np.array([3.0, 0, 0]), SLOPE, ETA)
    growing = law.step(DT, np.array([4.0, 0, 0]), SLOPE, ETA)
    assert law.factor > 1.0
    assert growing[0] > deadband_linear(np.array([4.0, 0, 0]), SLOPE, ETA)[0]
    easing = law.step(2 * DT, np.array([3.0, 0, 0]), SLOPE, ETA)
    assert law.factor < 1.0
    assert 0.0 < easing[0] < deadband_linear(np.array([3.0, 0, 0]), SLOPE, ETA)[0]
    # bounded, and steady when the push is
    p = law.params
    for k in range(3, 10):
        law.step(k * DT, np.array([3.0, 0, 0]), SLOPE, ETA)
    assert law.factor == 1.0
    assert p.slope_min <= law.factor <= p.slope_max


def test_variable_law_parameters_are_checked():
    with pytest.raises(ConfigError, match=r"slope_min <= 1 <= slope_max expected, got 1.2 and 1.3"):
        VariableAdmittanceParams(slope_min=1.2)


def test_the_tank_stays_full_while_the_robot_yields():
    pc = PassivityController(PassivityParams(enabled=True, tank_max_J=0.02))
    p = np.zeros(3)
    F = np.array([5.0, 0.0, 0.0])
    for k in range(100):
        pc.observe(k * DT, F, p)
        v, acted = pc.control(np.array([0.05, 0, 0]), F, DT)
        assert not acted
        p = p + v * DT
    assert pc.energy_J == pytest.approx(0.02)


def test_the_controller_dissipates_what_the_robot_gave_back():
    """The robot moves against the hand's force (a delayed loop giving energy back): the tank
    drains, and the PC then makes the command yield along the force until F · v >= 0."""
    pc = PassivityController(PassivityParams(enabled=True, tank_max_J=0.001))
    F = np.array([5.0, 0.0, 0.0])
    p = np.zeros(3)
    acted_any = False
    for k in range(50):
        dt = pc.observe(k * DT, F, p)
        p = p + np.array([-0.02, 0.0, 0.0]) * DT  # the tip runs against the push
        v, acted = pc.control(np.array([-0.02, 0.01, 0.0]), F, dt)
        if acted:
            acted_any = True
            # the tank plus this command's flow is back at zero; the sideways part is untouched
            assert pc.energy_J + float(F @ v) * dt == pytest.approx(0.0, abs=1e-12)
            assert v[1] == 0.01
    assert acted_any
    assert pc.energy_J < 0.0


def test_the_controller_flags_the_passivity_controller():
    ctl = HandGuidingController(
        ControllerParams(passivity=PassivityParams(enabled=True, tank_max_J=1e-4))
    )
    flags = 0
    for k in range(100):
        # the estimate pushes +x while the measured tip runs -x: energy flows out of the robot
        out = ctl.step(
            k * DT,
            DT,
            controller_inputs(F_hand_B=[3.0, 0, 0], p_BT_B=[0.3 - 0.02 * k * DT, 0.0, 0.3]),
        )
        flags |= int(out["status"][0])
    assert flags & int(Status.PASSIVITY)
