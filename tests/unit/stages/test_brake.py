"""The release brake's stage: rest, braking, status RELEASED, whatever the request; reset() forgets
the release detector's state."""

from __future__ import annotations

import numpy as np
import pytest

from hoh_cosim.control.admittance import TRANSLATION_GAINS
from hoh_cosim.control.guidance.stages import brake as brake_module
from hoh_cosim.control.guidance.stages.brake import ReleaseBrake
from hoh_cosim.control.release import ReleaseParams, ReleasePhase
from hoh_cosim.control.supervisor import Status
from tests.unit.stages.ticks import assert_reads_only, make_command, make_tick

PARAMS = ReleaseParams(enabled=True)


@pytest.mark.parametrize("steering", [True, False])
def test_the_command_is_rest_braked_and_released(steering, rng):
    stage = ReleaseBrake(PARAMS)
    status = int(Status.FIXTURE)
    for _ in range(10):
        tick = make_tick(F_hand_B=rng.normal(0.0, 5.0, 3), F_probe_B=rng.normal(0.0, 3.0, 3))
        law = rng.normal(0.0, 0.05, 6)
        command = make_command(law[:3], law[3:], status=status, steering=steering)
        out = stage.step(tick, command)
        assert not out.v.any()
        assert not out.w.any()
        assert out.braking
        assert out.status == status | int(Status.RELEASED)
        np.testing.assert_array_equal(out.law, law)  # the request stays the law's
        assert out.steering == steering


def released_detector(stage: ReleaseBrake):
    detector = stage.detector
    detector.step(0.0, np.array([3.0, 0.0, 0.0]), None, TRANSLATION_GAINS.deadband, True)
    detector.hold_at_rest(0.002)
    assert detector.released
    return detector


def test_reset_forgets_the_release():
    stage = ReleaseBrake(PARAMS)
    detector = released_detector(stage)
    stage.reset()
    fresh = ReleaseBrake(PARAMS).detector
    assert (detector.phase, detector.t_release, detector.releases) == (ReleasePhase.IDLE, None, 0)
    assert list(detector._trend) == list(fresh._trend) == []


def test_stepped_reset_and_stepped_again_equals_a_fresh_stage(rng):
    tick = make_tick(F_hand_B=rng.normal(0.0, 5.0, 3))
    stage = ReleaseBrake(PARAMS)
    released_detector(stage)
    stage.step(tick, make_command([0.01, 0.0, 0.0]))
    stage.reset()
    again = stage.step(tick, make_command([0.01, 0.0, 0.0]))
    fresh = ReleaseBrake(PARAMS).step(tick, make_command([0.01, 0.0, 0.0]))
    assert (again.status, again.braking) == (fresh.status, fresh.braking)
    np.testing.assert_array_equal(np.concatenate([again.v, again.w]), np.zeros(6))
    assert stage.detector.phase == ReleasePhase.IDLE


def test_it_reads_only_the_tick_and_the_command():
    assert_reads_only(brake_module, ReleaseBrake(PARAMS), make_tick(), make_command())
