"""The follow's stage: v ← v + the `BreathFollower`'s velocity along the probe axis (status
FOLLOWING while it acts); without a probe axis it stops; rest() and reset() forget."""

from __future__ import annotations

import numpy as np
import pytest

from hoh_cosim.control.follow import BreathFollower, FollowParams
from hoh_cosim.control.guidance.stages import follow as follow_module
from hoh_cosim.control.guidance.stages.follow import FollowStage
from hoh_cosim.control.supervisor import Status
from tests.unit.stages.ticks import DT, assert_reads_only, make_command, make_tick, same_state

PARAMS = FollowParams(enabled=True)
AXIS = np.array([0.0, 0.0, -1.0])  # the probe pointing down
P0 = np.array([0.3, 0.0, 0.3])


def breathing_tick(i: int, rng: np.random.Generator, **overrides):
    """The probe in contact on a breathing patient: 6 ± 3 N, the tip still, noisy sensors (an
    override None leaves the input out)."""
    force = 6.0 + 3.0 * np.sin(2.0 * np.pi * 0.25 * i * DT)
    F_probe = np.array([0.0, 0.0, force]) + rng.normal(0.0, 0.05, 3)
    inputs = {
        "F_hand_B": rng.normal(0.0, 0.1, 3),
        "F_hand_meas_B": F_probe + rng.normal(0.0, 0.1, 3),
        "F_probe_B": F_probe,
        "F_probe_meas_B": F_probe,
        "probe_axis_B": AXIS,
        "p_BT_B": P0,
        "ft_age": 0.001,
    }
    inputs.update(overrides)
    return make_tick(i * DT, **{k: v for k, v in inputs.items() if v is not None})


def test_in_contact_the_follow_adds_the_followers_velocity_along_the_axis(rng):
    stage, twin = FollowStage(PARAMS), BreathFollower(PARAMS)
    v_law = np.array([0.01, 0.0, 0.0])
    for i in range(600):
        tick = breathing_tick(i, rng)
        out = stage.step(tick, make_command(v_law, status=int(Status.FIXTURE)))
        want = twin.step(
            DT, tick.F, tick.F_probe, AXIS, tick.t, tick.p_BT, tick.F_meas, tick.F_probe_meas, 0.001
        )
        np.testing.assert_array_equal(out.v, v_law + want)
        assert out.status == int(Status.FIXTURE | Status.FOLLOWING)
    assert abs(out.v[2]) > 1e-4  # the follow moved the probe with the breath
    np.testing.assert_array_equal(out.v[:2], v_law[:2])  # along the axis only


def test_out_of_contact_it_leaves_the_command_and_sets_no_flag(rng):
    stage = FollowStage(PARAMS)
    tick = breathing_tick(0, rng, F_probe_B=[0.0, 0.0, 1.0])
    out = stage.step(tick, make_command([0.01, 0.0, 0.0]))
    np.testing.assert_array_equal(out.v, [0.01, 0.0, 0.0])
    assert out.status == 0


@pytest.mark.parametrize("axis", [None, np.zeros(3)])
def test_without_a_probe_axis_it_stops(axis, rng):
    stage = FollowStage(PARAMS)
    for i in range(200):
        stage.step(breathing_tick(i, rng), make_command())
    assert stage.follower.active
    tick = breathing_tick(200, rng, probe_axis_B=axis)
    out = stage.step(tick, make_command([0.01, 0.0, 0.0], status=int(Status.FIXTURE)))
    np.testing.assert_array_equal(out.v, [0.01, 0.0, 0.0])
    assert out.status == int(Status.FIXTURE)
    same_state(stage.follower, BreathFollower(PARAMS))


@pytest.mark.parametrize("forget", ["rest", "reset"])
def test_rest_and_reset_forget_the_follow(forget, rng):
    ticks = [breathing_tick(i, rng) for i in range(300)]
    stage = FollowStage(PARAMS)
    for tick in ticks[:-1]:
        stage.step(tick, make_command())
    getattr(stage, forget)()
    same_state(stage.follower, BreathFollower(PARAMS))
    again = stage.step(ticks[-1], make_command())
    once = FollowStage(PARAMS).step(ticks[-1], make_command())
    np.testing.assert_array_equal(again.v, once.v)
    assert again.status == once.status


def test_it_reads_only_the_tick_and_the_command(rng):
    assert_reads_only(follow_module, FollowStage(PARAMS), breathing_tick(0, rng), make_command())
