"""The operator's additions for the clinical study: the intrinsic hand, the feed-forward of a known
weight, physiological tremor, the grip's torque and the view task. All off by default."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hoh_cosim.control.frames import rotvec_to_matrix
from hoh_cosim.errors import ConfigError
from plant_models.operator import Operator, OperatorParams

DT = 2e-3
Z3 = np.zeros(3)
HOME = np.array([-0.10, -0.45, 0.25])


def inputs(p=HOME, v=Z3, F_contact=Z3, w=Z3, R=None):
    out = {
        "p_BT_B": np.asarray(p, float),
        "twist_B": np.concatenate([v, w]),
        "F_contact_B": np.asarray(F_contact, float),
    }
    if R is not None:
        out["R_BT"] = np.asarray(R, float).reshape(9)
    return out


def test_the_defaults_add_nothing() -> None:
    """Today's hand: no tremor, no feed-forward, no torque; the new parameters leave it alone."""
    plain = Operator(OperatorParams(task="hold"), rng=np.random.default_rng(1))
    for k in range(200):
        out = plain.step(k * DT, DT, inputs())
    np.testing.assert_array_equal(out["F_hand_B"], Z3)
    np.testing.assert_array_equal(out["tau_hand_B"], Z3)


def test_the_tremor_has_its_rms_and_its_band() -> None:
    p = OperatorParams(task="hold", intrinsic=True, tremor_rms_N=0.1, tremor_hz=9.0)
    op = Operator(p, rng=np.random.default_rng(4))
    F = np.array([op.step(k * DT, DT, inputs())["F_hand_B"] for k in range(round(60.0 / DT))])
    assert math.sqrt(np.mean(np.sum(F**2, axis=1))) == pytest.approx(0.1, rel=0.1)
    spectrum = np.abs(np.fft.rfft(F, axis=0)) ** 2
    hz = np.fft.rfftfreq(len(F), DT)
    in_band = (hz >= 8.0 - 1e-9) & (hz <= 10.0 + 1e-9)
    assert spectrum[in_band].sum() / spectrum.sum() > 0.99
    # seeded: another operator trembles otherwise, the same one the same after a reset
    other = Operator(p, rng=np.random.default_rng(5))
    assert not np.allclose(other.tremor(1.0), op.tremor(1.0))
    op.reset()
    np.testing.assert_array_equal(
        op.tremor(1.0), Operator(p, rng=np.random.default_rng(4)).tremor(1.0)
    )


def test_the_feed_forward_is_added() -> None:
    ff = np.array([0.0, 0.0, 4.7088])
    op = Operator(OperatorParams(task="hold", intrinsic=True, feedforward_B=ff))
    out = op.step(0.0, DT, inputs())
    np.testing.assert_allclose(out["F_hand_B"], ff)


def test_the_intrinsic_hand_acts_on_the_tip_as_it_is() -> None:
    """Delayed, the hand does not feel a displacement for a reaction delay; intrinsic, at once."""
    moved = HOME + np.array([0.01, 0.0, 0.0])
    for intrinsic, expected in ((False, 0.0), (True, -3.0)):
        op = Operator(OperatorParams(task="hold", stiffness=300.0, intrinsic=intrinsic))
        op.step(0.0, DT, inputs())
        out = op.step(DT, DT, inputs(p=moved))
        assert out["F_hand_B"][0] == pytest.approx(expected, abs=1e-12)


def test_on_a_contact_task_the_press_replaces_the_stiffness_along_the_press() -> None:
    """Intrinsic: across the pressing direction the stiffness, along it the press loop; the damping
    stays in every direction."""
    p = OperatorParams(task="press", intrinsic=True, stiffness=300.0, damping=20.0)
    op = Operator(p)
    op.step(0.0, DT, inputs())
    out = op.step(DT, DT, inputs(p=HOME + np.array([0.01, 0.0, -0.02]), v=[0.0, 0.0, -0.05]))
    # x: the stiffness; z: the approach push (1 N down) and the damping of the downward motion
    assert out["F_hand_B"][0] == pytest.approx(-3.0)
    assert out["F_hand_B"][2] == pytest.approx(-p.approach_force_N + 20.0 * 0.05)


def test_the_grip_resists_a_turn() -> None:
    p = OperatorParams(task="hold", intrinsic=True, grip_stiffness=4.0, grip_damping=0.1)
    op = Operator(p)
    R0 = rotvec_to_matrix([math.pi, 0.0, 0.0])  # the probe pointing down
    op.step(0.0, DT, inputs(R=R0))
    turned = rotvec_to_matrix([0.0, 0.02, 0.0]) @ R0
    out = op.step(DT, DT, inputs(R=turned, w=[0.0, 0.1, 0.0]))
    np.testing.assert_allclose(out["tau_hand_B"], [0.0, -4.0 * 0.02 - 0.1 * 0.1, 0.0], atol=1e-9)


def test_the_view_task_reaches_on_a_minimum_jerk_path_and_stays() -> None:
    op = Operator(OperatorParams(task="view", length_m=0.05, reach_s=5.0))
    p0, v0 = op.reference(0.0)
    half, v_half = op.reference(2.5)
    end, v_end = op.reference(5.0)
    later, v_later = op.reference(60.0)
    np.testing.assert_allclose(p0, Z3)
    np.testing.assert_allclose(half, [0.025, 0.0, 0.0])
    assert v_half[0] == pytest.approx(0.05 * 1.875 / 5.0)  # the peak speed, 15/8 L/T
    np.testing.assert_allclose(end, [0.05, 0.0, 0.0])
    np.testing.assert_allclose(later, end)
    np.testing.assert_allclose([v0, v_end, v_later], 0.0, atol=1e-15)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"tremor_rms_N": -0.1}, r"tremor_rms_N must be >= 0"),
        ({"tremor_hz": 0.0}, r"tremor_hz must be > 0"),
        ({"tremor_hz": 1.0, "tremor_bandwidth_hz": 3.0}, r"tremor_bandwidth_hz must be <= 1.0"),
        ({"grip_stiffness": -1.0}, r"grip_stiffness must be >= 0"),
        ({"feedforward_B": [1.0, 2.0]}, r"feedforward_B"),
        ({"task": "view", "reach_s": 0.0}, r"reach_s must be > 0"),
    ],
)
def test_bad_parameters_are_refused(kwargs: dict, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        OperatorParams(**kwargs)
