"""The limits' stage: `limit_command` from the tick's last command, with the probe force only
where there is a probe sensor and the braking clamp only on a braking command; no state."""

from __future__ import annotations

import numpy as np
import pytest

from hoh_cosim.control.guidance.stages import limits as limits_module
from hoh_cosim.control.guidance.stages.limits import Limits
from hoh_cosim.control.supervisor import LimitParams, Status, limit_command
from tests.unit.stages.ticks import DT, PLAIN, assert_reads_only, make_command, make_tick

PARAMS = LimitParams()
BOX = (PARAMS.workspace_min_B.tolist(), PARAMS.workspace_max_B.tolist())
NO_PROBE = (False, False, False, False, 0.0, False, 2.25)
X = np.array([1.0, 0.0, 0.0])
FIXTURE = int(Status.FIXTURE)


def limited(v, w=(0.0, 0.0, 0.0), *, last=None, braking=False, status=0, reading=PLAIN, **inputs):
    last = last or (np.zeros(3), np.zeros(3))
    command = make_command(v, w, status=status)
    command.braking = braking
    return Limits(PARAMS).step(make_tick(last=last, reading=reading, **inputs), command)


def test_the_command_is_limit_commands(rng):
    stage, flags = Limits(PARAMS), 0
    for _ in range(300):
        braking = bool(rng.random() < 0.3)
        v = np.zeros(3) if braking else rng.normal(0.0, 0.08, 3)
        w, last = rng.normal(0.0, 0.4, 3), (rng.normal(0.0, 0.05, 3), rng.normal(0.0, 0.3, 3))
        F_probe = rng.normal(0.0, 12.0, 3)
        p = rng.uniform(-0.75, 0.85, 3)
        reading = PLAIN if rng.random() < 0.7 else NO_PROBE
        tick = make_tick(last=last, reading=reading, F_probe_B=F_probe, p_BT_B=p)
        command = make_command(v, w, status=int(Status.FOLLOWING))
        command.braking = braking
        out = stage.step(tick, command)
        probe = F_probe if reading is PLAIN else None
        want_v, want_w, clamped = limit_command(
            v, w, *last, DT, probe, p, PARAMS, BOX, braking=braking
        )
        np.testing.assert_array_equal(out.v, want_v)
        np.testing.assert_array_equal(out.w, want_w)
        assert out.status == int(Status.FOLLOWING) | clamped
        flags |= clamped
    assert flags == int(
        Status.SPEED_CLAMPED
        | Status.ACCEL_CLAMPED
        | Status.BRAKING
        | Status.FORCE_SOFT_CAP
        | Status.WORKSPACE
    )


def test_a_fast_command_is_clamped_to_the_speed_limit():
    out = limited(0.3 * X, last=(0.1 * X, np.zeros(3)))
    assert np.linalg.norm(out.v) == pytest.approx(PARAMS.max_linear_speed)
    assert out.status == int(Status.SPEED_CLAMPED)


@pytest.mark.parametrize(("braking", "accel"), [(True, 10.0), (False, 1.0)])
def test_rest_after_a_release_is_shed_at_the_braking_deceleration(braking, accel):
    out = limited(np.zeros(3), last=(0.05 * X, np.zeros(3)), braking=braking, status=FIXTURE)
    np.testing.assert_allclose(out.v, (0.05 - accel * DT) * X, rtol=1e-12)
    clamped = Status.ACCEL_CLAMPED | (Status.BRAKING if braking else 0)
    assert out.status == FIXTURE | int(clamped)


def test_above_the_soft_cap_only_with_a_probe_sensor_the_press_is_taken_out():
    press = np.array([0.01, 0.0, -0.02])
    capped = limited(press, last=(press, np.zeros(3)), F_probe_B=[0.0, 0.0, 21.0])
    np.testing.assert_array_equal(capped.v, [0.01, 0.0, 0.0])
    assert capped.status == int(Status.FORCE_SOFT_CAP)
    free = limited(press, last=(press, np.zeros(3)), F_probe_B=[0.0, 0.0, 21.0], reading=NO_PROBE)
    np.testing.assert_array_equal(free.v, press)
    assert free.status == 0


def test_at_the_workspaces_face_motion_out_of_it_stops():
    up = np.array([0.01, 0.0, 0.02])
    out = limited(up, last=(up, np.zeros(3)), p_BT_B=[0.3, 0.0, 0.8])
    np.testing.assert_array_equal(out.v, [0.01, 0.0, 0.0])
    assert out.status == int(Status.WORKSPACE)


def test_reset_forgets_nothing_because_there_is_no_state():
    stage, tick = Limits(PARAMS), make_tick(last=(0.05 * X, np.zeros(3)))
    stage.step(tick, make_command(0.3 * X))
    stage.reset()
    again = stage.step(tick, make_command(0.3 * X))
    once = Limits(PARAMS).step(tick, make_command(0.3 * X))
    np.testing.assert_array_equal(again.v, once.v)
    assert again.status == once.status


def test_it_reads_only_the_tick_and_the_command():
    assert_reads_only(limits_module, Limits(PARAMS), make_tick(), make_command(0.3 * X))
