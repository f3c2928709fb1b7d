"""Safety limits (DESIGN.md §7) as pure functions."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from hoh_cosim.control.limits import (
    clamp_acceleration,
    clamp_speed,
    is_stale,
    probe_force_limit,
    workspace_limit,
)
from hoh_cosim.control.supervisor import STOP_FLAGS, LimitParams, Status
from hoh_cosim.errors import ConfigError

vectors = st.lists(st.floats(-10.0, 10.0), min_size=3, max_size=3).map(np.array)


@given(v=vectors)
def test_speed_clamp_caps_the_norm_and_keeps_the_direction(v):
    out, clamped = clamp_speed(v, 0.1)
    assert np.linalg.norm(out) <= 0.1 + 1e-12
    assert clamped == (np.linalg.norm(v) > 0.1)
    if clamped:
        np.testing.assert_allclose(out / np.linalg.norm(out), v / np.linalg.norm(v), atol=1e-12)
    else:
        np.testing.assert_array_equal(out, v)


@given(v=vectors, v_prev=vectors)
def test_acceleration_clamp_limits_the_change_per_tick(v, v_prev):
    out, clamped = clamp_acceleration(v, v_prev, 1e-3, 1.0)
    assert np.linalg.norm(out - v_prev) <= 1e-3 + 1e-12
    if not clamped:
        np.testing.assert_array_equal(out, v)


def test_acceleration_clamp_reaches_the_target_in_time():
    v, target = np.zeros(3), np.array([0.05, 0.0, 0.0])
    for _ in range(50):  # 0.05 m/s at 1 m/s² takes 50 ms
        v, _ = clamp_acceleration(target, v, 1e-3, 1.0)
    np.testing.assert_allclose(v, target, atol=1e-12)


def test_workspace_keeps_motion_inside_free():
    v = np.array([0.05, -0.05, 0.05])
    out, hit = workspace_limit(v, np.zeros(3), -np.ones(3), np.ones(3))
    np.testing.assert_array_equal(out, v)
    assert not hit


def test_workspace_stops_outward_motion_at_a_face_and_lets_it_come_back():
    lo, hi = np.array([-0.5, -0.5, 0.1]), np.array([0.5, 0.5, 0.6])
    p = np.array([0.5, 0.0, 0.1])  # on the +x face and on the floor
    out, hit = workspace_limit(np.array([0.05, 0.02, -0.03]), p, lo, hi)
    np.testing.assert_array_equal(out, [0.0, 0.02, 0.0])
    assert hit
    out, hit = workspace_limit(np.array([-0.05, 0.0, 0.03]), p, lo, hi)
    np.testing.assert_array_equal(out, [-0.05, 0.0, 0.03])
    assert not hit


def test_soft_force_cap_blocks_pressing_harder_only():
    F_probe = np.array([0.0, 0.0, 21.0])  # the patient pushes the probe up
    down_and_sideways = np.array([0.03, 0.0, -0.02])
    out, hit = probe_force_limit(down_and_sideways, F_probe, 20.0)
    np.testing.assert_allclose(out, [0.03, 0.0, 0.0])
    assert hit
    away = np.array([0.0, 0.0, 0.02])
    out, hit = probe_force_limit(away, F_probe, 20.0)
    np.testing.assert_array_equal(out, away)


def test_soft_force_cap_is_inactive_below_the_cap():
    v = np.array([0.0, 0.0, -0.02])
    out, hit = probe_force_limit(v, np.array([0.0, 0.0, 19.9]), 20.0)
    np.testing.assert_array_equal(out, v)
    assert not hit


def test_stale_after_three_periods():
    assert not is_stale(0.015, 0.005, 3.0)
    assert is_stale(0.0151, 0.005, 3.0)


def test_status_ok_and_description():
    assert Status(0).ok
    assert Status(0).describe() == "ok"
    s = Status.SPEED_CLAMPED | Status.STALE_FT
    assert not s.ok
    assert s.describe() == "stale FT-150 data, speed clamped"
    assert (Status.SPEED_CLAMPED | Status.ACCEL_CLAMPED | Status.WORKSPACE).ok
    for flag in (
        Status.FORCE_STOP,
        Status.NONFINITE,
        Status.STALE_FT,
        Status.STALE_PROBE,
        Status.NOT_READY,
    ):
        assert flag & STOP_FLAGS


def test_default_limits_are_the_designs():
    lim = LimitParams()
    assert lim.max_linear_speed == 0.10
    assert lim.probe_force_soft_cap == 20.0
    assert lim.probe_force_stop == 25.0
    assert lim.stale_periods == 3.0


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"max_linear_speed": 0.0}, r"max_linear_speed must be > 0.0, got 0.0"),
        (
            {"probe_force_soft_cap": 30.0},
            r"probe_force_soft_cap \(30.0 N\) must not exceed probe_force_stop \(25.0 N\)",
        ),
        (
            {"workspace_min_B": [0.0, 0.0, 1.0]},
            r"workspace_min_B must be below workspace_max_B on every axis",
        ),
        ({"workspace_max_B": [1.0, 1.0]}, r"workspace_max_B: expected 3 values, got 2"),
    ],
)
def test_limit_params_reject_bad_values(kwargs, message):
    with pytest.raises(ConfigError, match=message):
        LimitParams(**kwargs)
