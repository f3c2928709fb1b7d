"""The contact recovery's block (`hoh_cosim.control.recovery`): its parameters' checks, the normal
low-passed from the probe axis's reverse, the approach along -n̂, when the contact is back, when
the search gives up, the hand's pull, and the command."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hoh_cosim.control.recovery import ContactRecovery, RecoveryParams
from hoh_cosim.errors import ConfigError

DT = 0.002
AXIS = np.array([0.0, 0.0, -1.0])  # the probe pointing down
P0 = np.array([0.3, 0.0, 0.3])
PARAMS = RecoveryParams(enabled=True)
CLOSED = ("confirm_s", "pull_N", "established_s")  # >= 0
OPEN = (
    "speed_m_s",
    "contact_N",
    "max_travel_m",
    "max_s",
    "normal_tau_s",
    "loss_s",
    "loss_m",
)  # > 0


def unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v)


def angle(a: np.ndarray, b: np.ndarray) -> float:
    return math.acos(min(1.0, float(a @ b)))


# --- the parameters ------------------------------------------------------------------------------


@pytest.mark.parametrize("name", CLOSED)
def test_a_negative_parameter_is_refused_by_name(name):
    with pytest.raises(ConfigError, match=rf"^{name} must be >= 0.0, got -1.0$"):
        RecoveryParams(**{name: -1.0})
    RecoveryParams(**{name: 0.0})  # zero is allowed


@pytest.mark.parametrize("name", OPEN)
def test_a_parameter_that_must_be_positive_refuses_zero_by_name(name):
    with pytest.raises(ConfigError, match=rf"^{name} must be > 0.0, got 0.0$"):
        RecoveryParams(**{name: 0.0})


@pytest.mark.parametrize("name", CLOSED + OPEN)
@pytest.mark.parametrize(
    ("value", "said"), [("fast", "expected a number, got 'fast'"), (math.nan, "expected a finite")]
)
def test_a_parameter_that_is_no_finite_number_is_refused_in_one_line(name, value, said):
    with pytest.raises(ConfigError, match=rf"^{name}: {said}") as error:
        RecoveryParams(**{name: value})
    assert "\n" not in str(error.value)


# --- the normal ----------------------------------------------------------------------------------


def test_the_first_contact_starts_the_normal_from_the_probe_axis_reverse():
    recovery = ContactRecovery(PARAMS)
    F = 5.0 * unit([0.3, 0.0, 1.0])
    recovery.observe(DT, F, AXIS)
    w = DT / PARAMS.normal_tau_s
    np.testing.assert_allclose(recovery.normal, unit(-AXIS + w * (unit(F) - -AXIS)), rtol=1e-12)


@pytest.mark.parametrize("axis", [None, np.zeros(3)])
def test_without_a_probe_axis_the_first_contact_is_the_normal(axis):
    recovery = ContactRecovery(PARAMS)
    F = np.array([1.0, 0.0, 4.0])
    recovery.observe(DT, F, axis)
    np.testing.assert_allclose(recovery.normal, unit(F), rtol=1e-12)


def test_no_contact_no_force_or_an_approach_leave_the_normal_as_it_was():
    recovery = ContactRecovery(PARAMS)
    recovery.observe(DT, np.array([0.0, 0.0, PARAMS.contact_N]), AXIS)  # at, not above
    recovery.observe(DT, None, AXIS)
    assert not recovery.normal.any()
    recovery.observe(DT, np.array([0.0, 0.0, 5.0]), AXIS)
    before = recovery.normal.copy()
    recovery.start(0.0, P0, AXIS, True)
    recovery.observe(DT, np.array([5.0, 0.0, 0.0]), AXIS)
    np.testing.assert_array_equal(recovery.normal, before)


def test_the_normal_follows_the_contact_over_its_time_constant():
    recovery = ContactRecovery(PARAMS)
    n = unit([0.3, 0.0, 1.0])
    start = angle(-AXIS, n)
    angles = []
    for _ in range(int(5 * PARAMS.normal_tau_s / DT)):
        recovery.observe(DT, 5.0 * n, AXIS)
        angles.append(angle(recovery.normal, n))
    assert np.all(np.diff(angles) < 0.0)
    after_tau = angles[int(PARAMS.normal_tau_s / DT) - 1]
    assert after_tau == pytest.approx(start / math.e, rel=0.05)  # first order
    assert angles[-1] < 0.01 * start


def test_friction_tilting_the_contact_both_ways_averages_out_to_the_normal(rng):
    recovery = ContactRecovery(PARAMS)
    n = unit([0.2, -0.1, 1.0])
    slide = unit(np.cross(n, [0.0, 1.0, 0.0]))
    for i in range(int(10.0 / DT)):
        tilt = 0.2 * (1.0 if (i * DT) % 0.5 < 0.25 else -1.0)  # μ = 0.2, turning at each stroke
        F = 6.0 * (n + tilt * slide) + rng.normal(0.0, 0.1, 3)
        recovery.observe(DT, F, AXIS)
    one_reading = math.degrees(math.atan(0.2))  # a single reading is 11° off the normal
    assert math.degrees(angle(recovery.normal, n)) < one_reading / 5.0


# --- the approach --------------------------------------------------------------------------------


def test_start_approaches_along_minus_the_normal_from_the_tip():
    recovery = ContactRecovery(PARAMS)
    for _ in range(100):
        recovery.observe(DT, np.array([1.0, 0.0, 5.0]), AXIS)
    recovery.start(1.0, P0, AXIS, hands_off=False)
    np.testing.assert_array_equal(recovery.direction, -recovery.normal)
    assert (recovery.active, recovery.hands_off, recovery.recoveries) == (True, False, 1)
    recovery.stop()
    recovery.start(2.0, P0, AXIS, hands_off=True)
    assert (recovery.active, recovery.hands_off, recovery.recoveries) == (True, True, 2)


@pytest.mark.parametrize(
    ("axis", "direction"),
    [(AXIS, AXIS), (unit([0.0, 1.0, -1.0]), unit([0.0, 1.0, -1.0])), (None, [0.0, 0.0, -1.0])],
)
def test_without_a_contact_seen_the_approach_goes_along_the_probe_or_down(axis, direction):
    recovery = ContactRecovery(PARAMS)
    recovery.start(0.0, P0, axis, True)
    np.testing.assert_array_equal(recovery.direction, direction)


def test_reset_forgets_the_normal_and_the_approach():
    recovery = ContactRecovery(PARAMS)
    recovery.observe(DT, np.array([1.0, 0.0, 5.0]), AXIS)
    recovery.start(0.0, P0, AXIS, False)
    recovery.back(0.0, np.array([0.0, 0.0, 5.0]))
    recovery.reset()
    fresh = ContactRecovery(PARAMS)
    np.testing.assert_equal(vars(recovery), vars(fresh))


def approaching(hands_off: bool = True) -> ContactRecovery:
    recovery = ContactRecovery(PARAMS)
    recovery.start(0.0, P0, AXIS, hands_off)
    return recovery


def test_the_contact_is_back_after_confirm_s_above_contact_N():
    recovery = approaching()
    F = np.array([0.0, 0.0, PARAMS.contact_N + 0.1])
    n = round(PARAMS.confirm_s / DT)
    answers = [recovery.back(1.0 + i * DT, F) for i in range(n + 1)]
    assert answers == [False] * n + [True]


@pytest.mark.parametrize("dip", [np.array([0.0, 0.0, PARAMS.contact_N]), None])
def test_a_dip_to_contact_N_or_a_missing_force_starts_the_wait_again(dip):
    recovery = approaching()
    F = np.array([0.0, 0.0, 2.5])
    n = round(PARAMS.confirm_s / DT)
    for i in range(n):
        assert not recovery.back(i * DT, F)
    assert not recovery.back(n * DT, dip)
    assert not recovery.back((n + 1) * DT, F)  # the wait starts over
    assert recovery.back((2 * n + 1) * DT, F)


def test_it_gives_up_after_max_travel_along_the_approach_or_after_max_s():
    recovery = approaching()
    d = recovery.direction
    assert not recovery.gave_up(0.1, P0 + (PARAMS.max_travel_m - 1e-6) * d)
    assert recovery.gave_up(0.1, P0 + (PARAMS.max_travel_m + 1e-6) * d)
    assert not recovery.gave_up(0.1, P0 + np.array([0.1, 0.0, 0.0]))  # across: no travel
    assert not recovery.gave_up(0.1, P0 - 0.1 * d)  # backwards: no travel
    assert not recovery.gave_up(PARAMS.max_s - 0.01, P0)
    assert recovery.gave_up(PARAMS.max_s, P0)


def test_a_pull_against_the_approach_beyond_pull_N_for_pull_s_is_the_hands():
    recovery = approaching(hands_off=False)
    d = recovery.direction
    pull = -(PARAMS.pull_N + 0.01) * d
    assert not recovery.pulled(1.0, pull)  # just begun
    assert not recovery.pulled(1.0 + PARAMS.pull_s / 2, pull)
    assert recovery.pulled(1.0 + PARAMS.pull_s, pull)
    assert not recovery.pulled(2.0, -PARAMS.pull_N * d)  # at the threshold: none, and it restarts
    assert not recovery.pulled(2.0 + PARAMS.pull_s, pull)
    for t in (3.0, 3.0 + PARAMS.pull_s):
        assert not recovery.pulled(t, np.array([5.0, 0.0, 0.0]))  # across
        assert not recovery.pulled(t, 5.0 * d)  # a push along it


def test_hands_off_no_pull_ends_the_approach():
    recovery = approaching(hands_off=True)
    pull = -10.0 * recovery.direction
    assert not any(recovery.pulled(1.0 + 0.01 * k, pull) for k in range(100))


def test_the_command_keeps_the_request_across_and_the_larger_speed_along(rng):
    recovery = ContactRecovery(PARAMS)
    recovery.observe(DT, np.array([2.0, -1.0, 5.0]), None)
    recovery.start(0.0, P0, AXIS, False)
    d = recovery.direction
    faster = 0
    for _ in range(200):
        v = rng.normal(0.0, 0.03, 3)
        out = recovery.command(v)
        along = float(v @ d)
        assert float(out @ d) == pytest.approx(max(along, PARAMS.speed_m_s), abs=1e-15)
        np.testing.assert_allclose(out - float(out @ d) * d, v - along * d, atol=1e-15)
        faster += along > PARAMS.speed_m_s
    assert 0 < faster < 200  # both sides of the approach's speed were seen
