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


def _watch_run(position, seconds=6.0):
    law = VariableAdmittance()
    F = np.array([3.0, 0.0, 0.0])
    for k in range(int(seconds / DT)):
        t = k * DT
        law.step(t, F, SLOPE, ETA, np.array(position(t)))
    return law


def test_an_oscillation_lowers_the_slope_and_a_circle_does_not():
    """The oscillation watch: 40 mm/s at 2 Hz (a stiff hand's oscillation) takes the slope down;
    a 4 cm circle every 4 s (63 mm/s at 0.25 Hz) leaves it at 1."""
    w = 2 * np.pi * 2.0
    shaky = _watch_run(lambda t: [0.04 / w * np.sin(w * t), 0.0, 0.3])
    assert shaky.oscillation_m_s > shaky.params.oscillation_threshold_m_s
    assert shaky.stability < 0.2
    wc = 2 * np.pi * 0.25

    def circle(t):  # the operator's circle: the angular speed ramps up over the first second
        phi = 0.5 * wc * t * t if t < 1.0 else wc * (t - 0.5)
        return [0.04 * np.cos(phi), 0.04 * np.sin(phi), 0.3]

    calm = _watch_run(circle)
    assert calm.stability == 1.0
    assert calm.oscillation_m_s < 0.5 * calm.params.oscillation_threshold_m_s


def test_the_start_of_a_firm_push_is_not_an_oscillation():
    """A step of the tip's speed to 66 mm/s (a 5 N push, ramped at 1 m/s²) swings the
    high-passed velocity once: large, but no oscillation; the slope stays."""

    def push(t):
        if t < 1.0:
            return [0.0, 0.0, 0.3]
        ramp = 0.066  # [s] to reach 66 mm/s at 1 m/s²
        s = t - 1.0
        x = 0.5 * s * s if s < ramp else 0.5 * ramp * ramp + ramp * (s - ramp)
        return [x, 0.0, 0.3]

    run = _watch_run(push)
    assert run.stability == 1.0
    assert run.swings < run.params.oscillation_swings
