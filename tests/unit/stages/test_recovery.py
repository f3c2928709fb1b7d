"""The contact recovery's stage after `ContactRecovery.start`: along the approach at least
`speed_m_s`, the request across it kept, ω at rest when hands off, status RECOVERING; reset()
forgets the normal and the approach."""

from __future__ import annotations

import numpy as np
import pytest

from hoh_cosim.control.guidance.stages import recovery as recovery_module
from hoh_cosim.control.guidance.stages.recovery import RecoveryStage
from hoh_cosim.control.recovery import ContactRecovery, RecoveryParams
from hoh_cosim.control.supervisor import Status
from tests.unit.stages.ticks import DT, assert_reads_only, make_command, make_tick, same_state

PARAMS = RecoveryParams(enabled=True)
AXIS = np.array([0.0, 0.0, -1.0])  # the probe pointing down
P0 = np.array([0.3, 0.0, 0.3])
TILTED = np.array([0.3, 0.0, 1.0]) / np.hypot(0.3, 1.0)  # the contact's outward direction


def recovering(hands_off: bool, normal: np.ndarray | None = None) -> RecoveryStage:
    stage = RecoveryStage(PARAMS)
    if normal is not None:  # a contact seen long enough for the normal to settle on it
        for _ in range(3000):
            stage.recovery.observe(DT, 5.0 * normal, AXIS)
    stage.recovery.start(0.0, P0, AXIS, hands_off)
    return stage


@pytest.mark.parametrize("hands_off", [True, False])
@pytest.mark.parametrize("normal", [None, TILTED])
def test_the_approach_goes_along_minus_the_normal_and_keeps_the_request_across(
    hands_off, normal, rng
):
    stage = recovering(hands_off, normal)
    d = stage.recovery.direction
    np.testing.assert_allclose(d, AXIS if normal is None else -normal, atol=0.01)
    for _ in range(50):
        v, w = rng.normal(0.0, 0.03, 3), rng.normal(0.0, 0.2, 3)
        out = stage.step(make_tick(), make_command(v, w, status=int(Status.PASSIVITY)))
        along = float(out.v @ d)
        assert along >= PARAMS.speed_m_s - 1e-15
        assert along == pytest.approx(max(float(v @ d), PARAMS.speed_m_s), abs=1e-15)
        np.testing.assert_allclose(out.v - along * d, v - float(v @ d) * d, atol=1e-15)
        np.testing.assert_array_equal(out.v, stage.recovery.command(v))
        np.testing.assert_array_equal(out.w, np.zeros(3) if hands_off else w)
        assert out.status == int(Status.PASSIVITY | Status.RECOVERING)


def test_reset_forgets_the_normal_and_the_approach():
    stage = recovering(True, TILTED)
    stage.step(make_tick(), make_command())
    stage.reset()
    same_state(stage.recovery, ContactRecovery(PARAMS))
    # started again, it approaches along the probe as a fresh one does, not the old normal
    stage.recovery.start(0.0, P0, AXIS, True)
    again = stage.step(make_tick(), make_command())
    once = recovering(True).step(make_tick(), make_command())
    np.testing.assert_array_equal(again.v, once.v)
    np.testing.assert_array_equal(again.v, PARAMS.speed_m_s * AXIS)
    assert again.status == once.status


def test_it_reads_only_the_tick_and_the_command():
    assert_reads_only(recovery_module, recovering(True), make_tick(), make_command())
